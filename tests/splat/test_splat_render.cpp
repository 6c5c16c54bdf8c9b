// Forward semantics of the splatter against closed forms: one Gaussian's footprint, two
// Gaussians' ordering and occlusion, the exclusive transmittance rule, the alpha skip, the
// background and expected depth; invariances (tile size, thread count, workspace reuse);
// float against double.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "splat_scene.hpp"
#include "support/finite_diff.hpp"

using namespace smg;
using namespace smg::splat;
using smg::test::SplatScene;

namespace {

double logit(double o) { return std::log(o / (1 - o)); }

// The dilated 2D covariance of a Gaussian, written out from its definition (not from the
// library): Σ2D = J W R S² Rᵀ Wᵀ Jᵀ + 0.3 I, J = [fx/z 0 -fx x/z²; 0 fy/z -fy y/z²].
Matrix2<double> closed_form_cov2d(const Camera<double>& cam, const Vector3<double>& mean,
                                  const Quaternion<double>& q, const Vector3<double>& scale) {
  const Matrix3<double> W = cam.viewmat.topLeftCorner<3, 3>();
  const Vector3<double> p = W * mean + cam.viewmat.topRightCorner<3, 1>();
  Eigen::Matrix<double, 2, 3> J;
  J << cam.fx / p.z(), 0, -cam.fx * p.x() / (p.z() * p.z()), 0, cam.fy / p.z(),
      -cam.fy * p.y() / (p.z() * p.z());
  const Matrix3<double> R = q.normalized().toRotationMatrix();
  const Matrix3<double> Sigma = R * scale.cwiseAbs2().asDiagonal() * R.transpose();
  return J * W * Sigma * W.transpose() * J.transpose() + 0.3 * Matrix2<double>::Identity();
}

}  // namespace

TEST_CASE("one Gaussian: projected mean, radius and footprint match the closed form") {
  SMG_TEST_RNG(rng, 701);
  const auto cam = test::test_camera<double>(50, 40, 40.0, rng.rotation_with_angle(0.3),
                                             Vector3<double>(0.1, -0.2, 0.3));
  const Vector3<double> mean = test::world_at_pixel(cam, 21.3, 17.8, 3.5);
  const Quaternion<double> q = rng.quaternion();
  const Vector3<double> scale(0.12, 0.05, 0.2);
  const double o = 0.8;
  const double color[2] = {0.9, 0.3};
  const double bg[2] = {0.1, 0.6};
  SplatScene<double> scene;
  scene.C = 2;
  scene.add(mean, q, scale.array().log().matrix(), logit(o), {color[0], color[1]});
  SplatSettings<double> set;
  set.background = bg;
  RenderWorkspace<double> ws;
  const auto r = test::render<2>(scene, cam, set, ws);

  const Matrix2<double> cov = closed_form_cov2d(cam, mean, q, scale);
  const Matrix2<double> Q = cov.inverse();
  const double b = 0.5 * cov.trace();
  const double lambda = b + std::sqrt(std::max(b * b - cov.determinant(), 0.01));
  const double radius = std::ceil(3 * std::sqrt(lambda));
  CHECK(ws.radii[0] == radius);
  CHECK(std::abs(ws.means2d[0] - 21.3) < 1e-12);
  CHECK(std::abs(ws.means2d[1] - 17.8) < 1e-12);
  CHECK(std::abs(ws.depths[0] - 3.5) < 1e-12);

  // Tiles touched: [floor((m - r)/16), ceil((m + r)/16)).
  const int tx0 = int(std::floor((21.3 - radius) / 16)), tx1 = int(std::ceil((21.3 + radius) / 16));
  const int ty0 = int(std::floor((17.8 - radius) / 16)), ty1 = int(std::ceil((17.8 + radius) / 16));
  int drawn = 0, skipped_by_threshold = 0;
  double max_err = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const Vector2<double> d(21.3 - (x + 0.5), 17.8 - (y + 0.5));
      double alpha = std::min(0.99, o * std::exp(-0.5 * d.dot(Q * d)));
      const bool binned = x / 16 >= tx0 && x / 16 < tx1 && y / 16 >= ty0 && y / 16 < ty1;
      if (alpha < 1.0 / 255) {
        skipped_by_threshold += binned;
        alpha = 0;
      }
      if (!binned) alpha = 0;
      drawn += alpha > 0;
      const std::size_t p = std::size_t(y) * std::size_t(cam.width) + std::size_t(x);
      for (int k = 0; k < 2; ++k)
        max_err = std::max(max_err, std::abs(r.image[2 * p + k] - (alpha * color[k] + (1 - alpha) * bg[k])));
      max_err = std::max(max_err, std::abs(r.alpha[p] - alpha));
      max_err = std::max(max_err, std::abs(r.depth[p] - (alpha > 0 ? 3.5 : 0.0)));
    }
  MESSAGE("footprint: " << drawn << " pixels drawn, max error " << max_err);
  CHECK(drawn > 30);
  CHECK(skipped_by_threshold > 0);  // the 1/255 skip is exercised
  CHECK(max_err < 1e-12);
}

TEST_CASE("two Gaussians: front-to-back by depth regardless of index order, ties by index") {
  const auto cam = test::test_camera<double>(32, 32, 30.0);
  const double o_near = 0.6, o_far = 0.7;
  auto make = [&](bool near_first, double z_far) {
    SplatScene<double> s;
    s.C = 3;
    const Vector3<double> near = test::world_at_pixel(cam, 16.0, 16.0, 2.0);
    const Vector3<double> far = test::world_at_pixel(cam, 16.0, 16.0, z_far);
    const Vector3<double> ls_near = Vector3<double>::Constant(std::log(0.3 * 2.0 / 30.0 * 10));
    const Vector3<double> ls_far = Vector3<double>::Constant(std::log(0.3 * z_far / 30.0 * 10));
    auto add_near = [&] { s.add(near, Quaternion<double>::Identity(), ls_near, logit(o_near), {1, 0, 0}); };
    auto add_far = [&] { s.add(far, Quaternion<double>::Identity(), ls_far, logit(o_far), {0, 1, 0}); };
    if (near_first) { add_near(); add_far(); } else { add_far(); add_near(); }
    return s;
  };
  RenderWorkspace<double> ws;
  const auto a = test::render<3>(make(true, 4.0), cam, {}, ws);
  const auto b = test::render<3>(make(false, 4.0), cam, {}, ws);
  CHECK(std::memcmp(a.image.data(), b.image.data(), a.image.size() * sizeof(double)) == 0);
  // Centre pixel (16, 16) is at distance (0.5, 0.5) from both means: alpha = o exp(-½ dᵀQd).
  const std::size_t p = 16 * 32 + 16;
  const double s_near = 3.0, s_far = 3.0;  // both project to 3 px std
  auto alpha_at = [&](double o, double s) {
    const double var = s * s + 0.3;
    return o * std::exp(-0.5 * 0.5 / var);
  };
  const double an = alpha_at(o_near, s_near), af = alpha_at(o_far, s_far);
  CHECK(a.image[3 * p + 0] == doctest::Approx(an).epsilon(1e-12));
  CHECK(a.image[3 * p + 1] == doctest::Approx((1 - an) * af).epsilon(1e-12));
  CHECK(a.alpha[p] == doctest::Approx(1 - (1 - an) * (1 - af)).epsilon(1e-12));
  CHECK(a.depth[p] == doctest::Approx((an * 2.0 + (1 - an) * af * 4.0) / (1 - (1 - an) * (1 - af))).epsilon(1e-12));

  // Equal depths: the lower index is in front.
  const auto c = test::render<3>(make(true, 2.0), cam, {}, ws);
  const auto d = test::render<3>(make(false, 2.0), cam, {}, ws);
  CHECK(c.image[3 * p + 0] == doctest::Approx(an).epsilon(1e-12));        // red (index 0) in front
  CHECK(d.image[3 * p + 1] == doctest::Approx(alpha_at(o_far, s_near)).epsilon(1e-12));  // green in front
}

TEST_CASE("transmittance rule: a Gaussian that would take T to <= 1e-4 is not composited") {
  // Three wide, opaque Gaussians clamped at alpha_max = 0.98 on every pixel: T goes 1 ->
  // 0.02 -> 4e-4, and the third would give 8e-6 <= 1e-4, so it is excluded (exclusive rule).
  const auto cam = test::test_camera<double>(16, 16, 16.0);
  SplatScene<double> s;
  s.C = 3;
  const double colors[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int i = 0; i < 3; ++i) {
    const double z = 2.0 + i;
    s.add(test::world_at_pixel(cam, 8.0, 8.0, z), Quaternion<double>::Identity(),
          Vector3<double>::Constant(std::log(500.0 * z / 16.0)), logit(0.9999),
          {colors[i][0], colors[i][1], colors[i][2]});
  }
  SplatSettings<double> set;
  set.alpha_max = 0.98;
  RenderWorkspace<double> ws;
  const auto r = test::render<3>(s, cam, set, ws);
  for (std::size_t p = 0; p < 256; ++p) {
    CAPTURE(p);
    CHECK(r.image[3 * p + 0] == doctest::Approx(0.98).epsilon(1e-14));
    CHECK(r.image[3 * p + 1] == doctest::Approx(0.02 * 0.98).epsilon(1e-12));
    CHECK(r.image[3 * p + 2] == 0.0);
    CHECK(r.alpha[p] == doctest::Approx(1 - 4e-4).epsilon(1e-14));
  }
  // With only the first two the pixel is identical: the third contributed nothing.
  SplatScene<double> two = s;
  two.G = 2;
  two.means.resize(6); two.quats.resize(8); two.log_scales.resize(6); two.logits.resize(2); two.colors.resize(6);
  const auto r2 = test::render<3>(two, cam, set, ws);
  CHECK(std::memcmp(r.image.data(), r2.image.data(), r.image.size() * sizeof(double)) == 0);
}

TEST_CASE("alpha skip: opacity just below 1/255 draws nothing, just above draws") {
  const auto cam = test::test_camera<double>(16, 16, 16.0);
  for (double o : {0.999 / 255, 1.01 / 255}) {
    SplatScene<double> s;
    s.C = 1;
    s.add(test::world_at_pixel(cam, 8.0, 8.0, 2.0), Quaternion<double>::Identity(),
          Vector3<double>::Constant(std::log(100.0 * 2.0 / 16.0)), logit(o), {1.0});
    RenderWorkspace<double> ws;
    const auto r = test::render<1>(s, cam, {}, ws);
    const double centre = r.alpha[8 * 16 + 8];
    if (o < 1.0 / 255) {
      CHECK(centre == 0.0);
      CHECK(ws.cull[0] == std::uint8_t(Cull::transparent));
      CHECK(ws.radii[0] == 0.0);
    } else {
      CHECK(centre > 1.0 / 255);
    }
  }
}

TEST_CASE("with radius_sigmas >= 3.33 the image does not depend on the tile size") {
  // Every pixel with alpha >= 1/255 lies within sqrt(2 ln(255 * 0.99)) = 3.32 sigma, so a
  // 3.4-sigma radius bins each Gaussian to every tile it can draw on, for any tile size.
  SMG_TEST_RNG(rng, 702);
  const auto cam = test::test_camera<double>(70, 45, 60.0, rng.rotation_with_angle(0.2));
  const auto scene = test::random_scene(rng, cam, 300, 3, 2.5);
  SplatSettings<double> set;
  set.radius_sigmas = 3.4;
  std::vector<double> ref;
  for (int ts : {16, 8, 32}) {
    CAPTURE(ts);
    set.tile_size = ts;
    RenderWorkspace<double> ws;
    const auto r = test::render<3>(scene, cam, set, ws);
    if (ref.empty()) {
      ref = r.image;
    } else {
      CHECK(std::memcmp(ref.data(), r.image.data(), ref.size() * sizeof(double)) == 0);
    }
  }
  // At gsplat's 3 sigma the tile size matters, but only for faint contributions.
  set.radius_sigmas = 3.0;
  double max_diff = 0;
  std::vector<double> r16;
  for (int ts : {16, 8}) {
    set.tile_size = ts;
    RenderWorkspace<double> ws;
    const auto r = test::render<3>(scene, cam, set, ws);
    if (r16.empty()) r16 = r.image;
    else
      for (std::size_t k = 0; k < r.image.size(); ++k) max_diff = std::max(max_diff, std::abs(r.image[k] - r16[k]));
  }
  MESSAGE("3-sigma radius, tile 8 vs 16: max pixel difference " << max_diff);
  CHECK(max_diff < 0.05);
}

TEST_CASE("forward and backward are bit-identical for 1, 2 and 7 threads") {
  SMG_TEST_RNG(rng, 703);
  const auto cam = test::test_camera<float>(97, 61, 80.0f, rng.rotation_with_angle(0.4));
  const auto scene = test::random_scene(rng, cam, 2000, 3, 2.0).cast<float>();
  const auto w = test::random_weights(rng, cam.height, cam.width, 3);
  RenderWorkspace<float> ws;
  const auto r1 = test::render<3>(scene, cam, {}, ws, 1);
  const auto g1 = test::backward<3>(scene, cam, {}, ws, w, 1);
  for (int threads : {2, 7}) {
    CAPTURE(threads);
    RenderWorkspace<float> wsn;
    const auto rn = test::render<3>(scene, cam, {}, wsn, threads);
    const auto gn = test::backward<3>(scene, cam, {}, wsn, w, threads);
    CHECK(std::memcmp(r1.image.data(), rn.image.data(), r1.image.size() * sizeof(float)) == 0);
    CHECK(std::memcmp(r1.alpha.data(), rn.alpha.data(), r1.alpha.size() * sizeof(float)) == 0);
    CHECK(std::memcmp(r1.depth.data(), rn.depth.data(), r1.depth.size() * sizeof(float)) == 0);
    CHECK(g1.flat() == gn.flat());
    CHECK(g1.quats_tangent == gn.quats_tangent);
    CHECK(g1.means2d == gn.means2d);
  }
}

TEST_CASE("a warmed-up workspace is reused without reallocation") {
  test::Rng rng(704);
  const auto cam = test::test_camera<float>(64, 48, 50.0f);
  const auto scene = test::random_scene(rng, cam, 500, 3, 2.0).cast<float>();
  const auto w = test::random_weights(rng, cam.height, cam.width, 3);
  RenderWorkspace<float> ws;
  test::render<3>(scene, cam, {}, ws);
  test::backward<3>(scene, cam, {}, ws, w);
  const auto* proj = ws.proj.data();
  const auto* lists = ws.tile_gauss.data();
  const auto* grads = ws.isect_grad.data();
  const auto* scratch = ws.scratch.data();
  // the depth sort ping-pongs between two buffers: either may hold the result
  const auto* order = ws.order.data();
  const auto* order_tmp = ws.order_tmp.data();
  for (int it = 0; it < 3; ++it) {
    test::render<3>(scene, cam, {}, ws);
    test::backward<3>(scene, cam, {}, ws, w);
  }
  CHECK(ws.proj.data() == proj);
  CHECK(ws.tile_gauss.data() == lists);
  CHECK(ws.isect_grad.data() == grads);
  CHECK(ws.scratch.data() == scratch);
  CHECK((ws.order.data() == order || ws.order.data() == order_tmp));
  CHECK((ws.order_tmp.data() == order || ws.order_tmp.data() == order_tmp));
}

TEST_CASE("float agrees with double on images and gradients") {
  SMG_TEST_RNG(rng, 705);
  const auto camd = test::test_camera<double>(80, 60, 70.0, rng.rotation_with_angle(0.3));
  const auto camf = test::test_camera<float>(80, 60, 70.0, Quaternion<double>(camd.viewmat.topLeftCorner<3, 3>()));
  const auto scene = test::random_scene(rng, camd, 800, 3, 2.5);
  const auto w = test::random_weights(rng, camd.height, camd.width, 3);
  RenderWorkspace<double> wsd;
  RenderWorkspace<float> wsf;
  const auto rd = test::render<3>(scene, camd, {}, wsd);
  const auto rf = test::render<3>(scene.cast<float>(), camf, {}, wsf);
  double img = 0, alpha = 0;
  for (std::size_t k = 0; k < rd.image.size(); ++k) img = std::max(img, std::abs(rd.image[k] - rf.image[k]));
  for (std::size_t k = 0; k < rd.alpha.size(); ++k) alpha = std::max(alpha, std::abs(rd.alpha[k] - rf.alpha[k]));
  const auto gd = test::backward<3>(scene, camd, {}, wsd, w).flat();
  const auto gf = test::backward<3>(scene.cast<float>(), camf, {}, wsf, w).flat();
  const double grad = test::relative_error(Eigen::Map<const Eigen::VectorXd>(gf.data(), Index(gf.size())),
                                           Eigen::Map<const Eigen::VectorXd>(gd.data(), Index(gd.size())));
  MESSAGE("float vs double: image max abs " << img << ", alpha max abs " << alpha
                                            << ", gradient relative " << grad);
  CHECK(img < 1e-4);
  CHECK(alpha < 1e-4);
  CHECK(grad < 1e-3);
}
