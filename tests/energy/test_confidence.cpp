// Tests of smg/energy/confidence.hpp: the reference, visibility, the separate motion and
// rigidity factors, determinism, rigid scenes, a corrupted node, invariances, float vs double.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "energy/reference_energies.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "support/prelude.hpp"

using smg::test::Scene;

namespace {

struct Conf {
  std::vector<double> c, m, r;
};

template <class S = double>
Conf run(const Scene<double>& sd, const smg::ConfidenceOptions& o, bool vis = true,
         int threads = 1) {
  const Scene<S> s = sd.cast<S>();
  std::vector<S> c(s.v.size()), m(s.v.size()), r(s.v.size());
  smg::ParallelOptions par;
  par.threads = threads;
  smg::node_confidences<S>(s.positions(),
                           vis ? s.visibility() : smg::VisibilityView<const std::uint8_t>(),
                           s.graph(), o, {c.data(), s.T, s.N}, {m.data(), s.T, s.N},
                           {r.data(), s.T, s.N}, nullptr, par);
  return {std::vector<double>(c.begin(), c.end()), std::vector<double>(m.begin(), m.end()),
          std::vector<double>(r.begin(), r.end())};
}

double max_abs_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double d = 0;
  for (std::size_t k = 0; k < a.size(); ++k) d = std::max(d, std::abs(a[k] - b[k]));
  return d;
}

}  // namespace

TEST_CASE("confidence matches the reference, with and without visibility") {
  SMG_TEST_RNG(rng, 301);
  for (Index T : {1, 2, 7}) {
    const Scene<double> s = smg::test::random_scene(T, 15, 6, rng);
    smg::ConfidenceOptions o;
    o.kappa_m = 1.7;
    o.kappa_r = 3.1;
    o.lambda_m = 0.5;
    o.lambda_r = 2.0;
    o.eps = 1e-3;
    for (bool vis : {true, false}) {
      CAPTURE(T);
      CAPTURE(vis);
      std::vector<double> c, m, r;
      // The reference in long double: (E4) differences lengths that barely change, so a double
      // reference would carry cancellation errors of its own (~5e-14 in c^r here).
      smg::test::ref::confidence<long double>(s, o, vis, c, m, r);
      const Conf got = run(s, o, vis);
      CHECK(max_abs_diff(got.c, c) < 1e-14);
      CHECK(max_abs_diff(got.m, m) < 1e-14);
      // c^r divides |e_i − ē_i| by the spread of the e_j: near-rigid neighbourhoods make that
      // ill-conditioned, and double lands ~3e-14 from the long-double value here (2.4e-14 with
      // the plain difference of lengths, 3.2e-14 with the cancellation-free one: both rounding).
      CHECK(max_abs_diff(got.r, r) < 1e-13);
    }
  }
}

TEST_CASE("confidence: visibility is only the final factor; outputs are optional") {
  SMG_TEST_RNG(rng, 302);
  const Scene<double> s = smg::test::random_scene(6, 12, 5, rng);
  const Conf a = run(s, {}, true), b = run(s, {}, false);
  CHECK(a.m == b.m);
  CHECK(a.r == b.r);
  for (std::size_t k = 0; k < s.v.size(); ++k) {
    CHECK(a.c[k] == (s.v[k] ? b.c[k] : 0.0));
    CHECK(b.c[k] == doctest::Approx(b.m[k] * b.r[k]).epsilon(1e-14));  // λ = 1
    CHECK(b.c[k] >= 0.0);
    CHECK(b.c[k] <= 1.0);
  }
  // Only the combined confidence requested.
  std::vector<double> c(s.v.size());
  smg::node_confidences<double>(s.positions(), s.visibility(), s.graph(), {}, {c.data(), s.T, s.N});
  CHECK(c == a.c);
}

TEST_CASE("confidence is bit-identical for 1, 2 and 7 threads") {
  SMG_TEST_RNG(rng, 303);
  const Scene<double> s = smg::test::random_scene(9, 300, 8, rng);
  const Conf a = run(s, {}, true, 1), b = run(s, {}, true, 2), c = run(s, {}, true, 7);
  CHECK(a.c == b.c);
  CHECK(a.c == c.c);
  CHECK(a.m == c.m);
  CHECK(a.r == c.r);
}

TEST_CASE("confidence: a rigidly translating scene gives 1; a rotating one stays near 1") {
  SMG_TEST_RNG(rng, 304);
  const Scene<double> tr = smg::test::rigid_scene(8, 200, 10, 0.0, Vector3<double>(0.01, 0.02, -0.03), rng);
  const Conf a = run(tr, {});
  for (double v : a.c) CHECK(v == doctest::Approx(1.0).epsilon(1e-9));
  // Rotation: edge lengths are constant (c^r = 1 up to rounding), velocities vary linearly
  // across a neighbourhood, so c^m is below 1 only by how far a node sits from its
  // neighbours' centroid (boundary nodes of the cloud).
  const Scene<double> rot = smg::test::rigid_scene(8, 200, 10, 0.05, Vector3<double>(0.01, 0, 0), rng);
  const Conf b = run(rot, {});
  std::vector<double> sorted = b.c;
  std::sort(sorted.begin(), sorted.end());
  const double mean = std::accumulate(b.c.begin(), b.c.end(), 0.0) / double(b.c.size());
  const double p10 = sorted[sorted.size() / 10];
  CAPTURE(mean);
  CAPTURE(p10);
  CAPTURE(sorted.front());
  CHECK(mean > 0.9);
  CHECK(p10 > 0.8);
  CHECK(sorted.front() > 0.3);
  for (double v : b.r) CHECK(v > 1.0 - 1e-6);
}

TEST_CASE("confidence: one corrupted node is flagged, its neighbours are not") {
  SMG_TEST_RNG(rng, 305);
  Scene<double> s = smg::test::rigid_scene(6, 300, 12, 0.02, Vector3<double>(0.02, 0, 0), rng);
  const Index bad = 17, t = 3;
  s.set_pos(t, bad, s.pos(t, bad) + Vector3<double>(0.05, -0.04, 0.03));  // one-frame glitch
  const Conf a = run(s, {});
  // Frames 2 and 3 see the glitch in u^2 = x^3 − x^2 and u^3 = x^4 − x^3.
  for (Index f : {Index(2), Index(3)}) {
    CAPTURE(f);
    CHECK(a.c[f * s.N + bad] < 0.05);
    std::vector<double> nb;
    for (Index k = 0; k < s.K; ++k) nb.push_back(a.c[f * s.N + s.idx[bad * s.K + k]]);
    std::sort(nb.begin(), nb.end());
    CAPTURE(nb.front());
    CHECK(nb[nb.size() / 2] > 0.8);  // median neighbour stays confident
    CHECK(nb.front() > 0.3);
  }
  // Frames the glitch does not touch: the node is confident again.
  CHECK(a.c[0 * s.N + bad] > 0.5);
  CHECK(a.c[5 * s.N + bad] > 0.5);
}

TEST_CASE("confidence is invariant to a global rigid transform and covariant with scale") {
  SMG_TEST_RNG(rng, 306);
  const Scene<double> s = smg::test::random_scene(6, 40, 6, rng);
  const Scene<double> m = smg::test::transformed(s, rng.quaternion(), rng.vec3(5.0));
  const Conf a = run(s, {}), b = run(m, {});
  CHECK(max_abs_diff(a.c, b.c) < 1e-9);
  // Scaling positions by 1e3 and ε with them leaves every ratio unchanged.
  Scene<double> big = s;
  for (double& v : big.x) v *= 1e3;
  smg::ConfidenceOptions o;
  o.eps *= 1e3;
  const Conf c = run(big, o);
  CHECK(max_abs_diff(a.c, c.c) < 1e-9);
}

TEST_CASE("confidence: float agrees with double") {
  SMG_TEST_RNG(rng, 307);
  const Scene<double> s = smg::test::random_scene(8, 100, 8, rng);
  const Conf d = run<double>(s, {}), f = run<float>(s, {});
  // c^r divides a difference of edge-length changes (E4) by their spread: where the motion is
  // near rigid that ratio is ill-conditioned, and one entry of 800 sits near 1e-4 in float
  // whatever the rounding order (measured 1.2e-4 with correctly rounded square roots, 6e-5 with
  // Eigen's approximate packet sqrt). The mean error says whether the float path is accurate:
  // 6.0e-7 (c^r), 2.5e-7 (c), 2.7e-8 (c^m) with the cancellation-free ℓ⁺ − ℓ⁻ of
  // confidence_edge_change, against 1.1e-6 / 6.0e-7 / 2.7e-8 before it.
  auto mean_abs_diff = [](const std::vector<double>& a, const auto& b) {
    double sum = 0;
    for (std::size_t k = 0; k < a.size(); ++k) sum += std::abs(a[k] - double(b[k]));
    return sum / double(a.size());
  };
  CHECK(max_abs_diff(d.c, f.c) < 1e-4);
  CHECK(max_abs_diff(d.m, f.m) < 1e-4);
  CHECK(max_abs_diff(d.r, f.r) < 2e-4);
  CHECK(mean_abs_diff(d.c, f.c) < 5e-7);
  CHECK(mean_abs_diff(d.m, f.m) < 1e-7);
  CHECK(mean_abs_diff(d.r, f.r) < 1e-6);
}

TEST_CASE("confidence: validation names the argument") {
  Rng rng(308);
  const Scene<double> s = smg::test::random_scene(3, 5, 2, rng);
  std::vector<double> c(s.v.size());
  smg::ConfidenceOptions o;
  CHECK(smg::validate_confidence<double>(s.positions(), s.visibility(), s.graph(), o,
                                         {c.data(), s.T, s.N})
            .is_ok());
  o.kappa_m = 0;
  CHECK(smg::validate_confidence<double>(s.positions(), s.visibility(), s.graph(), o,
                                         {c.data(), s.T, s.N})
            .message() == "ConfidenceOptions.kappa_m must be finite and > 0, got 0");
  Scene<double> bad = s;
  bad.x[7] = std::nan("");
  CHECK(smg::validate_confidence<double>(bad.positions(), s.visibility(), s.graph(), {},
                                         {c.data(), s.T, s.N})
            .message() == "positions: element [t=0][i=2] is NaN");
  CHECK(smg::validate_confidence<double>(s.positions(), s.visibility(), s.graph(), {},
                                         {c.data(), s.T, s.N - 1})
            .message() == "confidence: expected shape [T=3][N=5], got [T=3][N=4]");
}
