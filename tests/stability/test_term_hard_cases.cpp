// The values single terms pin on the hard cases (docs/math/energy.md, "Hard cases"): LRM's ω and
// residual block where the neighbours are collinear or coincident, C-ARAP's residual block on a
// zero-length edge, the confidences' pinned factors at an isolated node, how C-ARAP and LRM scale
// with the coordinates, C-ARAP's term count with gaps past the end. What every operator must do
// on these cases (finite outputs, gradients against central differences, no edge energy without
// edges, NaN/Inf refused, ...) is test_energy_hard_cases.cpp's, over the operator list.
#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/prelude.hpp"

using smg::test::Scene;

namespace {

// LRM's ω [T][N][3] on s (default options, confidences 1), every entry `fill` beforehand.
std::vector<double> lrm_omega(const Scene<double>& s, double fill) {
  std::vector<double> om(s.x.size(), fill);
  smg::lrm<double>(s.positions(), {}, s.graph(), {}, {}, nullptr, {}, {om.data(), s.T, s.N});
  return om;
}

// C-ARAP and LRM on a scene, with the confidences the scene's visibility gives.
struct CarapLrm {
  double carap = 0, lrm = 0;
};

template <class S = double>
CarapLrm carap_lrm(const Scene<double>& sd, smg::LrmOptions lo, double eps) {
  const Scene<S> s = sd.cast<S>();
  std::vector<S> c(s.v.size(), S(0));
  smg::ConfidenceOptions co;
  co.eps = eps;  // a length: scaled with the scene
  smg::node_confidences<S>(s.positions(), s.visibility(), s.graph(), co, {c.data(), s.T, s.N});
  const smg::FrameScalarsView<const S> cv(c.data(), s.T, s.N);
  CarapLrm r;
  r.carap = double(smg::carap<S>(s.positions(), s.rotations(), cv, s.graph(), {}));
  r.lrm = double(smg::lrm<S>(s.positions(), cv, s.graph(), lo));
  return r;
}

}  // namespace

TEST_CASE("LRM on a collinear neighbourhood: ω finite (decided by μ along the line), energy above 0") {
  SMG_TEST_RNG(rng, 801);
  const Vector3<double> dir = Vector3<double>(1, 2, -1).normalized();
  const Scene<double> s = smg::test::star_scene(5, 6, rng, [&](Index t, Index k) {
    return Vector3<double>((0.3 * double(k) + 0.05 * double(t * k % 3)) * dir + Vector3<double>(0.01 * double(t), 0, 0));
  });
  // ω along the line is decided by μ (b has no component there); the energy and the exact
  // gradient do not depend on it (test_energy_hard_cases.cpp differentiates them).
  CHECK(smg::lrm<double>(s.positions(), {}, s.graph(), {}) > 0);
  for (double v : lrm_omega(s, 0.0)) CHECK(std::isfinite(v));
}

TEST_CASE("LRM on coincident neighbours: trace(A) = 0 gives omega = 0 and a finite residual block") {
  SMG_TEST_RNG(rng, 802);
  const Vector3<double> p0(0.2, -0.1, 0.4);
  const Scene<double> s = smg::test::star_scene(4, 5, rng, [&](Index t, Index k) {
    return Vector3<double>(p0 + Vector3<double>(0.01 * double(t * (k + 1)), 0, 0) * (t == 2 ? 0.0 : 1.0));
  });
  // At t = 2 every neighbour sits at p0: ω = 0 there by definition (pinned); the energy is
  // finite (Σ ŵ ρ(‖ũ‖)) but not continuous at that point, since any spread lets ω fit.
  const std::vector<double> om = lrm_omega(s, 1.0);
  CHECK(om[(2 * s.N + 0) * 3] == 0.0);
  CHECK(om[(2 * s.N + 0) * 3 + 1] == 0.0);
  smg::LrmResidualBlock<double> b;
  CHECK(smg::lrm_residual_block<double>(s.positions(), {}, s.graph(), {}, 2, 0, b));
  CHECK(b.J_x.allFinite());
  CHECK(b.J_u.allFinite());
}

TEST_CASE("LRM with a single neighbour adds exactly 0 (x̃ = ũ = 0)") {
  Rng rng(803);
  const Scene<double> s = smg::test::star_scene(4, 1, rng, [&](Index t, Index) { return Vector3<double>(0.1 * double(t), 0, 0); });
  std::vector<double> g(s.x.size(), 0.0);
  CHECK(smg::lrm<double>(s.positions(), {}, s.graph(), {}, {g.data(), s.T, s.N}) == 0.0);
  for (double v : g) CHECK(v == 0.0);
}

TEST_CASE("C-ARAP on zero-length edges: the length term's derivative at 0 is 0; its residual block") {
  SMG_TEST_RNG(rng, 804);
  Scene<double> s = smg::test::zero_length_edge_scene(rng);  // node 0's edge 0 at frames 1 and 4
  // Central differences to 1e-6 (every operator's check in test_energy_hard_cases.cpp allows the
  // collinear neighbourhoods' 1e-5).
  std::vector<double> g(s.x.size(), 0.0);
  smg::carap<double>(s.positions(), s.rotations(), {}, s.graph(), {}, {g.data(), s.T, s.N});
  const std::vector<double> f = smg::test::central_gradient(
      s.x, [&] { return smg::carap<double>(s.positions(), s.rotations(), {}, s.graph(), {}); });
  CHECK(smg::test::relative_error(g, f, 1e-150) < 1e-6);
  smg::CarapResidualBlock<double> b;
  CHECK(smg::carap_residual_block<double>(s.positions(), s.rotations(), {}, s.graph(), {}, 0, 1, 0, 0, b));
  CHECK(b.J_xj_t.row(3).norm() == 0.0);  // ‖d^t‖ = 0: no length direction
  CHECK(b.J_xj_s.allFinite());
}

TEST_CASE("confidences of an isolated node: empty sums are 0, so r = 1 and m from the velocity alone") {
  SMG_TEST_RNG(rng, 805);
  Scene<double> s = smg::test::random_scene(5, 8, 3, rng);
  smg::test::isolate_node(s, 3);
  std::vector<double> c(s.v.size()), m(s.v.size()), r(s.v.size());
  smg::ConfidenceOptions o;
  smg::node_confidences<double>(s.positions(), {}, s.graph(), o, {c.data(), s.T, s.N}, {m.data(), s.T, s.N},
                                {r.data(), s.T, s.N});
  for (Index t = 0; t < s.T; ++t) {
    // Empty sums are 0: v̄ = 0, s^v = 0, e = ē = 0 (docs/design.md pinned).
    const double u = smg::velocity(s.positions(), t, 3).norm();
    CHECK(r[t * s.N + 3] == 1.0);
    CHECK(m[t * s.N + 3] == doctest::Approx(std::exp(-std::pow(u / (o.kappa_m * o.eps), 2))));
  }
}

TEST_CASE("LRM on two frames with Huber's linear zone: the gradient matches central differences") {
  SMG_TEST_RNG(rng, 806);
  Scene<double> two = smg::test::random_scene(2, 7, 4, rng);
  smg::LrmOptions o;
  o.huber_delta = 0.05;
  std::vector<double> g(two.x.size(), 0.0);
  smg::lrm<double>(two.positions(), {}, two.graph(), o, {g.data(), two.T, two.N});
  const std::vector<double> f =
      smg::test::central_gradient(two.x, [&] { return smg::lrm<double>(two.positions(), {}, two.graph(), o); });
  CHECK(smg::test::relative_error(g, f, 1e-150) < 1e-7);
}

TEST_CASE("C-ARAP and LRM at huge and tiny coordinates: energies scale as s^2, float included") {
  SMG_TEST_RNG(rng, 807);
  const Scene<double> s = smg::test::random_scene(6, 30, 6, rng, true);
  smg::LrmOptions lo;
  lo.huber_delta = 1e9;  // quadratic zone at every scale (δ_H is a length per frame)
  const CarapLrm base = carap_lrm(s, lo, 1e-4);
  for (double scale : {1e-6, 1e6}) {
    CAPTURE(scale);
    Scene<double> p = s;
    for (double& v : p.x) v *= scale;
    smg::LrmOptions ls = lo;
    ls.huber_delta = lo.huber_delta * scale;
    const CarapLrm d = carap_lrm<double>(p, ls, 1e-4 * scale);
    CHECK(d.carap == doctest::Approx(base.carap * scale * scale).epsilon(1e-9));
    CHECK(d.lrm == doctest::Approx(base.lrm * scale * scale).epsilon(1e-9));
    const CarapLrm f = carap_lrm<float>(p, ls, 1e-4 * scale);
    CHECK(std::isfinite(f.carap));
    CHECK(std::isfinite(f.lrm));
    CHECK(f.carap == doctest::Approx(d.carap).epsilon(1e-4));
    CHECK(f.lrm == doctest::Approx(d.lrm).epsilon(1e-3));
  }
}

TEST_CASE("C-ARAP's term count with gaps past the end and a zero gap weight; its gap message") {
  Rng rng(808);
  const Scene<double> s = smg::test::random_scene(5, 8, 3, rng);
  smg::CarapOptions o;
  o.gaps = {{5, 1.0}, {100, 1.0}, {1, 0.0}};
  // The zero-weight gap's pairs are counted (mean normalisation's denominator), the others are
  // past the end.
  CHECK(smg::carap_term_count(s.graph(), s.T, o.gaps) == 4 * smg::edge_count(s.graph()));
  smg::CarapOptions c;
  c.gaps = {{1, std::numeric_limits<double>::quiet_NaN()}};
  CHECK(smg::validate_carap<double>(s.positions(), s.rotations(), {}, s.graph(), c).message() ==
        "CarapOptions.gaps[0].weight must be finite and >= 0, got nan");
}
