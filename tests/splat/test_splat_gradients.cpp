// Gradients of render_backward against central finite differences of render_forward, in
// double, on tiny images, for every input: means, raw quaternions, right-tangent rotations,
// log-scales, opacity logits, colours / SH coefficients — with image, alpha and depth
// gradients and a background. Scenes avoid the measure-zero places where the rendered
// function is discontinuous (a pixel whose alpha sits within h of 1/255, a transmittance
// exactly at 1e-4, a radius at an integer), so the analytic gradient must match to ~1e-7.
// Step h = 1e-5: the quotient's rounding (eps |L| / h) and truncation (h² L''') are both
// near 1e-10 relative here.
#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "splat_scene.hpp"
#include "support/finite_diff.hpp"

using namespace smg;
using namespace smg::splat;
using smg::test::SplatScene;

namespace {

struct BlockError {
  std::string name;
  double err;
};

// Relative error of each parameter block of the analytic gradient against central
// differences of the loss, plus the right-tangent rotation gradient.
template <int C>
std::vector<BlockError> gradient_errors(SplatScene<double> scene, const Camera<double>& cam,
                                        const SplatSettings<double>& set,
                                        const test::LossWeights& w, double h = 1e-5) {
  RenderWorkspace<double> ws;
  test::render<C>(scene, cam, set, ws);
  const auto grads = test::backward<C>(scene, cam, set, ws, w);
  auto L = [&]() {
    RenderWorkspace<double> ws2;
    return test::loss(test::render<C>(scene, cam, set, ws2, 1), w);
  };
  std::vector<double> fd;
  for (double* p : scene.flat()) fd.push_back(test::central_difference(*p, L, h));
  const std::vector<double> an = grads.flat();
  std::vector<BlockError> out;
  std::size_t off = 0;
  auto block = [&](const std::string& name, std::size_t n) {
    Eigen::Map<const Eigen::VectorXd> a(an.data() + off, Index(n)), f(fd.data() + off, Index(n));
    out.push_back({name, test::relative_error(a, f, 1e-9)});
    off += n;
  };
  block("means", scene.means.size());
  block("quats (raw)", scene.quats.size());
  block("log_scales", scene.log_scales.size());
  block("opacity_logits", scene.logits.size());
  block("colors", scene.colors.size());

  // Right tangent: L(q̂ ⊗ Exp(φ)) at φ = 0, per Gaussian.
  Eigen::VectorXd tan_fd(3 * scene.G), tan_an(3 * scene.G);
  for (Index g = 0; g < scene.G; ++g) {
    const Quaternion<double> q0 = from_wxyz(scene.quats.data() + 4 * g);
    for (int k = 0; k < 3; ++k) {
      double l[2];
      for (int s = 0; s < 2; ++s) {
        Vector3<double> phi = Vector3<double>::Zero();
        phi(k) = s == 0 ? h : -h;
        const Quaternion<double> q = q0.normalized() * so3::exp(phi);
        to_wxyz(q, scene.quats.data() + 4 * g);
        l[s] = L();
      }
      to_wxyz(q0, scene.quats.data() + 4 * g);
      tan_fd(3 * g + k) = (l[0] - l[1]) / (2 * h);
      tan_an(3 * g + k) = grads.quats_tangent[static_cast<std::size_t>(3 * g + k)];
    }
  }
  out.push_back({"quats (right tangent)", test::relative_error(tan_an, tan_fd, 1e-9)});
  return out;
}

void check_all(const std::vector<BlockError>& errs, double tol) {
  for (const auto& e : errs) {
    CAPTURE(e.name);
    MESSAGE(e.name << ": relative error " << e.err);
    CHECK(e.err < tol);
  }
}

// Large Gaussians on a tiny image: every pixel is far inside every Gaussian's alpha >= 1/255
// region, so the test is free of the threshold discontinuity.
SplatScene<double> large_scene(test::Rng& rng, const Camera<double>& cam, Index n, Index C,
                               double o_max = 0.7) {
  return test::random_scene(rng, cam, n, C, /*sigma_px=*/14.0, 2.0, 5.0, 0.2, o_max, 0.2);
}

}  // namespace

TEST_CASE("render gradients match central differences: RGB, background, image+alpha+depth") {
  SMG_TEST_RNG(rng, 601);
  const auto cam = test::test_camera<double>(24, 20, 18.0, rng.quaternion(), rng.vec3(0.3));
  const auto scene = large_scene(rng, cam, 6, 3);
  const double bg[3] = {0.2, -0.4, 0.7};
  SplatSettings<double> set;
  set.background = bg;
  const auto w = test::random_weights(rng, cam.height, cam.width, 3);
  check_all(gradient_errors<3>(scene, cam, set, w), 1e-7);
}

TEST_CASE("render gradients match central differences: SH degrees 0..3") {
  for (int degree = 0; degree <= 3; ++degree) {
    CAPTURE(degree);
    SMG_TEST_RNG(rng, 610 + std::uint64_t(degree));
    const auto cam = test::test_camera<double>(20, 18, 16.0, rng.quaternion(), rng.vec3(0.3));
    auto scene = large_scene(rng, cam, 4, 3);
    scene.sh_degree = degree;
    scene.colors.clear();
    const Index K = sh_basis_count(degree);
    for (Index k = 0; k < scene.G * K * 3; ++k)
      scene.colors.push_back(k % (K * 3) < 3 ? rng.uniform(0.5, 1.5) : 0.4 * rng.uniform(-1, 1));
    const auto w = test::random_weights(rng, cam.height, cam.width, 3);
    check_all(gradient_errors<3>(scene, cam, SplatSettings<double>{}, w), 1e-7);
  }
}

TEST_CASE("render gradients: dynamic channel count, small Gaussians crossing tiles") {
  // Smaller Gaussians (about 3 px) on a 40x36 image with 8-pixel tiles: pixels at the
  // alpha = 1/255 contour and Gaussians binned to subsets of tiles. The seed is fixed; no
  // pixel sits within h of a discontinuity.
  SMG_TEST_RNG(rng, 620);
  const auto cam = test::test_camera<double>(40, 36, 30.0, rng.quaternion(), rng.vec3(0.2));
  const auto scene = test::random_scene(rng, cam, 12, 2, 3.0, 2.0, 5.0, 0.3, 0.8);
  SplatSettings<double> set;
  set.tile_size = 8;
  const double bg[2] = {0.5, 0.25};
  set.background = bg;
  const auto w = test::random_weights(rng, cam.height, cam.width, 2);
  check_all(gradient_errors<Eigen::Dynamic>(scene, cam, set, w), 1e-6);
}

TEST_CASE("render gradients with the 0.99 clamp and early termination active") {
  // Opaque Gaussians stacked on the same pixels: alpha_raw > 0.99 near their centres (the
  // clamp's flat side passes no opacity/footprint gradient) and the transmittance reaches
  // 1e-4 after a few of them (later ones get no gradient from those pixels).
  SMG_TEST_RNG(rng, 630);
  const auto cam = test::test_camera<double>(24, 20, 18.0);
  SplatScene<double> scene;
  scene.C = 3;
  for (int i = 0; i < 5; ++i) {
    const double z = 2.0 + 0.5 * i;
    const Vector3<double> m = test::world_at_pixel(cam, 9.3 + 1.1 * i, 8.7 + 0.6 * i, z);
    const double sigma = 9.0 * z / 18.0;
    scene.add(m, rng.quaternion(), Vector3<double>(std::log(sigma), std::log(0.8 * sigma), std::log(sigma)),
              std::log(0.998 / 0.002), {rng.uniform(0, 1), rng.uniform(0, 1), rng.uniform(0, 1)});
  }
  SplatSettings<double> set;
  RenderWorkspace<double> ws;
  test::render<3>(scene, cam, set, ws);
  // The setting does what it says: opacities above the clamp (o = 0.998 > 0.99 at the
  // centres), and pixels that stopped before the end of their tile's list.
  int terminated = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Index tile = Index(y / 16) * ws.tiles_x + x / 16;
      terminated += ws.last[std::size_t(y) * std::size_t(cam.width) + std::size_t(x)] < ws.tile_offsets[std::size_t(tile) + 1] - 1;
    }
  CHECK(terminated > 50);
  const auto w = test::random_weights(rng, cam.height, cam.width, 3);
  // Opacity-logit gradients are small here (o (1 - o) = 0.002), so their relative error
  // carries more of the difference quotient's rounding.
  check_all(gradient_errors<3>(scene, cam, set, w), 2e-6);
}

TEST_CASE("gsplat v1.x alpha clamp 0.999 is a setting and differentiates too") {
  test::Rng rng(640);
  const auto cam = test::test_camera<double>(20, 16, 16.0);
  auto scene = large_scene(rng, cam, 3, 3, 0.9);
  SplatSettings<double> set;
  set.alpha_max = 0.999;
  const auto w = test::random_weights(rng, cam.height, cam.width, 3);
  check_all(gradient_errors<3>(scene, cam, set, w), 1e-7);
}
