// Hard cases of smg/energy: degenerate neighbourhoods (collinear, coincident, single neighbour),
// zero-length edges, isolated nodes, T = 1 and 2, huge and tiny coordinates, zero confidences,
// gaps past the end, empty graphs, and NaN/Inf inputs rejected by validation. Each has a
// defined behaviour (docs/math/energy.md, "Hard cases").
#include <doctest/doctest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <vector>

#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/prelude.hpp"

using smg::test::Scene;

namespace {

struct All {
  double carap = 0, lrm = 0;
  std::vector<double> gx_c, gr_c, gx_l, conf;
};

template <class S = double>
All evaluate(const Scene<double>& sd, smg::LrmOptions lo = {}, double eps = 1e-4) {
  const Scene<S> s = sd.cast<S>();
  All a;
  std::vector<S> gx(s.x.size(), S(0)), gr(s.x.size(), S(0)), gl(s.x.size(), S(0)),
      c(s.v.size(), S(0));
  smg::ConfidenceOptions co;
  co.eps = eps;  // a length: scaled with the scene in the scale test
  smg::node_confidences<S>(s.positions(), s.visibility(), s.graph(), co, {c.data(), s.T, s.N});
  smg::FrameScalarsView<const S> cv(c.data(), s.T, s.N);
  a.carap = double(smg::carap<S>(s.positions(), s.rotations(), cv, s.graph(), {},
                                 {gx.data(), s.T, s.N}, {gr.data(), s.T, s.N}));
  a.lrm = double(smg::lrm<S>(s.positions(), cv, s.graph(), lo, {gl.data(), s.T, s.N}));
  a.gx_c.assign(gx.begin(), gx.end());
  a.gr_c.assign(gr.begin(), gr.end());
  a.gx_l.assign(gl.begin(), gl.end());
  a.conf.assign(c.begin(), c.end());
  return a;
}

bool all_finite(const All& a) {
  if (!std::isfinite(a.carap) || !std::isfinite(a.lrm)) return false;
  for (const auto* v : {&a.gx_c, &a.gr_c, &a.gx_l, &a.conf})
    for (double x : *v)
      if (!std::isfinite(x)) return false;
  return true;
}

double lrm_fd_error(const Scene<double>& s, const smg::LrmOptions& o, double h) {
  std::vector<double> g(s.x.size(), 0.0);
  smg::lrm<double>(s.positions(), {}, s.graph(), o, {g.data(), s.T, s.N});
  Scene<double> p = s;
  const std::vector<double> f =
      smg::test::central_gradient(p.x, [&] { return smg::lrm<double>(p.positions(), {}, p.graph(), o); }, h);
  return smg::test::relative_error(g, f, 1e-150);
}

double carap_fd_error(const Scene<double>& s, double h) {
  std::vector<double> g(s.x.size(), 0.0);
  smg::carap<double>(s.positions(), s.rotations(), {}, s.graph(), {}, {g.data(), s.T, s.N});
  Scene<double> p = s;
  const std::vector<double> f = smg::test::central_gradient(
      p.x, [&] { return smg::carap<double>(p.positions(), p.rotations(), {}, p.graph(), {}); }, h);
  return smg::test::relative_error(g, f, 1e-150);
}

// Node 0 with neighbours 1..n placed by `place(t, k)`; other rows empty.
Scene<double> star(Index T, Index n, Rng& rng,
                   const std::function<Vector3<double>(Index, Index)>& place) {
  Scene<double> s = smg::test::random_scene(T, n + 1, n, rng);
  std::fill(s.idx.begin(), s.idx.end(), -1);
  std::fill(s.w.begin(), s.w.end(), 0.0);
  for (Index k = 0; k < n; ++k) {
    s.idx[k] = static_cast<std::int32_t>(k + 1);
    s.w[k] = 1.0 / double(n);
  }
  for (Index t = 0; t < T; ++t)
    for (Index k = 0; k < n; ++k) s.set_pos(t, k + 1, place(t, k));
  return s;
}

}  // namespace

TEST_CASE("collinear neighbourhood: finite everything; the regularised solve is smooth") {
  SMG_TEST_RNG(rng, 801);
  const Vector3<double> dir = Vector3<double>(1, 2, -1).normalized();
  Scene<double> s = star(5, 6, rng, [&](Index t, Index k) {
    return Vector3<double>((0.3 * double(k) + 0.05 * double(t * k % 3)) * dir +
                           Vector3<double>(0.01 * double(t), 0, 0));
  });
  const All a = evaluate(s);
  CHECK(all_finite(a));
  CHECK(a.lrm > 0);
  // ω along the line is decided by μ (b has no component there); the energy and the exact
  // gradient do not depend on it.
  std::vector<double> om(s.x.size());
  smg::lrm<double>(s.positions(), {}, s.graph(), {}, {}, nullptr, {}, {om.data(), s.T, s.N});
  for (double v : om) CHECK(std::isfinite(v));
  smg::LrmOptions o;
  CHECK(lrm_fd_error(s, o, 1e-7) < 1e-5);
}

TEST_CASE("coincident neighbours: trace(A) = 0 gives omega = 0 and finite gradients") {
  SMG_TEST_RNG(rng, 802);
  const Vector3<double> p0(0.2, -0.1, 0.4);
  Scene<double> s = star(4, 5, rng, [&](Index t, Index k) {
    return Vector3<double>(p0 + Vector3<double>(0.01 * double(t * (k + 1)), 0, 0) * (t == 2 ? 0.0 : 1.0));
  });
  // At t = 2 every neighbour sits at p0: ω = 0 there by definition (pinned); the energy is
  // finite (Σ ŵ ρ(‖ũ‖)) but not continuous at that point, since any spread lets ω fit.
  std::vector<double> om(s.x.size(), 1.0);
  smg::lrm<double>(s.positions(), {}, s.graph(), {}, {}, nullptr, {}, {om.data(), s.T, s.N});
  CHECK(om[(2 * s.N + 0) * 3] == 0.0);
  CHECK(om[(2 * s.N + 0) * 3 + 1] == 0.0);
  const All a = evaluate(s);
  CHECK(all_finite(a));
  smg::LrmResidualBlock<double> b;
  CHECK(smg::lrm_residual_block<double>(s.positions(), {}, s.graph(), {}, 2, 0, b));
  CHECK(b.J_x.allFinite());
  CHECK(b.J_u.allFinite());
}

TEST_CASE("a single neighbour: LRM adds exactly 0 (x̃ = ũ = 0)") {
  Rng rng(803);
  Scene<double> s = star(4, 1, rng, [&](Index t, Index) { return Vector3<double>(0.1 * double(t), 0, 0); });
  std::vector<double> g(s.x.size(), 0.0);
  CHECK(smg::lrm<double>(s.positions(), {}, s.graph(), {}, {g.data(), s.T, s.N}) == 0.0);
  for (double v : g) CHECK(v == 0.0);
}

TEST_CASE("zero-length edges: the length term's derivative at 0 is 0; central FD agrees") {
  SMG_TEST_RNG(rng, 804);
  Scene<double> s = smg::test::random_scene(6, 6, 3, rng);
  // Node idx[0] coincides with node 0 at frames 1 and 4.
  const Index j = s.idx[0];
  for (Index t : {Index(1), Index(4)}) s.set_pos(t, j, s.pos(t, 0));
  const All a = evaluate(s);
  CHECK(all_finite(a));
  CHECK(carap_fd_error(s, 1e-6) < 1e-6);
  smg::CarapResidualBlock<double> b;
  CHECK(smg::carap_residual_block<double>(s.positions(), s.rotations(), {}, s.graph(), {}, 0, 1, 0,
                                          0, b));
  CHECK(b.J_xj_t.row(3).norm() == 0.0);  // ‖d^t‖ = 0: no length direction
  CHECK(b.J_xj_s.allFinite());
}

TEST_CASE("isolated nodes and empty rows: pinned confidence, zero energy terms") {
  SMG_TEST_RNG(rng, 805);
  Scene<double> s = smg::test::random_scene(5, 8, 3, rng);
  for (Index k = 0; k < s.K; ++k) {  // node 3 has no neighbours
    s.idx[3 * s.K + k] = -1;
    s.w[3 * s.K + k] = 0.0;
  }
  std::vector<double> c(s.v.size()), m(s.v.size()), r(s.v.size());
  smg::ConfidenceOptions o;
  smg::node_confidences<double>(s.positions(), {}, s.graph(), o, {c.data(), s.T, s.N},
                                {m.data(), s.T, s.N}, {r.data(), s.T, s.N});
  for (Index t = 0; t < s.T; ++t) {
    // Empty sums are 0: v̄ = 0, s^v = 0, e = ē = 0 (docs/design.md pinned).
    const double u = smg::velocity(s.positions(), t, 3).norm();
    CHECK(r[t * s.N + 3] == 1.0);
    CHECK(m[t * s.N + 3] == doctest::Approx(std::exp(-std::pow(u / (o.kappa_m * o.eps), 2))));
  }
  const All a = evaluate(s);
  CHECK(all_finite(a));
  // All rows empty: every energy is 0.
  std::fill(s.idx.begin(), s.idx.end(), -1);
  std::fill(s.w.begin(), s.w.end(), 0.0);
  const All z = evaluate(s);
  CHECK(z.carap == 0.0);
  CHECK(z.lrm == 0.0);
  for (double v : z.gx_c) CHECK(v == 0.0);
  // K = 0 columns.
  const smg::NeighborsView<double> none(nullptr, nullptr, s.N, 0);
  CHECK(smg::carap<double>(s.positions(), s.rotations(), {}, none, {}) == 0.0);
  CHECK(smg::lrm<double>(s.positions(), {}, none, {}) == 0.0);
}

TEST_CASE("T = 1 and T = 2: velocities by the pinned time rule") {
  SMG_TEST_RNG(rng, 806);
  const Scene<double> one = smg::test::random_scene(1, 10, 4, rng);
  const All a = evaluate(one);
  CHECK(all_finite(a));
  CHECK(a.carap == 0.0);  // no pair of frames
  CHECK(a.lrm == 0.0);    // u = 0
  for (std::size_t k = 0; k < one.v.size(); ++k)
    CHECK(a.conf[k] == (one.v[k] ? doctest::Approx(1.0) : doctest::Approx(0.0)));
  const Scene<double> two = smg::test::random_scene(2, 7, 4, rng);
  smg::LrmOptions o;
  o.huber_delta = 0.05;
  CHECK(lrm_fd_error(two, o, 1e-6) < 1e-7);
  CHECK(carap_fd_error(two, 1e-6) < 1e-7);
}

TEST_CASE("huge and tiny coordinates: energies scale as s^2, gradients as s, float included") {
  SMG_TEST_RNG(rng, 807);
  const Scene<double> s = smg::test::random_scene(6, 30, 6, rng, true);
  smg::LrmOptions lo;
  lo.huber_delta = 1e9;  // quadratic zone at every scale (δ_H is a length per frame)
  const All base = evaluate(s, lo);
  for (double scale : {1e-6, 1e6}) {
    CAPTURE(scale);
    Scene<double> p = s;
    for (double& v : p.x) v *= scale;
    smg::LrmOptions ls = lo;
    ls.huber_delta = lo.huber_delta * scale;
    const All d = evaluate<double>(p, ls, 1e-4 * scale);
    CHECK(all_finite(d));
    CHECK(d.carap == doctest::Approx(base.carap * scale * scale).epsilon(1e-9));
    CHECK(d.lrm == doctest::Approx(base.lrm * scale * scale).epsilon(1e-9));
    const All f = evaluate<float>(p, ls, 1e-4 * scale);
    CHECK(all_finite(f));
    CHECK(f.carap == doctest::Approx(d.carap).epsilon(1e-4));
    CHECK(f.lrm == doctest::Approx(d.lrm).epsilon(1e-3));
  }
}

TEST_CASE("gaps past the end and zero gap weights add nothing") {
  Rng rng(808);
  const Scene<double> s = smg::test::random_scene(5, 8, 3, rng);
  smg::CarapOptions o;
  o.gaps = {{5, 1.0}, {100, 1.0}, {1, 0.0}};
  std::vector<double> g(s.x.size(), 0.0);
  CHECK(smg::carap<double>(s.positions(), s.rotations(), {}, s.graph(), o, {g.data(), s.T, s.N}) == 0.0);
  for (double v : g) CHECK(v == 0.0);
  CHECK(smg::carap_term_count(s.graph(), s.T, o.gaps) == 4 * smg::edge_count(s.graph()));
}

TEST_CASE("NaN and Inf inputs are rejected by validation, naming the argument") {
  Rng rng(809);
  const Scene<double> s = smg::test::random_scene(3, 5, 2, rng);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  Scene<double> b = s;
  b.x[4] = inf;
  CHECK(smg::validate_carap<double>(b.positions(), b.rotations(), {}, b.graph(), {}).message() ==
        "positions: element [t=0][i=1] is Inf");
  CHECK(smg::validate_lrm<double>(b.positions(), {}, b.graph(), {}).message() ==
        "positions: element [t=0][i=1] is Inf");
  b = s;
  b.q[9] = nan;
  CHECK(smg::validate_carap<double>(b.positions(), b.rotations(), {}, b.graph(), {}).message() ==
        "rotations: element [t=0][i=2] is NaN");
  b = s;
  b.c[3] = nan;
  CHECK(smg::validate_lrm<double>(b.positions(), b.confidence(), b.graph(), {}).message() ==
        "confidence: element [t=0][i=3] is not in [0, 1]");
  b = s;
  b.w[0] = nan;
  CHECK(smg::validate_confidence<double>(b.positions(), {}, b.graph(), {}, {}).message() ==
        "graph: entry [i=0][k=0] has a weight that is negative or not finite");
  smg::LrmOptions o;
  o.huber_delta = inf;
  CHECK(!smg::validate_lrm<double>(s.positions(), {}, s.graph(), o).is_ok());
  smg::CarapOptions c;
  c.gaps = {{1, nan}};
  CHECK(smg::validate_carap<double>(s.positions(), s.rotations(), {}, s.graph(), c).message() ==
        "CarapOptions.gaps[0].weight must be finite and >= 0, got nan");
}
