// ModelRenderer<double>::backward against central finite differences of
//   L = sum(image * R) + sum(depth * Rd)
// for every Gaussian parameter (static and DQB-skinned dynamic rows) and for the node positions
// and right-tangent node rotations at the rendered frame and at the points' reference frames.
// The model is built by hand (not init_model) so that every Gaussian sits well inside a tiny
// image, away from the splatter's tile and alpha cut-offs, where L is smooth.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "smg/core/quaternion.hpp"
#include "smg/core/so3.hpp"
#include "support/finite_diff.hpp"
#include "support/random.hpp"
#include "trainer/gaussians.hpp"

namespace {

using trainer::GaussianModel;
using trainer::ModelGrads;
using trainer::ModelRenderer;
using trainer::NodeState;

struct Fixture {
  smg::splat::Camera<double> camera;
  GaussianModel<double> model;
  NodeState<double> nodes;
  std::vector<double> R, Rd;  // loss weights [H][W][3], [H][W]
  int t = 2;                  // rendered frame
};

constexpr int kT = 3, kN = 5, kStatic = 3, kDynamic = 4, kD = 3;

Fixture make_fixture(smg::test::Rng& rng) {
  Fixture f;
  smg::splat::Camera<double>& c = f.camera;
  c.width = 24;
  c.height = 18;
  c.fx = c.fy = 20.0;
  c.cx = 12.0;
  c.cy = 9.0;
  // A camera a little rotated and translated, so that the view matrix is not the identity.
  const Eigen::Matrix3d Rc = smg::so3::exp(Eigen::Vector3d(0.05, -0.04, 0.03)).toRotationMatrix();
  c.viewmat.setIdentity();
  c.viewmat.topLeftCorner<3, 3>() = Rc;
  c.viewmat.topRightCorner<3, 1>() = Eigen::Vector3d(0.02, -0.03, 0.1);

  // Nodes: a small cloud in front of the camera (z ~ 2.5), moving and rotating a little.
  NodeState<double>& n = f.nodes;
  n.frames = kT;
  n.count = kN;
  n.positions.resize(kT * kN * 3);
  n.rotations.resize(kT * kN * 4);
  std::vector<Eigen::Vector3d> base(kN);
  for (int i = 0; i < kN; ++i) base[i] = Eigen::Vector3d(0.25 * rng.uniform(), 0.2 * rng.uniform(), 2.5 + 0.3 * rng.uniform());
  for (int t = 0; t < kT; ++t)
    for (int i = 0; i < kN; ++i) {
      const Eigen::Vector3d p = base[i] + 0.04 * t * rng.vec3();
      for (int k = 0; k < 3; ++k) n.positions[(t * kN + i) * 3 + k] = p(k);
      const Eigen::Quaterniond q = rng.rotation_with_angle(0.3 * rng.uniform(0.2, 1.0));
      smg::to_wxyz(q, n.rotations.data() + (t * kN + i) * 4);
    }

  // Gaussians: static rows first, then dynamic rows holding their reference pose.
  GaussianModel<double>& m = f.model;
  const int G = kStatic + kDynamic;
  m.fixed = kStatic;
  m.table.resize(G);
  m.skin.width = kD;
  m.skin.drivers.assign(kDynamic * kD, -1);
  m.skin.weights.assign(kDynamic * kD, 0.0);
  m.skin.t_ref.assign(kDynamic, 0);
  m.skin.sigma.assign(kN, 0.1);
  for (int r = 0; r < G; ++r) {
    Eigen::Vector3d mean;
    if (r < kStatic) {
      mean = Eigen::Vector3d(0.3 * rng.uniform(), 0.2 * rng.uniform(), 2.2 + 0.8 * rng.uniform(0, 1));
    } else {
      const int p = r - kStatic;
      const int t_ref = p % 2;  // frames 0 and 1; frame 2 is rendered
      m.skin.t_ref[p] = t_ref;
      // Anchor + distinct neighbours; the last point has one padded driver column.
      const int anchor = p % kN;
      const int used = p == kDynamic - 1 ? kD - 1 : kD;
      for (int k = 0; k < used; ++k) {
        m.skin.drivers[p * kD + k] = (anchor + k) % kN;
        m.skin.weights[p * kD + k] = rng.uniform(0.2, 1.0);
      }
      mean = Eigen::Map<const Eigen::Vector3d>(n.positions.data() + (t_ref * kN + anchor) * 3) + 0.05 * rng.vec3();
    }
    for (int k = 0; k < 3; ++k) {
      m.table.means[r * 3 + k] = mean(k);
      // World sigma ~0.25 m: ~2 px at z = 2.5, radius ~6-8 px.
      m.table.log_scales[r * 3 + k] = std::log(0.25 * rng.uniform(0.7, 1.3));
      m.table.colors[r * 3 + k] = rng.uniform(0.1, 0.9);
    }
    const Eigen::Quaterniond q = rng.quaternion();
    const double norm = rng.uniform(0.7, 1.3);  // raw quaternions need not be unit
    m.table.quats[r * 4 + 0] = norm * q.w();
    m.table.quats[r * 4 + 1] = norm * q.x();
    m.table.quats[r * 4 + 2] = norm * q.y();
    m.table.quats[r * 4 + 3] = norm * q.z();
    m.table.opacity[r] = rng.uniform(-1.0, 1.0);  // opacity in (0.27, 0.73): far from alpha_max
  }

  const int pixels = c.width * c.height;
  f.R.resize(pixels * 3);
  f.Rd.resize(pixels);
  for (double& v : f.R) v = rng.uniform();
  for (double& v : f.Rd) v = rng.uniform();
  return f;
}

double loss(const Fixture& f, const GaussianModel<double>& m, const NodeState<double>& n) {
  ModelRenderer<double> r;
  const int pixels = f.camera.width * f.camera.height;
  std::vector<double> image(pixels * 3), depth(pixels);
  r.render(m, n, f.t, f.camera, image.data(), nullptr, depth.data());
  double L = 0;
  for (int k = 0; k < pixels * 3; ++k) L += image[k] * f.R[k];
  for (int k = 0; k < pixels; ++k) L += depth[k] * f.Rd[k];
  return L;
}

// Central differences of L in each entry of a flat parameter array.
Eigen::VectorXd fd_flat(std::vector<double>& x, const std::function<double()>& L, double h = 1e-6) {
  const std::vector<double> g = smg::test::central_gradient(x, L, h);
  return Eigen::Map<const Eigen::VectorXd>(g.data(), static_cast<Eigen::Index>(g.size()));
}

Eigen::VectorXd rg_as_vector(const std::vector<double>& v) {
  return Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

}  // namespace

TEST_CASE("ModelRenderer<double>: backward matches finite differences (Gaussians and nodes)") {
  SMG_TEST_RNG(rng, 7101);
  Fixture f = make_fixture(rng);
  const int G = f.model.count();

  // The fixture must be what the test assumes: everything projected inside the image.
  ModelRenderer<double> renderer;
  const int pixels = f.camera.width * f.camera.height;
  std::vector<double> image(pixels * 3), depth(pixels), alpha(pixels);
  renderer.render(f.model, f.nodes, f.t, f.camera, image.data(), alpha.data(), depth.data());
  for (int r = 0; r < G; ++r) {
    const Eigen::Vector3d p = Eigen::Map<const Eigen::Vector3d>(renderer.posed_means().data() + 3 * r);
    const Eigen::Vector3d pc = f.camera.rotation() * p + f.camera.translation();
    const double u = f.camera.fx * pc.x() / pc.z() + f.camera.cx, v = f.camera.fy * pc.y() / pc.z() + f.camera.cy;
    CAPTURE(r);
    CHECK(u > 4.0);
    CHECK(u < f.camera.width - 4.0);
    CHECK(v > 3.0);
    CHECK(v < f.camera.height - 3.0);
  }
  double max_alpha = 0;
  for (double a : alpha) max_alpha = std::max(max_alpha, a);
  CHECK(max_alpha > 0.3);

  ModelGrads<double> grads;
  grads.zero(G, f.nodes.frames, f.nodes.count);
  renderer.backward(f.model, f.nodes, f.camera, f.R.data(), f.Rd.data(), grads);

  GaussianModel<double> m = f.model;
  NodeState<double> n = f.nodes;
  const std::function<double()> L = [&] { return loss(f, m, n); };
  const double tol = 1e-6;
  // The analytic gradient `an` equals the central differences `fd`, which must not vanish (> floor).
  const auto check_gradient = [&](const Eigen::VectorXd& an, const Eigen::VectorXd& fd, double floor) {
    CHECK(fd.norm() > floor);
    const double error = smg::test::relative_error(an, fd);
    CAPTURE(error);
    CHECK(error < tol);
  };

  SUBCASE("Gaussian parameters") {
    struct Group {
      const char* name;
      std::vector<double>* x;
      const std::vector<double>* g;
      int width;
    } groups[] = {{"means", &m.table.means, &grads.table.means, 3},
                  {"log_scales", &m.table.log_scales, &grads.table.log_scales, 3},
                  {"opacity", &m.table.opacity, &grads.table.opacity, 1},
                  {"colors", &m.table.colors, &grads.table.colors, 3},
                  {"quats (raw)", &m.table.quats, &grads.table.quats, 4}};
    for (const Group& gr : groups) {
      const std::string group = gr.name;
      CAPTURE(group);
      const Eigen::VectorXd fd = fd_flat(*gr.x, L);
      const Eigen::VectorXd an = rg_as_vector(*gr.g);
      // Static and dynamic rows separately, so that one cannot hide the other.
      const Eigen::Index split = static_cast<Eigen::Index>(kStatic) * gr.width;
      const Eigen::VectorXd fd_s = fd.head(split), fd_d = fd.tail(fd.size() - split);
      const Eigen::VectorXd an_s = an.head(split), an_d = an.tail(an.size() - split);
      check_gradient(an_s, fd_s, 1e-3);
      check_gradient(an_d, fd_d, 1e-3);
    }
  }

  SUBCASE("node positions and right-tangent rotations, at the rendered and reference frames") {
    const Eigen::VectorXd fd_x = fd_flat(n.positions, L);
    Eigen::VectorXd fd_q(kT * kN * 3);
    for (int s = 0; s < kT * kN; ++s) {
      const Eigen::Quaterniond q0 = smg::from_wxyz(f.nodes.rotations.data() + 4 * s);
      const auto set = [&](const Eigen::Quaterniond& q) { smg::to_wxyz(q, n.rotations.data() + 4 * s); };
      for (int k = 0; k < 3; ++k) fd_q(3 * s + k) = smg::test::central_difference_tangent(q0, k, set, L);
    }
    const Eigen::VectorXd an_x = rg_as_vector(grads.node_positions), an_q = rg_as_vector(grads.node_rotations);
    // Per frame: the rendered frame (2) and both reference frames (0, 1) must carry gradient.
    for (int t = 0; t < kT; ++t) {
      CAPTURE(t);
      const Eigen::VectorXd fx = fd_x.segment(t * kN * 3, kN * 3), fq = fd_q.segment(t * kN * 3, kN * 3);
      const Eigen::VectorXd ax = an_x.segment(t * kN * 3, kN * 3), aq = an_q.segment(t * kN * 3, kN * 3);
      check_gradient(ax, fx, 1e-3);
      check_gradient(aq, fq, 1e-4);
    }
  }
}

TEST_CASE("ModelRenderer: backward adds into the gradient buffers and a reused renderer gives the same result") {
  SMG_TEST_RNG(rng, 7102);
  Fixture f = make_fixture(rng);
  const int G = f.model.count(), pixels = f.camera.width * f.camera.height;
  std::vector<double> image(pixels * 3), depth(pixels);
  ModelRenderer<double> renderer;
  ModelGrads<double> once, twice;
  once.zero(G, f.nodes.frames, f.nodes.count);
  twice.zero(G, f.nodes.frames, f.nodes.count);
  renderer.render(f.model, f.nodes, f.t, f.camera, image.data(), nullptr, depth.data());
  renderer.backward(f.model, f.nodes, f.camera, f.R.data(), f.Rd.data(), once);
  // Render another frame in between, then the same frame again: the workspace must not leak.
  renderer.render(f.model, f.nodes, 0, f.camera, image.data(), nullptr, depth.data());
  renderer.backward(f.model, f.nodes, f.camera, f.R.data(), f.Rd.data(), twice);
  twice.zero(G, f.nodes.frames, f.nodes.count);
  for (int rep = 0; rep < 2; ++rep) {
    renderer.render(f.model, f.nodes, f.t, f.camera, image.data(), nullptr, depth.data());
    renderer.backward(f.model, f.nodes, f.camera, f.R.data(), f.Rd.data(), twice);
  }
  const auto check_double = [](const std::vector<double>& a, const std::vector<double>& b, const std::string& name) {
    CAPTURE(name);
    REQUIRE(a.size() == b.size());
    double err = 0, ref = 0;
    for (std::size_t k = 0; k < a.size(); ++k) {
      err = std::max(err, std::abs(b[k] - 2 * a[k]));
      ref = std::max(ref, std::abs(a[k]));
    }
    CHECK(ref > 0);
    CHECK(err <= 1e-12 * ref);
  };
  check_double(once.table.means, twice.table.means, "means");
  check_double(once.table.quats, twice.table.quats, "quats");
  check_double(once.table.log_scales, twice.table.log_scales, "log_scales");
  check_double(once.table.opacity, twice.table.opacity, "opacity");
  check_double(once.table.colors, twice.table.colors, "colors");
  check_double(once.node_positions, twice.node_positions, "node_positions");
  check_double(once.node_rotations, twice.node_rotations, "node_rotations");
}

TEST_CASE("ModelRenderer<float> agrees with ModelRenderer<double> (image, depth, gradients)") {
  SMG_TEST_RNG(rng, 7103);
  const Fixture f = make_fixture(rng);
  const auto cast = [](const std::vector<double>& v) { return std::vector<float>(v.begin(), v.end()); };
  GaussianModel<float> mf;
  mf.fixed = f.model.fixed;
  mf.table.means = cast(f.model.table.means);
  mf.table.quats = cast(f.model.table.quats);
  mf.table.log_scales = cast(f.model.table.log_scales);
  mf.table.opacity = cast(f.model.table.opacity);
  mf.table.colors = cast(f.model.table.colors);
  mf.skin.width = f.model.skin.width;
  mf.skin.drivers = f.model.skin.drivers;
  mf.skin.weights = cast(f.model.skin.weights);
  mf.skin.t_ref = f.model.skin.t_ref;
  mf.skin.sigma = cast(f.model.skin.sigma);
  NodeState<float> nf;
  nf.frames = f.nodes.frames;
  nf.count = f.nodes.count;
  nf.positions = cast(f.nodes.positions);
  nf.rotations = cast(f.nodes.rotations);
  smg::splat::Camera<float> cf;
  cf.viewmat = f.camera.viewmat.cast<float>();
  cf.fx = static_cast<float>(f.camera.fx);
  cf.fy = static_cast<float>(f.camera.fy);
  cf.cx = static_cast<float>(f.camera.cx);
  cf.cy = static_cast<float>(f.camera.cy);
  cf.width = f.camera.width;
  cf.height = f.camera.height;
  const std::vector<float> Rf = cast(f.R), Rdf = cast(f.Rd);

  const int G = f.model.count(), pixels = f.camera.width * f.camera.height;
  std::vector<double> image(pixels * 3), depth(pixels);
  std::vector<float> image_f(pixels * 3), depth_f(pixels);
  ModelRenderer<double> rd;
  ModelRenderer<float> rf;
  ModelGrads<double> gd;
  ModelGrads<float> gf;
  gd.zero(G, f.nodes.frames, f.nodes.count);
  gf.zero(G, f.nodes.frames, f.nodes.count);
  rd.render(f.model, f.nodes, f.t, f.camera, image.data(), nullptr, depth.data());
  rf.render(mf, nf, f.t, cf, image_f.data(), nullptr, depth_f.data());
  rd.backward(f.model, f.nodes, f.camera, f.R.data(), f.Rd.data(), gd);
  rf.backward(mf, nf, cf, Rf.data(), Rdf.data(), gf);
  const auto rel = [](const std::vector<float>& a, const std::vector<double>& b) {
    Eigen::VectorXd x(static_cast<Eigen::Index>(a.size()));
    for (std::size_t k = 0; k < a.size(); ++k) x(static_cast<Eigen::Index>(k)) = a[k];
    return smg::test::relative_error(x, rg_as_vector(b));
  };
  CHECK(rel(image_f, image) < 1e-5);
  CHECK(rel(depth_f, depth) < 1e-5);
  const double tol = 1e-3;  // gradients in float: cancellation in the compositing backward
  CHECK(rel(gf.table.means, gd.table.means) < tol);
  CHECK(rel(gf.table.quats, gd.table.quats) < tol);
  CHECK(rel(gf.table.log_scales, gd.table.log_scales) < tol);
  CHECK(rel(gf.table.opacity, gd.table.opacity) < tol);
  CHECK(rel(gf.table.colors, gd.table.colors) < tol);
  CHECK(rel(gf.node_positions, gd.node_positions) < tol);
  CHECK(rel(gf.node_rotations, gd.node_rotations) < tol);
}
