// Hard cases of the splatter, each with its defined behaviour: Gaussians behind, on, or just
// in front of the camera plane, beyond the far plane, with near-singular or overflowing 2D
// covariances, huge and tiny scales, partly off-screen (with the field-of-view clamp), all
// culled, none at all; invalid inputs rejected by validation. No NaN/Inf ever reaches an
// output.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "splat/splat_scene.hpp"
#include "support/finite_diff.hpp"

using namespace smg;
using namespace smg::splat;
using smg::test::SplatScene;

namespace {

double logit(double o) { return std::log(o / (1 - o)); }

template <class S>
bool splat_all_finite(const std::vector<S>& v) {
  for (const S& x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

// Renders one Gaussian (plus nothing else) and returns its cull reason; checks outputs and
// gradients are finite, and that a culled Gaussian leaves the background and gets zeros.
template <class S>
Cull render_one(const Camera<S>& cam, const Vector3<double>& mean, const Vector3<double>& log_scale,
                const Quaternion<double>& q = Quaternion<double>::Identity(), double eps2d = 0.3,
                double o = 0.8) {
  SplatScene<double> sd;
  sd.C = 3;
  sd.add(mean, q, log_scale, logit(o), {0.2, 0.5, 0.9});
  const auto s = sd.template cast<S>();
  const S bg[3] = {S(0.25), S(0.5), S(0.75)};
  SplatSettings<S> set;
  set.background = bg;
  set.eps2d = S(eps2d);
  RenderWorkspace<S> ws;
  test::Rng rng(1);
  const auto r = test::render<3>(s, cam, set, ws);
  const auto w = test::random_weights(rng, cam.height, cam.width, 3);
  const auto g = test::backward<3>(s, cam, set, ws, w);
  CHECK(splat_all_finite(r.image));
  CHECK(splat_all_finite(r.alpha));
  CHECK(splat_all_finite(r.depth));
  CHECK(splat_all_finite(g.flat()));
  CHECK(splat_all_finite(g.quats_tangent));
  const Cull c = static_cast<Cull>(ws.cull[0]);
  if (c != Cull::none) {
    CHECK(ws.radii[0] == S(0));
    bool background = true;
    for (std::size_t p = 0; p < r.alpha.size(); ++p)
      background = background && r.alpha[p] == S(0) && r.depth[p] == S(0) &&
                   r.image[3 * p] == bg[0] && r.image[3 * p + 1] == bg[1] && r.image[3 * p + 2] == bg[2];
    CHECK(background);
    for (double x : g.flat()) CHECK(x == 0.0);
  }
  return c;
}

}  // namespace

TEST_CASE("depth culling: behind, on the camera plane, inside the near plane, beyond far") {
  auto cam = test::test_camera<double>(32, 24, 30.0);
  cam.far_plane = 100.0;
  const Vector3<double> ls = Vector3<double>::Constant(std::log(0.2));
  CHECK(render_one(cam, Vector3<double>(0.1, 0.0, -2.0), ls) == Cull::depth);    // behind
  CHECK(render_one(cam, Vector3<double>(0.1, 0.0, 0.0), ls) == Cull::depth);     // z = 0
  CHECK(render_one(cam, Vector3<double>(0.0, 0.0, 0.0), ls) == Cull::depth);     // at the centre
  CHECK(render_one(cam, Vector3<double>(0.0, 0.0, 0.005), ls) == Cull::depth);   // z < near
  CHECK(render_one(cam, Vector3<double>(0.0, 0.0, 0.01), ls) == Cull::none);     // z = near: drawn
  CHECK(render_one(cam, Vector3<double>(0.0, 0.0, 100.5), ls) == Cull::depth);   // beyond far
  CHECK(render_one(cam, Vector3<double>(0.0, 0.0, 99.0), Vector3<double>::Constant(std::log(5.0))) == Cull::none);
  // float behaves the same
  const auto camf = test::test_camera<float>(32, 24, 30.0);
  CHECK(render_one(camf, Vector3<double>(0.1, 0.0, -1e-3), ls) == Cull::depth);
  CHECK(render_one(camf, Vector3<double>(0.1, 0.0, 0.0), ls) == Cull::depth);
}

TEST_CASE("near-singular 2D covariances are culled, in float and double") {
  const auto cam = test::test_camera<double>(32, 24, 30.0);
  const auto camf = test::test_camera<float>(32, 24, 30.0);
  // A disc with an exactly zero extent along the camera's y axis, without dilation: the 2D
  // covariance has det = 0.
  const Vector3<double> mean(0.0, 0.0, 3.0);
  const Vector3<double> disc(std::log(0.5), -1e4, std::log(0.5));  // exp(-1e4) == 0
  CHECK(render_one(cam, mean, disc, Quaternion<double>::Identity(), /*eps2d=*/0.0) == Cull::singular);
  CHECK(render_one(camf, mean, disc, Quaternion<double>::Identity(), 0.0) == Cull::singular);
  // The same disc with gsplat's 0.3 px dilation is a legitimate thin ellipse.
  CHECK(render_one(cam, mean, disc, Quaternion<double>::Identity(), 0.3) == Cull::none);
  CHECK(render_one(camf, mean, disc, Quaternion<double>::Identity(), 0.3) == Cull::none);
  // Thin but resolvable without dilation (no cancellation in det = a c - b² when b = 0): drawn.
  const Vector3<double> thin(std::log(0.5), std::log(1e-9), std::log(0.5));
  CHECK(render_one(cam, mean, thin, Quaternion<double>::Identity(), 0.0) == Cull::none);
  // A needle 3000 px long at 45 degrees in the image plane: float cannot resolve its
  // determinant (det / (a c) ~ 1e-7 < 16 eps), double can.
  const Vector3<double> needle(std::log(300.0), std::log(1e-9), std::log(1e-9));
  const Quaternion<double> diag = so3::exp(Vector3<double>(0, 0, M_PI / 4));
  CHECK(render_one(camf, mean, needle, diag) == Cull::singular);
  CHECK(render_one(cam, mean, needle, diag) == Cull::none);
}

TEST_CASE("huge and tiny scales") {
  const auto cam = test::test_camera<double>(32, 24, 30.0);
  const auto camf = test::test_camera<float>(32, 24, 30.0);
  const Vector3<double> mean(0.0, 0.0, 3.0);
  // exp(100) overflows float: the covariance is Inf, the Gaussian is culled, nothing is NaN.
  CHECK(render_one(camf, mean, Vector3<double>::Constant(100.0)) == Cull::singular);
  CHECK(render_one(cam, mean, Vector3<double>::Constant(400.0)) == Cull::singular);
  // A Gaussian far larger than the image covers it with alpha ~ o everywhere.
  {
    SplatScene<double> s;
    s.C = 1;
    s.add(mean, Quaternion<double>::Identity(), Vector3<double>::Constant(12.0), logit(0.6), {1.0});
    RenderWorkspace<double> ws;
    const auto r = test::render<1>(s, cam, {}, ws);
    for (double a : r.alpha) CHECK(a == doctest::Approx(0.6).epsilon(1e-9));
  }
  // A vanishing Gaussian is a dilation-only splat: Σ2D = 0.3 I, alpha = o exp(-d²/0.6).
  {
    SplatScene<double> s;
    s.C = 1;
    s.add(test::world_at_pixel(cam, 10.5, 7.5, 3.0), Quaternion<double>::Identity(),
          Vector3<double>::Constant(-40.0), logit(0.9), {1.0});
    RenderWorkspace<double> ws;
    const auto r = test::render<1>(s, cam, {}, ws);
    CHECK(r.alpha[7 * 32 + 10] == doctest::Approx(0.9).epsilon(1e-12));
    CHECK(r.alpha[7 * 32 + 11] == doctest::Approx(0.9 * std::exp(-1.0 / 0.6)).epsilon(1e-12));
    CHECK(ws.radii[0] == std::ceil(3 * std::sqrt(0.3 + 0.1)));  // lambda_max = b + sqrt(0.01)
  }
}

TEST_CASE("partly off-screen Gaussians are drawn, culled when their box misses the image") {
  const auto cam = test::test_camera<double>(32, 24, 30.0);
  const double z = 3.0, sigma_world = 4.0 * z / 30.0;  // 4 px at the image centre
  const Vector3<double> ls = Vector3<double>::Constant(std::log(sigma_world));
  // The expected decision from the definitions: J with gsplat's clamp of x/z and y/z to
  // 0.3 tan(fov/2) beyond the image, Σ2D = s² J Jᵀ + 0.3 I, radius = ceil(3 sqrt(λmax)),
  // culled when the radius box misses the image.
  auto expected_outside = [&](double u, double v) {
    double xz = (u - cam.cx) / cam.fx, yz = (v - cam.cy) / cam.fy;
    xz = std::clamp(xz, -(cam.cx / cam.fx + 0.3 * 0.5 * cam.width / cam.fx),
                    (cam.width - cam.cx) / cam.fx + 0.3 * 0.5 * cam.width / cam.fx);
    yz = std::clamp(yz, -(cam.cy / cam.fy + 0.3 * 0.5 * cam.height / cam.fy),
                    (cam.height - cam.cy) / cam.fy + 0.3 * 0.5 * cam.height / cam.fy);
    Eigen::Matrix<double, 2, 3> J;
    J << cam.fx / z, 0, -cam.fx * xz / z, 0, cam.fy / z, -cam.fy * yz / z;
    const Matrix2<double> cov = sigma_world * sigma_world * J * J.transpose() + 0.3 * Matrix2<double>::Identity();
    const double b = 0.5 * cov.trace();
    const double r = std::ceil(3 * std::sqrt(b + std::sqrt(std::max(b * b - cov.determinant(), 0.01))));
    return !(u + r > 0 && u - r < cam.width && v + r > 0 && v - r < cam.height);
  };
  int drawn = 0, outside = 0;
  for (double t = 0; t <= 12; t += 0.75) {
    for (const auto& uv : {Vector2<double>(-8 - t, 12.0), Vector2<double>(40 + t, 5.0),
                           Vector2<double>(16.0, -7 - t), Vector2<double>(3.0, 31 + t)}) {
      CAPTURE(uv.transpose());
      const bool out = expected_outside(uv.x(), uv.y());
      CHECK(render_one(cam, test::world_at_pixel(cam, uv.x(), uv.y(), z), ls) ==
            (out ? Cull::outside : Cull::none));
      (out ? outside : drawn)++;
    }
  }
  CHECK(drawn > 8);
  CHECK(outside > 8);

  // Gradients of off-screen Gaussians, one beyond the field-of-view clamp, by central
  // differences (the renderer's own check lives in tests/splat; here the hard geometry).
  SplatScene<double> s;
  s.C = 3;
  test::Rng rng(900);
  for (double u : {-10.0, -25.0, 45.0}) {
    const Vector3<double> big = Vector3<double>::Constant(std::log(12.0 * z / 30.0));
    s.add(test::world_at_pixel(cam, u, rng.uniform(0, 24), z + rng.uniform()), rng.quaternion(),
          big, logit(0.6), {rng.uniform(), rng.uniform(), rng.uniform()});
  }
  const auto w = test::random_weights(rng, cam.height, cam.width, 3);
  RenderWorkspace<double> ws;
  test::render<3>(s, cam, {}, ws);
  for (int g = 0; g < 3; ++g) CHECK(ws.cull[std::size_t(g)] == 0);
  const auto an = test::backward<3>(s, cam, {}, ws, w).flat();
  std::vector<double> fd;
  const double h = 1e-5;
  for (double* p : s.flat()) {
    RenderWorkspace<double> w2;
    fd.push_back(test::central_difference(*p, [&] { return test::loss(test::render<3>(s, cam, {}, w2), w); }, h));
  }
  const double err = test::relative_error(Eigen::Map<const Eigen::VectorXd>(an.data(), Index(an.size())),
                                          Eigen::Map<const Eigen::VectorXd>(fd.data(), Index(fd.size())));
  MESSAGE("off-screen Gaussians, gradient relative error " << err);
  CHECK(err < 1e-7);
}

TEST_CASE("nothing visible, and no Gaussians at all: the background") {
  const auto cam = test::test_camera<float>(20, 10, 20.0);
  const float bg[2] = {0.3f, 0.7f};
  SplatSettings<float> set;
  set.background = bg;
  for (int G : {0, 3}) {
    CAPTURE(G);
    SplatScene<float> s;
    s.C = 2;
    for (int i = 0; i < G; ++i)
      s.add(Vector3<double>(0, 0, -1.0 - i), Quaternion<double>::Identity(), Vector3<double>::Zero(), 0.0, {1, 1});
    RenderWorkspace<float> ws;
    const auto r = test::render<2>(s, cam, set, ws);
    for (std::size_t p = 0; p < r.alpha.size(); ++p) {
      CHECK(r.image[2 * p] == bg[0]);
      CHECK(r.image[2 * p + 1] == bg[1]);
      CHECK(r.alpha[p] == 0.0f);
      CHECK(r.depth[p] == 0.0f);
    }
    test::Rng rng(2);
    const auto g = test::backward<2>(s, cam, set, ws, test::random_weights(rng, 10, 20, 2));
    for (double x : g.flat()) CHECK(x == 0.0);
    CHECK(ws.n_isect == 0);
  }
}

TEST_CASE("validation rejects NaN/Inf, zero quaternions and bad shapes with a clear message") {
  const auto cam = test::test_camera<double>(16, 16, 16.0);
  SplatScene<double> s;
  s.C = 3;
  s.add(Vector3<double>(0, 0, 2), Quaternion<double>::Identity(), Vector3<double>::Zero(), 0.0, {1, 1, 1});
  s.add(Vector3<double>(0, 0, 3), Quaternion<double>::Identity(), Vector3<double>::Zero(), 0.0, {1, 1, 1});
  std::vector<double> img(16 * 16 * 3), alpha(256), depth(256);
  const RenderImages<double> out{{img.data(), 16, 16, 3}, {alpha.data(), 16, 16}, {depth.data(), 16, 16}};
  auto msg = [&](const SplatScene<double>& sc) {
    return validate_render(sc.params(), cam, SplatSettings<double>{}, out, 3).message();
  };
  CHECK(msg(s).empty());
  auto bad = s;
  bad.means[4] = std::numeric_limits<double>::quiet_NaN();
  CHECK(msg(bad) == "means: element [1][1] is NaN");
  bad = s;
  bad.log_scales[0] = std::numeric_limits<double>::infinity();
  CHECK(msg(bad) == "log_scales: element [0][0] is Inf");
  bad = s;
  bad.logits[1] = -std::numeric_limits<double>::infinity();
  CHECK(msg(bad) == "opacity_logits: element [1][0] is Inf");
  bad = s;
  for (int k = 4; k < 8; ++k) bad.quats[std::size_t(k)] = 0.0;
  CHECK(msg(bad) == "quats: element [1] is the zero quaternion");
  bad = s;
  bad.colors[5] = std::numeric_limits<double>::quiet_NaN();
  CHECK(msg(bad) == "colors: element [1][2] is NaN");
  bad = s;
  bad.sh_degree = 4;
  CHECK(msg(bad) == "sh_degree: must be -1 (plain colours) or 0..3, got 4");
  auto p = s.params();
  p.sh_degree = 1;  // 3 columns is not 4 x C
  CHECK(validate_render(p, cam, SplatSettings<double>{}, out, 3).message() ==
        "colors: expected 3 channels x 4 SH coefficients per Gaussian, got 3 columns");
  p = s.params();
  p.quats = {s.quats.data(), 1};
  CHECK(validate_render(p, cam, SplatSettings<double>{}, out, 3).message() ==
        "quats: expected shape [2][4], got [1][4]");
  // camera, settings, outputs
  auto c2 = cam;
  c2.viewmat(0, 1) = 0.5;
  CHECK(validate_render(s.params(), c2, SplatSettings<double>{}, out, 3).message().rfind(
            "viewmat: the 3x3 block is not a rotation", 0) == 0);
  c2 = cam;
  c2.near_plane = 0;
  CHECK(validate_render(s.params(), c2, SplatSettings<double>{}, out, 3).message() ==
        "camera: near plane must be finite and > 0");
  SplatSettings<double> set;
  set.tile_size = 12;
  CHECK(validate_render(s.params(), cam, set, out, 3).message() ==
        "settings: tile_size must be 8, 16 or 32, got 12");
  const double nan_bg[3] = {0, std::nan(""), 0};
  set = {};
  set.background = nan_bg;
  CHECK(validate_render(s.params(), cam, set, out, 3).message() == "background: non-finite value");
  const RenderImages<double> small{{img.data(), 16, 15, 3}, {}, {}};
  CHECK(validate_render(s.params(), cam, SplatSettings<double>{}, small, 3).message() ==
        "image: expected shape [H=16][W=16][C=3], got [16][15][3]");
  // backward: a workspace from another scene
  RenderWorkspace<double> ws;
  std::vector<double> gm(6);
  GaussianGrads<double> grads;
  grads.means = {gm.data(), 2};
  CHECK(validate_render_backward(s.params(), cam, SplatSettings<double>{}, ws, {}, grads).message() ==
        "workspace: does not hold a render_forward of these Gaussians, camera and settings");
  render_forward<3>(s.params(), cam, SplatSettings<double>{}, ws, out);
  CHECK(validate_render_backward(s.params(), cam, SplatSettings<double>{}, ws, {}, grads).is_ok());
  grads.means = {gm.data(), 1};
  CHECK(validate_render_backward(s.params(), cam, SplatSettings<double>{}, ws, {}, grads).message() ==
        "grad means: expected shape [2][3], got [1][3]");
}
