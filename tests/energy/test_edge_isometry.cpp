// smg::edge_isometry (E26, energy/edge_isometry.hpp): the energy against the sum written out
// edge by edge; the gradient against central differences in double and against Eigen's
// AutoDiffScalar (the same code on AD scalars); float against double; bit-identical for 1, 2 and
// 4 threads; every penalty; zero weights, a zero-length edge (with and without the length's
// floor), padding; several frames; the refusals (a NaN rest length, shapes, options).
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "smg/energy/edge_isometry.hpp"
#include "support/autodiff.hpp"
#include "support/random.hpp"

namespace edge_isometry_test {

using smg::Index;

struct IsoScene {
  Index T, N, K;
  std::vector<double> x;           // [T][N][3]
  std::vector<std::int32_t> idx;   // [N][K], −1 padding
  std::vector<double> w, rest;     // [N][K]
  smg::NeighborsView<double, std::int32_t> graph() const { return {idx.data(), w.data(), N, K}; }
  smg::TableView<const double, Eigen::Dynamic> rest_view() const { return {rest.data(), N, K}; }
};

IsoScene iso_scene(Index T, Index N, Index K, unsigned seed) {
  SMG_TEST_RNG(rng, seed);
  IsoScene s{T, N, K, std::vector<double>(std::size_t(3 * T * N)), std::vector<std::int32_t>(std::size_t(N * K), -1),
             std::vector<double>(std::size_t(N * K), 0.0), std::vector<double>(std::size_t(N * K), 0.0)};
  for (auto& v : s.x) v = rng.uniform(-1, 1);
  for (Index i = 0; i < N; ++i) {
    const Index deg = 1 + (i % K);  // rows of 1 .. K neighbours, the rest −1
    for (Index k = 0; k < deg; ++k) {
      s.idx[std::size_t(i * K + k)] = std::int32_t((i + 1 + 3 * k) % N);
      s.w[std::size_t(i * K + k)] = k == 1 ? 0.0 : rng.uniform(0.1, 2.0);  // one zero weight per row
      s.rest[std::size_t(i * K + k)] = rng.uniform(0.2, 1.5);
    }
  }
  return s;
}

// (E26) written out, edge by edge, in double.
double reference(const IsoScene& s, const smg::EdgeIsometryOptions& o) {
  double sum = 0;
  for (Index t = 0; t < s.T; ++t)
    for (Index i = 0; i < s.N; ++i)
      for (Index k = 0; k < s.K; ++k) {
        const std::int32_t j = s.idx[std::size_t(i * s.K + k)];
        if (j < 0) break;
        double aa = o.length_eps;
        for (int d = 0; d < 3; ++d) {
          const double e = s.x[std::size_t(3 * (t * s.N + j) + d)] - s.x[std::size_t(3 * (t * s.N + i) + d)];
          aa += e * e;
        }
        const double r = std::sqrt(aa) - s.rest[std::size_t(i * s.K + k)];
        const double w = s.w[std::size_t(i * s.K + k)];
        if (o.penalty == smg::Penalty::sqrt_weighted)
          sum += o.weight * std::sqrt(w * r * r + o.penalty_eps);
        else if (o.penalty == smg::Penalty::norm)
          sum += o.weight * w * std::abs(r);
        else
          sum += o.weight * w * r * r;
      }
  return sum;
}

template <class S>
double run(const IsoScene& s, const std::vector<S>& x, const smg::EdgeIsometryOptions& o, std::vector<S>* grad,
           int threads = 0) {
  std::vector<S> w(s.w.begin(), s.w.end()), rest(s.rest.begin(), s.rest.end());
  smg::EdgeIsometryOptions oo = o;
  oo.parallel.threads = threads;
  const smg::NeighborsView<S, std::int32_t> g(s.idx.data(), w.data(), s.N, s.K);
  const smg::TableView<const S, Eigen::Dynamic> rv(rest.data(), s.N, s.K);
  const smg::PositionsView<const S> xv(x.data(), s.T, s.N);
  smg::PositionsView<S> gv;
  if (grad) {
    grad->assign(x.size(), S(0));
    gv = smg::PositionsView<S>(grad->data(), s.T, s.N);
  }
  REQUIRE(smg::validate_edge_isometry<S, std::int32_t>(xv, g, rv, oo, gv).is_ok());
  return double(smg::edge_isometry<S, std::int32_t>(xv, g, rv, oo, gv));
}

}  // namespace edge_isometry_test

TEST_CASE("edge_isometry: the energy written out, central differences and AutoDiffScalar, every penalty") {
  using namespace edge_isometry_test;
  for (smg::Penalty p : {smg::Penalty::sqrt_weighted, smg::Penalty::norm, smg::Penalty::squared}) {
    CAPTURE(smg::to_string(p));
    const IsoScene s = iso_scene(2, 23, 5, 3u + unsigned(p));
    smg::EdgeIsometryOptions o;
    o.penalty = p;
    o.weight = 0.7;
    o.penalty_eps = 1e-6;  // large enough to matter in the energy
    std::vector<double> g;
    const double e = run<double>(s, s.x, o, &g);
    CHECK(e == doctest::Approx(reference(s, o)).epsilon(1e-13));
    double worst = 0, scale = 0;
    for (std::size_t a = 0; a < s.x.size(); ++a) {
      std::vector<double> xp = s.x, xm = s.x;
      const double h = 1e-6;
      xp[a] += h;
      xm[a] -= h;
      const double fd = (run<double>(s, xp, o, nullptr) - run<double>(s, xm, o, nullptr)) / (2 * h);
      worst = std::max(worst, std::abs(fd - g[a]));
      scale = std::max(scale, std::abs(g[a]));
    }
    CHECK(worst <= 1e-7 * scale);
    // The same code on AutoDiffScalar: its derivative vector is the gradient.
    using smg::test::AD;
    const Index n = Index(s.x.size());
    std::vector<AD> xa(s.x.size());
    for (Index a = 0; a < n; ++a) xa[std::size_t(a)] = AD(s.x[std::size_t(a)], n, a);
    std::vector<AD> wa(s.w.begin(), s.w.end()), ra(s.rest.begin(), s.rest.end());
    for (auto& v : wa) v.derivatives() = Eigen::VectorXd::Zero(n);
    for (auto& v : ra) v.derivatives() = Eigen::VectorXd::Zero(n);
    const smg::NeighborsView<AD, std::int32_t> ga(s.idx.data(), wa.data(), s.N, s.K);
    const AD ea = smg::edge_isometry<AD, std::int32_t>(smg::PositionsView<const AD>(xa.data(), s.T, s.N), ga,
                                                       smg::TableView<const AD, Eigen::Dynamic>(ra.data(), s.N, s.K), o);
    CHECK(ea.value() == doctest::Approx(e).epsilon(1e-14));
    double ad_worst = 0;
    for (Index a = 0; a < n; ++a) ad_worst = std::max(ad_worst, std::abs(ea.derivatives()(a) - g[std::size_t(a)]));
    CHECK(ad_worst <= 1e-12 * scale);
  }
}

TEST_CASE("edge_isometry: float against double, and bit-identical for 1, 2 and 4 threads") {
  using namespace edge_isometry_test;
  const IsoScene s = iso_scene(3, 700, 8, 11u);
  smg::EdgeIsometryOptions o;
  std::vector<double> gd;
  const double ed = run<double>(s, s.x, o, &gd);
  const std::vector<float> xf(s.x.begin(), s.x.end());
  std::vector<float> g1, g2, g4;
  const double e1 = run<float>(s, xf, o, &g1, 1), e2 = run<float>(s, xf, o, &g2, 2), e4 = run<float>(s, xf, o, &g4, 4);
  CHECK(e1 == e2);
  CHECK(e1 == e4);
  CHECK(std::memcmp(g1.data(), g2.data(), g1.size() * sizeof(float)) == 0);
  CHECK(std::memcmp(g1.data(), g4.data(), g1.size() * sizeof(float)) == 0);
  CHECK(e1 == doctest::Approx(ed).epsilon(1e-6));
  double worst = 0, scale = 0;
  for (std::size_t a = 0; a < gd.size(); ++a) {
    worst = std::max(worst, std::abs(double(g1[a]) - gd[a]));
    scale = std::max(scale, std::abs(gd[a]));
  }
  CHECK(worst <= 1e-5 * scale);
}

TEST_CASE("edge_isometry: a zero-length edge, zero weights, huge and tiny coordinates") {
  using namespace edge_isometry_test;
  IsoScene s = iso_scene(1, 12, 3, 5u);
  for (Index d = 0; d < 3; ++d) s.x[std::size_t(3 * 4 + d)] = s.x[std::size_t(3 * 3 + d)];  // node 3 -> 4 has length 0
  for (double len_eps : {0.0, 1e-20}) {
    smg::EdgeIsometryOptions o;
    o.length_eps = len_eps;
    std::vector<double> g;
    const double e = run<double>(s, s.x, o, &g);
    CHECK(std::isfinite(e));
    for (double v : g) CHECK(std::isfinite(v));
    CHECK(e == doctest::Approx(reference(s, o)).epsilon(1e-13));
  }
  // All weights 0 under sqrt_weighted: each valid edge adds k·sqrt(ε), no gradient.
  std::fill(s.w.begin(), s.w.end(), 0.0);
  smg::EdgeIsometryOptions o;
  std::vector<double> g;
  Index edges = 0;
  for (std::int32_t j : s.idx) edges += j >= 0;
  CHECK(run<double>(s, s.x, o, &g) == doctest::Approx(double(edges) * 1e-10).epsilon(1e-12));
  for (double v : g) CHECK(v == 0.0);
  // Scale: coordinates and rest lengths times 1e6 (and 1e-6) scale the unsquared norm's energy alike.
  IsoScene big = iso_scene(1, 30, 4, 9u), tiny = big, base = big;
  for (auto& v : big.x) v *= 1e6;
  for (auto& v : big.rest) v *= 1e6;
  for (auto& v : tiny.x) v *= 1e-6;
  for (auto& v : tiny.rest) v *= 1e-6;
  smg::EdgeIsometryOptions n;
  n.penalty = smg::Penalty::norm;
  n.length_eps = 0;
  const double e0 = run<double>(base, base.x, n, nullptr);
  CHECK(run<double>(big, big.x, n, nullptr) == doctest::Approx(1e6 * e0).epsilon(1e-12));
  CHECK(run<double>(tiny, tiny.x, n, nullptr) == doctest::Approx(1e-6 * e0).epsilon(1e-12));
}

TEST_CASE("edge_isometry: refusals name the argument") {
  using namespace edge_isometry_test;
  IsoScene s = iso_scene(1, 10, 3, 7u);
  const smg::PositionsView<const double> xv(s.x.data(), 1, 10);
  smg::EdgeIsometryOptions o;
  s.rest[4] = std::numeric_limits<double>::quiet_NaN();
  smg::Status st = smg::validate_edge_isometry<double, std::int32_t>(xv, s.graph(), s.rest_view(), o);
  CHECK(st.message() == "rest: entry [i=1][k=1] is not finite");
  s.rest[4] = 0.5;
  st = smg::validate_edge_isometry<double, std::int32_t>(xv, s.graph(), {s.rest.data(), 9, 3}, o);
  CHECK(st.message().rfind("rest: expected shape [N=10][K=3]", 0) == 0);
  o.penalty_eps = 0;
  st = smg::validate_edge_isometry<double, std::int32_t>(xv, s.graph(), s.rest_view(), o);
  CHECK(st.message() == "EdgeIsometryOptions::penalty_eps must be finite and > 0");
  o = smg::EdgeIsometryOptions();
  o.length_eps = -1;
  CHECK(!smg::validate_edge_isometry<double, std::int32_t>(xv, s.graph(), s.rest_view(), o));
  s.x[7] = std::numeric_limits<double>::infinity();
  CHECK(smg::validate_edge_isometry<double, std::int32_t>(xv, s.graph(), s.rest_view(), smg::EdgeIsometryOptions())
            .message()
            .rfind("positions", 0) == 0);
  // An empty graph (K = 0) and no nodes: energy 0.
  const smg::NeighborsView<double, std::int32_t> none(nullptr, nullptr, 10, 0);
  CHECK(double(smg::edge_isometry<double, std::int32_t>(xv, none, {nullptr, 10, 0}, smg::EdgeIsometryOptions())) == 0.0);
}
