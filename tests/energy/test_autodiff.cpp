// AutoDiffScalar cross-check: the library's own C-ARAP and LRM kernels instantiated with
// Eigen::AutoDiffScalar (forward mode over every position and right-tangent rotation of a tiny
// scene) give the same gradient as the analytic one.
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/autodiff.hpp"
#include "support/prelude.hpp"

using smg::test::AD;
using smg::test::Scene;

namespace {

// The scene as AD arrays: positions are variables 0..3TN-1, rotations q ⊗ Exp(φ) with φ the
// variables 3TN..6TN-1 (at φ = 0), so derivatives are right-tangent gradients.
struct AdScene {
  std::vector<AD> x, q, c, w;
  Index vars = 0;
};
AdScene to_ad(const Scene<double>& s) {
  AdScene a;
  const Index TN = s.T * s.N;
  a.vars = 6 * TN;
  for (Index k = 0; k < 3 * TN; ++k) a.x.push_back(AD(s.x[k], a.vars, k));
  for (Index k = 0; k < TN; ++k) {
    Eigen::Matrix<AD, 3, 1> phi;
    for (int c = 0; c < 3; ++c) phi(c) = AD(0.0, a.vars, 3 * TN + 3 * k + c);
    const Eigen::Quaternion<AD> q0(AD(s.q[4 * k]), AD(s.q[4 * k + 1]), AD(s.q[4 * k + 2]),
                                   AD(s.q[4 * k + 3]));
    const Eigen::Quaternion<AD> r = q0 * smg::so3::exp(phi);
    a.q.push_back(r.w());
    a.q.push_back(r.x());
    a.q.push_back(r.y());
    a.q.push_back(r.z());
  }
  for (double v : s.c) a.c.push_back(AD(v));
  for (double v : s.w) a.w.push_back(AD(v));
  return a;
}

// ‖a − b‖ / ‖b‖ (support/finite_diff.hpp) of an AD derivative vector against a gradient.
double max_rel(const Eigen::VectorXd& a, const std::vector<double>& b) {
  return smg::test::relative_error(a, Eigen::Map<const Eigen::VectorXd>(b.data(), static_cast<Index>(b.size())));
}

}  // namespace

TEST_CASE("C-ARAP: AutoDiffScalar through the kernel equals the analytic gradient") {
  SMG_TEST_RNG(rng, 601);
  const Scene<double> s = smg::test::random_scene(10, 6, 3, rng);
  AdScene a = to_ad(s);
  smg::CarapOptions o;
  smg::ParallelOptions par;
  par.threads = 1;
  const smg::NeighborsView<AD> g(s.idx.data(), a.w.data(), s.N, s.K);
  const AD e = smg::carap<AD>({a.x.data(), s.T, s.N}, {a.q.data(), s.T, s.N},
                              {a.c.data(), s.T, s.N}, g, o, {}, {}, nullptr, par);
  std::vector<double> gx(s.x.size(), 0.0), gr(s.x.size(), 0.0);
  const double ea = smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), o,
                                       {gx.data(), s.T, s.N}, {gr.data(), s.T, s.N});
  CHECK(std::abs(e.value() - ea) <= 1e-12 * ea);
  const Index n = 3 * s.T * s.N;
  CHECK(max_rel(e.derivatives().head(n), gx) < 1e-12);
  CHECK(max_rel(e.derivatives().tail(n), gr) < 1e-12);
}

TEST_CASE("LRM: AutoDiffScalar through the kernel equals the analytic gradient") {
  SMG_TEST_RNG(rng, 602);
  const Scene<double> s = smg::test::random_scene(5, 8, 4, rng);
  AdScene a = to_ad(s);
  smg::ParallelOptions par;
  par.threads = 1;
  const smg::NeighborsView<AD> g(s.idx.data(), a.w.data(), s.N, s.K);
  for (double delta : {0.02, 10.0})
    for (bool detach : {false, true}) {
      const smg::LrmOptions o = smg::test::lrm_options(delta, detach);
      CAPTURE(delta);
      CAPTURE(detach);
      const AD e = smg::lrm<AD>({a.x.data(), s.T, s.N}, {a.c.data(), s.T, s.N}, g, o, {}, nullptr,
                                par);
      std::vector<double> gx(s.x.size(), 0.0);
      const double ea = smg::lrm<double>(s.positions(), s.confidence(), s.graph(), o,
                                         {gx.data(), s.T, s.N});
      CHECK(std::abs(e.value() - ea) <= 1e-12 * ea);
      if (!detach) {
        // Forward-mode AD differentiates ω too: it must equal the exact gradient. (With
        // detach_omega the AD energy still moves ω, so only the exact variant is compared.)
        CHECK(max_rel(e.derivatives().head(3 * s.T * s.N), gx) < 1e-10);
      }
    }
}
