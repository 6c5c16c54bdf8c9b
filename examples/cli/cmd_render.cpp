// smg_cli render CASE OUT — the reference CPU splatter on a case directory (docs/interop.md).
//
// Reads means [G,3], quats [G,4] (w,x,y,z), scales [G,3] (log-scales), opacities [G]
// (logits), colors [G,C] (or SH coefficients [G,K,C], K = (d+1)², d <= 3), viewmat [4,4]
// (world -> camera, OpenCV axes), K [3,3]; renders image [H,W,C], alpha [H,W], depth [H,W]
// (expected depth) and radii [G] (int32, 0 = culled). With grad_image.npy [H,W,C] (and/or
// the optional grad_alpha.npy, grad_depth.npy [H,W]) also runs the backward and writes
// grad_means, grad_quats (raw 4-vector), grad_quats_tangent [G,3] (right tangent),
// grad_scales (log-scales), grad_opacities (logits), grad_colors (colors' shape) and
// grad_means2d [G,2]. Outputs are float64, or float32 with --float.
#include <chrono>
#include <cstdint>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "smg/splat.hpp"
#include "subcommand.hpp"

namespace cli {

namespace {

namespace sp = smg::splat;

// Library names -> the case's files and the flags.
NameMap render_names(const CaseDir& c) {
  return {{"means", c.file("means.npy")},
          {"quats", c.file("quats.npy")},
          {"log_scales", c.file("scales.npy")},
          {"opacity_logits", c.file("opacities.npy")},
          {"colors", c.file("colors.npy")},
          {"sh_degree", c.file("colors.npy")},
          {"viewmat", c.file("viewmat.npy")},
          {"focal lengths", c.file("K.npy")},
          {"principal point", c.file("K.npy")},
          {"image size", "--width"},
          {"near plane", "--near"},
          {"far plane", "--far"},
          {"tile_size", "--tile-size"},
          {"radius_sigmas", "--radius-sigmas"},
          {"eps2d", "--eps2d"},
          {"alpha_max", "--alpha-max"},
          {"image", c.file("grad_image.npy")},
          {"alpha", c.file("grad_alpha.npy")},
          {"depth", c.file("grad_depth.npy")}};
}

template <int C, class S>
void run_splat(const sp::GaussianParams<S>& params, const sp::Camera<S>& cam,
               const sp::SplatSettings<S>& set, sp::RenderWorkspace<S>& ws,
               const sp::RenderImages<S>& images, const sp::RenderImageGrads<S>* gin,
               const sp::GaussianGrads<S>& gout, int threads, double* t_fwd, double* t_bwd,
               const NameMap& names, const std::string& fallback) {
  auto ok = [&](const smg::Status& s) { check_mapped(s, names, fallback); };
  ok(sp::validate_render(params, cam, set, images, C > 0 ? C : -1));
  const smg::ParallelOptions par{threads, 0};
  auto t0 = std::chrono::steady_clock::now();
  sp::render_forward<C>(params, cam, set, ws, images, par);
  auto t1 = std::chrono::steady_clock::now();
  *t_fwd = std::chrono::duration<double>(t1 - t0).count();
  if (!gin) return;
  ok(sp::validate_render_backward(params, cam, set, ws, *gin, gout));
  sp::render_backward<C>(params, cam, set, ws, *gin, gout, par);
  *t_bwd = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
}

template <class S>
void render_case(const Invocation& inv, JsonLine& summary) {
  const CaseDir& c = inv.case_dir;
  const auto means = c.load<S>("means.npy", {{"G"}, {"", 3}});
  const std::int64_t G = means.dim(0);
  const auto quats = c.load<S>("quats.npy", {{"G", G}, {"", 4}});
  const auto scales = c.load<S>("scales.npy", {{"G", G}, {"", 3}});
  const auto opac = c.load<S>("opacities.npy", {{"G", G}});
  if (!c.has("colors.npy")) throw RunError(c.file("colors.npy") + ": missing required file");
  const npy::Array craw = npy::read(c.file("colors.npy"), static_cast<std::uint64_t>(c.max_bytes() / 2));
  std::optional<Tensor<S>> colors;
  int sh_degree = -1;
  std::int64_t C = 0;
  if (craw.shape.size() == 3) {
    colors = c.load<S>("colors.npy", {{"G", G}, {"K"}, {"C"}});
    const std::int64_t K = colors->dim(1);
    for (int d = 0; d <= sp::kMaxShDegree; ++d)
      if (sp::sh_basis_count(d) == K) sh_degree = d;
    if (sh_degree < 0)
      throw RunError((c.path() / "colors.npy").string() + ": SH coefficient count " +
                     std::to_string(K) + " is not (d+1)^2 for a degree d in 0..3");
    C = colors->dim(2);
  } else {
    colors = c.load<S>("colors.npy", {{"G", G}, {"C"}});
    C = colors->dim(1);
  }
  if (C < 1) throw RunError((c.path() / "colors.npy").string() + ": needs at least one channel");
  const auto viewmat = c.load<S>("viewmat.npy", {{"", 4}, {"", 4}});
  const auto Kmat = c.load<S>("K.npy", {{"", 3}, {"", 3}});

  const int width = inv.args.get_int32_in("width", 1, 65536), height = inv.args.get_int32_in("height", 1, 65536);
  {
    // Images (image, alpha, depth), the optional image gradients (same size), the workspace's
    // per-pixel state (~4 scalars) and per-Gaussian state (~64 scalars incl. gradients).
    const double s = sizeof(S), px = double(width) * double(height), C1 = double(C) + 2;
    check_memory(px * (C1 * s * 2 + 4 * s) + double(G) * 64 * s, inv.max_bytes,
                 "--width: a " + std::to_string(width) + "x" + std::to_string(height) + " image with C = " +
                     std::to_string(C) + " channels and G = " + std::to_string(G) + " Gaussians");
  }
  const Eigen::Matrix<S, 3, 3> Km = Eigen::Map<const Eigen::Matrix<S, 3, 3, Eigen::RowMajor>>(Kmat.ptr());
  if (smg::Status s = sp::validate_camera_matrix<S>(Km); !s)
    throw RunError(c.file("K.npy") + ": " + s.message().substr(3));
  sp::Camera<S> cam = sp::Camera<S>::from_K(
      Eigen::Map<const Eigen::Matrix<S, 4, 4, Eigen::RowMajor>>(viewmat.ptr()), Km, width, height);
  cam.near_plane = S(inv.args.get_double("near"));
  cam.far_plane = S(inv.args.get_double("far"));
  const NameMap names = render_names(c);
  const std::string fallback = c.path().string();
  check_mapped(sp::validate_camera(cam), names, fallback);

  sp::SplatSettings<S> set;
  set.tile_size = inv.args.get_int32_in("tile-size");
  set.radius_sigmas = S(inv.args.get_double("radius-sigmas"));
  set.eps2d = S(inv.args.get_double("eps2d"));
  set.alpha_max = S(inv.args.get_double("alpha-max"));
  check_mapped(sp::validate_settings(set), names, fallback);
  const std::vector<double> bg_in = inv.args.get_doubles("background");
  if (bg_in.size() != 1 && std::int64_t(bg_in.size()) != C)
    throw UsageError("--background: takes 1 or C = " + std::to_string(C) + " comma-separated values");
  std::vector<S> bg(static_cast<std::size_t>(C));
  for (std::int64_t k = 0; k < C; ++k) bg[std::size_t(k)] = S(bg_in.size() == 1 ? bg_in[0] : bg_in[std::size_t(k)]);
  set.background = bg.data();

  sp::GaussianParams<S> params;
  params.means = {means.ptr(), G};
  params.quats = {quats.ptr(), G};
  params.log_scales = {scales.ptr(), G};
  params.opacity_logits = {opac.ptr(), G};
  params.colors = {colors->ptr(), G, colors->shape.size() == 3 ? colors->dim(1) * C : C};
  params.sh_degree = sh_degree;

  const std::int64_t H = height, W = width;
  const AllocContext ctx("--width: render of a " + std::to_string(W) + "x" + std::to_string(H) + " image");
  std::vector<S> image(std::size_t(H * W * C)), alpha(std::size_t(H * W)), depth(std::size_t(H * W));
  const sp::RenderImages<S> images{{image.data(), H, W, C}, {alpha.data(), H, W}, {depth.data(), H, W}};

  const auto gimg = c.load_optional<S>("grad_image.npy", {{"H", H}, {"W", W}, {"C", C}});
  const auto galpha = c.load_optional<S>("grad_alpha.npy", {{"H", H}, {"W", W}});
  const auto gdepth = c.load_optional<S>("grad_depth.npy", {{"H", H}, {"W", W}});
  const bool backward = gimg || galpha || gdepth;
  sp::RenderImageGrads<S> gin;
  if (gimg) gin.image = {gimg->ptr(), H, W, C};
  if (galpha) gin.alpha = {galpha->ptr(), H, W};
  if (gdepth) gin.depth = {gdepth->ptr(), H, W};
  std::vector<S> g_means, g_quats, g_tan, g_scales, g_opac, g_colors, g_m2d;
  sp::GaussianGrads<S> gout;
  if (backward) {
    g_means.resize(std::size_t(3 * G));
    g_quats.resize(std::size_t(4 * G));
    g_tan.resize(std::size_t(3 * G));
    g_scales.resize(std::size_t(3 * G));
    g_opac.resize(std::size_t(G));
    g_colors.resize(colors->data.size());
    g_m2d.resize(std::size_t(2 * G));
    gout.means = {g_means.data(), G};
    gout.quats = {g_quats.data(), G};
    gout.quats_tangent = {g_tan.data(), G};
    gout.log_scales = {g_scales.data(), G};
    gout.opacity_logits = {g_opac.data(), G};
    gout.colors = {g_colors.data(), G, params.colors.cols()};
    gout.means2d = {g_m2d.data(), G};
  }

  sp::RenderWorkspace<S> ws;
  double t_fwd = 0, t_bwd = 0;
  const sp::RenderImageGrads<S>* gptr = backward ? &gin : nullptr;
  // RGB gets the renderer's fixed-channel kernels; any other count the run-time-C kernels. More
  // fixed counts (1, 4) would each add two instantiations of the whole renderer to smg_cli, the
  // costliest file of the build, for a bridge program whose speed is not its point.
  if (C == 3)
    run_splat<3>(params, cam, set, ws, images, gptr, gout, inv.threads, &t_fwd, &t_bwd, names, fallback);
  else
    run_splat<Eigen::Dynamic>(params, cam, set, ws, images, gptr, gout, inv.threads, &t_fwd, &t_bwd, names, fallback);

  // Finite inputs must give finite results (docs/interop.md "Overflow").
  const std::string cause = c.file("means.npy") + ": values too large: the render overflows (non-finite ";
  require_finite(image, cause + "image)");
  require_finite(alpha, cause + "alpha)");
  require_finite(depth, cause + "depth)");
  for (const auto* g : {&g_means, &g_quats, &g_tan, &g_scales, &g_opac, &g_colors, &g_m2d})
    require_finite(*g, cause + "gradient)");

  OutputSet out;
  out.add("image.npy", std::move(image), {H, W, C});
  out.add("alpha.npy", std::move(alpha), {H, W});
  out.add("depth.npy", std::move(depth), {H, W});
  std::vector<std::int32_t> radii(static_cast<std::size_t>(G));
  for (std::int64_t g = 0; g < G; ++g) radii[std::size_t(g)] = static_cast<std::int32_t>(std::min<S>(ws.radii[std::size_t(g)], S(2147483647)));
  out.add("radii.npy", std::move(radii), {G});
  if (backward) {
    out.add("grad_means.npy", std::move(g_means), {G, 3});
    out.add("grad_quats.npy", std::move(g_quats), {G, 4});
    out.add("grad_quats_tangent.npy", std::move(g_tan), {G, 3});
    out.add("grad_scales.npy", std::move(g_scales), {G, 3});
    out.add("grad_opacities.npy", std::move(g_opac), {G});
    out.add("grad_colors.npy", std::move(g_colors), colors->shape);
    out.add("grad_means2d.npy", std::move(g_m2d), {G, 2});
  }
  out.commit(inv.out_dir);
  summary.add("G", G).add("H", H).add("W", W).add("C", C).add("sh_degree", sh_degree)
      .add("visible", static_cast<std::int64_t>(ws.n_visible))
      .add("intersections", static_cast<std::int64_t>(ws.n_isect))
      .add("backward", backward).add("precision", sizeof(S) == 4 ? "float32" : "float64")
      .add("seconds", t_fwd + t_bwd).add("seconds_forward", t_fwd).add("seconds_backward", t_bwd);
}

}  // namespace

Subcommand render_subcommand() {
  Subcommand s;
  s.name = "render";
  s.summary = "render Gaussians with the reference CPU splatter (and backward with grad_image.npy)";
  // Defaults come from the library's structs (Camera, SplatSettings), so each exists once.
  const sp::Camera<double> cam{};
  const sp::SplatSettings<double> set{};
  s.flags = {{"width", "0", "image width in pixels (required), 1..65536"},
             {"height", "0", "image height in pixels (required), 1..65536"},
             {"background", "0", "background colour: 1 value or C comma-separated values"},
             {"near", format_number(cam.near_plane), "near plane (camera-space z)"},
             {"far", format_number(cam.far_plane), "far plane (camera-space z)"},
             {"tile-size", format_number(set.tile_size), "tile edge in pixels: 8, 16 or 32"},
             {"radius-sigmas", format_number(set.radius_sigmas), "binning radius in standard deviations (gsplat: 3)"},
             {"eps2d", format_number(set.eps2d), "2D covariance dilation, pixels^2"},
             {"alpha-max", format_number(set.alpha_max), "alpha clamp (gsplat v1.0-1.4 used 0.999)"}};
  s.run = [](const Invocation& inv, JsonLine& summary) {
    if (inv.use_float)
      render_case<float>(inv, summary);
    else
      render_case<double>(inv, summary);
  };
  return s;
}

}  // namespace cli
