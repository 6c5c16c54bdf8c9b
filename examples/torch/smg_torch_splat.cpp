// examples/torch/smg_torch_splat.cpp — the reference CPU Gaussian splatter for smg_torch:
// render_forward into new tensors, keeping the RenderWorkspace (projections, tile lists,
// per-pixel transmittance) in a RenderState that the autograd backward hands to render_backward.
// Gradients: means, raw quaternions, log-scales, opacity logits, colours (plain [G, C] or SH
// [G, K, C]); viewmat and K are constants. Channel counts 3 (compiled for speed) and any other
// (Eigen::Dynamic).
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "smg/splat.hpp"
#include "smg_torch_common.hpp"

namespace smg_torch {

namespace {

namespace sp = smg::splat;

// Library names that differ from the Python arguments of render (after validate_camera's
// "camera: " and validate_settings' "settings: " prefixes are dropped).
constexpr Names kRenderNames = {
    {"near plane", "near"},           {"far plane", "far"},         {"focal lengths", "K"},
    {"principal point", "K"},         {"image size", "width, height"},
    {"tile_size", "tile_size"},       {"radius_sigmas", "radius_sigmas"},
    {"eps2d", "eps2d"},               {"alpha_max", "alpha_max"},   {"image", "grad_image"},
    {"alpha", "grad_alpha"},          {"depth", "grad_depth"}};

struct RenderState {
  at::ScalarType st = at::kDouble;
  sp::RenderWorkspace<float> wf;
  sp::RenderWorkspace<double> wd;
  double vm[16] = {}, fx = 0, fy = 0, cx = 0, cy = 0, near_plane = 0, far_plane = 0;
  int width = 0, height = 0, tile_size = 16, sh_degree = -1;
  double radius_sigmas = 3, eps2d = 0.3, alpha_max = 0.99;
  std::vector<double> background;
  int64_t channels = 0;
  template <class S>
  sp::RenderWorkspace<S>& ws() {
    if constexpr (std::is_same_v<S, float>) return wf; else return wd;
  }
  template <class S>
  sp::Camera<S> camera() const {
    sp::Camera<S> c;
    for (int r = 0; r < 4; ++r)
      for (int k = 0; k < 4; ++k) c.viewmat(r, k) = S(vm[4 * r + k]);
    c.fx = S(fx);
    c.fy = S(fy);
    c.cx = S(cx);
    c.cy = S(cy);
    c.width = width;
    c.height = height;
    c.near_plane = S(near_plane);
    c.far_plane = S(far_plane);
    return c;
  }
  template <class S>
  sp::SplatSettings<S> settings(std::vector<S>& bg) const {
    sp::SplatSettings<S> s;
    s.tile_size = tile_size;
    s.radius_sigmas = S(radius_sigmas);
    s.eps2d = S(eps2d);
    s.alpha_max = S(alpha_max);
    bg.assign(background.begin(), background.end());
    s.background = bg.empty() ? nullptr : bg.data();
    return s;
  }
};

struct Params {
  at::Tensor means, quats, scales, logits, colors;
  int64_t G = 0, ncoef = 0;
};

// The Gaussians on the CPU (the splatter has no CUDA code): means [G, 3] (the reference), quats
// [G, 4], log_scales [G, 3], opacity_logits [G], colors [G, C] or [G, K, C].
Params prepare(const at::Tensor& means, const at::Tensor& quats, const at::Tensor& log_scales,
               const at::Tensor& opacity_logits, const at::Tensor& colors) {
  for (const auto& [t, name] : {std::pair{&means, "means"}, std::pair{&quats, "quats"},
                                std::pair{&log_scales, "log_scales"},
                                std::pair{&opacity_logits, "opacity_logits"},
                                std::pair{&colors, "colors"}})
    require_cpu(*t, name);
  Params p;
  const Reference r = reference(means, "means");
  p.means = float_input(means, "means", r, 2, 3, "[G, 3]");
  p.G = means.size(0);
  p.quats = float_input(quats, "quats", r, 2, 4, "[G, 4]");
  p.scales = float_input(log_scales, "log_scales", r, 2, 3, "[G, 3]");
  p.logits = float_input(opacity_logits, "opacity_logits", r, 1, -1, "[G]");
  p.colors = on_device(colors, "colors", r);
  if (p.colors.scalar_type() != r.st)
    value_error("colors: dtype " + dtype_name(p.colors.scalar_type()) + " does not match means (" +
                dtype_name(r.st) + ")");
  if (p.colors.dim() != 2 && p.colors.dim() != 3)
    value_error("colors: expected shape [G, C] or SH coefficients [G, K, C], got " + shape_of(colors));
  p.ncoef = p.colors.dim() == 2 ? p.colors.size(1) : p.colors.size(1) * p.colors.size(2);
  return p;
}

template <class S>
sp::GaussianParams<S> params_of(const Params& p, int sh_degree) {
  sp::GaussianParams<S> g;
  g.means = {cptr<S>(p.means), p.means.size(0)};
  g.quats = {cptr<S>(p.quats), p.quats.size(0)};
  g.log_scales = {cptr<S>(p.scales), p.scales.size(0)};
  g.opacity_logits = {cptr<S>(p.logits), p.logits.size(0)};
  g.colors = {cptr<S>(p.colors), p.colors.size(0), p.ncoef};
  g.sh_degree = sh_degree;
  return g;
}

// -> (image [H, W, C], alpha [H, W], depth [H, W], radii [G] int32, state)
py::tuple render_forward(const at::Tensor& means, const at::Tensor& quats,
                         const at::Tensor& log_scales, const at::Tensor& opacity_logits,
                         const at::Tensor& colors, const at::Tensor& viewmat, const at::Tensor& K,
                         const py::int_& width_arg, const py::int_& height_arg,
                         const OptTensor& background, double near, double far,
                         const py::int_& tile_size_arg, double radius_sigmas, double eps2d,
                         double alpha_max) {
  Params p = prepare(means, quats, log_scales, opacity_logits, colors);
  const at::ScalarType st = p.means.scalar_type();
  auto state = std::make_shared<RenderState>();
  state->st = st;
  if (p.colors.dim() == 3) {
    const int64_t Kc = p.colors.size(1);
    for (int d = 0; d <= sp::kMaxShDegree; ++d)
      if (sp::sh_basis_count(d) == Kc) state->sh_degree = d;
    if (state->sh_degree < 0)
      value_error("colors: SH coefficient count " + std::to_string(Kc) +
                  " is not (d+1)^2 for a degree d in 0..3");
  }
  const int64_t C = p.colors.size(p.colors.dim() - 1);
  if (C < 1) value_error("colors: needs at least one channel");
  state->channels = C;
  require_cpu(viewmat, "viewmat");
  require_cpu(K, "K");
  if (viewmat.dim() != 2 || viewmat.size(0) != 4 || viewmat.size(1) != 4)
    value_error("viewmat: expected shape [4, 4], got " + shape_of(viewmat));
  if (K.dim() != 2 || K.size(0) != 3 || K.size(1) != 3)
    value_error("K: expected shape [3, 3], got " + shape_of(K));
  // Integer arguments range-checked before they are narrowed to int (as smg_cli's --width,
  // --height and --tile-size); the library then allows tile sizes 8, 16 and 32.
  const int64_t width = int_arg(width_arg, "width", 1, 65536);
  const int64_t height = int_arg(height_arg, "height", 1, 65536);
  const int64_t tile_size = int_arg(tile_size_arg, "tile_size", 1, 2147483647);
  const at::Tensor vm = viewmat.to(at::kDouble).contiguous(), km = K.to(at::kDouble).contiguous();
  for (int k = 0; k < 16; ++k) state->vm[k] = vm.data_ptr<double>()[k];
  const double* kp = km.data_ptr<double>();
  {
    const Eigen::Matrix3d Km = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(kp);
    ok(sp::validate_camera_matrix<double>(Km), kRenderNames);
  }
  state->fx = kp[0];
  state->fy = kp[4];
  state->cx = kp[2];
  state->cy = kp[5];
  state->width = int(width);
  state->height = int(height);
  state->near_plane = near;
  state->far_plane = far;
  state->tile_size = int(tile_size);
  state->radius_sigmas = radius_sigmas;
  state->eps2d = eps2d;
  state->alpha_max = alpha_max;
  if (background) {
    require_cpu(*background, "background");
    const at::Tensor bg = background->to(at::kDouble).contiguous().reshape({-1});
    if (bg.numel() != 1 && bg.numel() != C)
      value_error("background: expected 1 or C=" + std::to_string(C) + " values, got " +
                  std::to_string(bg.numel()));
    for (int64_t k = 0; k < C; ++k) state->background.push_back(bg.data_ptr<double>()[bg.numel() == 1 ? 0 : k]);
  }
  // Images (image, alpha, depth), their gradients in backward (same size), the workspace's
  // per-pixel state (~4 scalars) and per-Gaussian state (~64 scalars), as smg_cli's render.
  const double s = st == at::kFloat ? 4 : 8, px = double(width) * double(height);
  const std::string images_what = "width, height: a " + std::to_string(width) + "x" +
                                  std::to_string(height) + " image with C = " + std::to_string(C) +
                                  " channels and G = " + std::to_string(p.G) + " Gaussians";
  check_memory(px * ((double(C) + 2) * s * 2 + 4 * s) + double(p.G) * 64 * s, images_what);
  const at::TensorOptions o = at::TensorOptions().dtype(st);
  at::Tensor image, alpha, depth, radii;
  allocating(images_what, [&] {
    image = at::empty({height, width, C}, o);
    alpha = at::empty({height, width}, o);
    depth = at::empty({height, width}, o);
    radii = at::empty({p.G}, at::TensorOptions().dtype(at::kInt));
  });
  dispatch(st, false, [&](auto s, auto) {
    using S = decltype(s);
    const auto params = params_of<S>(p, state->sh_degree);
    const auto cam = state->camera<S>();
    std::vector<S> bg;
    const auto set = state->settings<S>(bg);
    const sp::RenderImages<S> images{{mptr<S>(image), height, width, C},
                                     {mptr<S>(alpha), height, width},
                                     {mptr<S>(depth), height, width}};
    auto& ws = state->ws<S>();
    ok(sp::validate_render(params, cam, set, images, C == 3 ? 3 : -1), kRenderNames);
    allocating(images_what, [&] {  // the workspace (tile lists, per-pixel state)
      py::gil_scoped_release release;
      if (C == 3)
        sp::render_forward<3>(params, cam, set, ws, images, parallel_options());
      else
        sp::render_forward<Eigen::Dynamic>(params, cam, set, ws, images, parallel_options());
    });
    int32_t* r = radii.data_ptr<int32_t>();
    for (int64_t g = 0; g < p.G; ++g)
      r[g] = static_cast<int32_t>(std::min<S>(ws.radii[std::size_t(g)], S(2147483647)));
    return 0;
  });
  return py::make_tuple(image, alpha, depth, radii, state);
}

// -> (grad means, grad quats (raw), grad log_scales, grad opacity_logits, grad colors)
py::tuple render_backward(const std::shared_ptr<RenderState>& state, const at::Tensor& means,
                          const at::Tensor& quats, const at::Tensor& log_scales,
                          const at::Tensor& opacity_logits, const at::Tensor& colors,
                          const OptTensor& grad_image, const OptTensor& grad_alpha,
                          const OptTensor& grad_depth) {
  const at::ScalarType st = state->st;
  Params p = prepare(means, quats, log_scales, opacity_logits, colors);
  const Reference r{"means", at::Device(at::kCPU), st};
  if (p.means.scalar_type() != st)
    value_error("means: dtype " + dtype_name(p.means.scalar_type()) + " does not match the forward's (" +
                dtype_name(st) + ")");
  const int64_t H = state->height, W = state->width, C = state->channels;
  at::Tensor gi, ga, gd;
  if (grad_image) gi = float_input(*grad_image, "grad_image", r, 3, C, "[H, W, C]");
  if (grad_alpha) ga = float_input(*grad_alpha, "grad_alpha", r, 2, -1, "[H, W]");
  if (grad_depth) gd = float_input(*grad_depth, "grad_depth", r, 2, -1, "[H, W]");
  const at::TensorOptions o = at::TensorOptions().dtype(st);
  at::Tensor g_means = at::zeros({p.G, 3}, o), g_quats = at::zeros({p.G, 4}, o),
             g_scales = at::zeros({p.G, 3}, o), g_logits = at::zeros({p.G}, o),
             g_colors = at::zeros(p.colors.sizes(), o);
  dispatch(st, false, [&](auto s, auto) {
    using S = decltype(s);
    const auto params = params_of<S>(p, state->sh_degree);
    const auto cam = state->camera<S>();
    std::vector<S> bg;
    const auto set = state->settings<S>(bg);
    auto& ws = state->ws<S>();
    sp::RenderImageGrads<S> gin;
    if (gi.defined()) gin.image = {cptr<S>(gi), H, W, C};
    if (ga.defined()) gin.alpha = {cptr<S>(ga), H, W};
    if (gd.defined()) gin.depth = {cptr<S>(gd), H, W};
    if (gi.defined() && (gi.dim() != 3 || gi.size(0) != H || gi.size(1) != W || gi.size(2) != C))
      value_error("grad_image: expected shape [H, W, C], got " + shape_of(gi));
    if (ga.defined() && (ga.dim() != 2 || ga.size(0) != H || ga.size(1) != W))
      value_error("grad_alpha: expected shape [H, W], got " + shape_of(ga));
    if (gd.defined() && (gd.dim() != 2 || gd.size(0) != H || gd.size(1) != W))
      value_error("grad_depth: expected shape [H, W], got " + shape_of(gd));
    sp::GaussianGrads<S> gout;
    gout.means = {mptr<S>(g_means), p.G};
    gout.quats = {mptr<S>(g_quats), p.G};
    gout.log_scales = {mptr<S>(g_scales), p.G};
    gout.opacity_logits = {mptr<S>(g_logits), p.G};
    gout.colors = {mptr<S>(g_colors), p.G, p.ncoef};
    ok(sp::validate_render_backward(params, cam, set, ws, gin, gout), kRenderNames);
    py::gil_scoped_release release;
    if (C == 3)
      sp::render_backward<3>(params, cam, set, ws, gin, gout, parallel_options());
    else
      sp::render_backward<Eigen::Dynamic>(params, cam, set, ws, gin, gout, parallel_options());
    return 0;
  });
  return py::make_tuple(g_means, g_quats, g_scales, g_logits, g_colors);
}

}  // namespace

void register_splat(py::module_& m) {
  using namespace pybind11::literals;
  py::class_<RenderState, std::shared_ptr<RenderState>>(
      m, "RenderState", "the splatter's forward workspace, kept for the backward");
  m.def("render_forward", &render_forward, "means"_a, "quats"_a, "log_scales"_a,
        "opacity_logits"_a, "colors"_a, "viewmat"_a, "K"_a, "width"_a, "height"_a,
        "background"_a, "near"_a, "far"_a, "tile_size"_a, "radius_sigmas"_a, "eps2d"_a,
        "alpha_max"_a);
  m.def("render_backward", &render_backward, "state"_a, "means"_a, "quats"_a, "log_scales"_a,
        "opacity_logits"_a, "colors"_a, "grad_image"_a, "grad_alpha"_a, "grad_depth"_a);
}

}  // namespace smg_torch
