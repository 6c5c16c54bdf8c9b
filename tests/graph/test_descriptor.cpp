// Tests of smg/graph/descriptor.hpp: (G7)-(G8) by hand, robustness to outlier samples, ties,
// zero samples, invisible frames, against a plain pairwise reference, float vs double,
// determinism, validation.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <vector>

#include "smg/graph/descriptor.hpp"
#include "support/random.hpp"

using smg::Index;

namespace {

template <class S>
struct Samples {
  Index T = 0, N = 0, C = 0;
  std::vector<S> g;                  // [T][N][C]
  std::vector<std::uint8_t> v;       // [T][N], empty: all visible
  S* at(Index t, Index i) { return g.data() + (t * N + i) * C; }
  smg::FeatureSamplesView<const S> view() const { return {g.data(), T, N, C}; }
  smg::VisibilityView<const std::uint8_t> vis() const {
    return v.empty() ? smg::VisibilityView<const std::uint8_t>() : smg::VisibilityView<const std::uint8_t>(v.data(), T, N);
  }
};

// T x N x C samples, all `value`, all visible.
template <class S>
Samples<S> samples(Index T, Index N, Index C, S value = S(0)) {
  Samples<S> s;
  s.T = T;
  s.N = N;
  s.C = C;
  s.g.assign(static_cast<std::size_t>(T * N * C), value);
  return s;
}

template <class S>
std::vector<S> describe(const Samples<S>& s, double rho, smg::DescriptorStats* stats = nullptr, int threads = 0) {
  std::vector<S> f(static_cast<std::size_t>(s.N * s.C), S(-9));
  smg::DescriptorOptions o;
  o.rho = rho;
  o.parallel.threads = threads;
  REQUIRE(smg::validate_semantic_descriptors<S>(s.view(), s.vis(), o, {f.data(), s.N, s.C}).is_ok());
  const auto st = smg::semantic_descriptors<S>(s.view(), s.vis(), o, {f.data(), s.N, s.C});
  if (stats) *stats = st;
  return f;
}

// (G7)-(G8) with an explicit O(n^2) mean of pairwise cosines.
std::vector<double> reference_descriptor(const Samples<double>& s, Index i, double rho) {
  std::vector<std::vector<double>> u;
  for (Index t = 0; t < s.T; ++t) {
    if (!s.v.empty() && !s.v[static_cast<std::size_t>(t * s.N + i)]) continue;
    const double* p = s.g.data() + (t * s.N + i) * s.C;
    double n = 0;
    for (Index c = 0; c < s.C; ++c) n += p[c] * p[c];
    n = std::sqrt(n);
    std::vector<double> w(static_cast<std::size_t>(s.C), 0.0);
    for (Index c = 0; c < s.C; ++c) w[static_cast<std::size_t>(c)] = n > 0 ? p[c] / n : 0.0;
    u.push_back(w);
  }
  const std::size_t n = u.size();
  std::vector<double> f(static_cast<std::size_t>(s.C), 0.0);
  if (n == 0) return f;
  std::vector<double> score(n, 0.0);
  for (std::size_t a = 0; a < n; ++a) {
    for (std::size_t b = 0; b < n; ++b)
      if (a != b) score[a] += std::inner_product(u[a].begin(), u[a].end(), u[b].begin(), 0.0);
    if (n > 1) score[a] /= static_cast<double>(n - 1);
  }
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return score[a] > score[b]; });
  const std::size_t keep = std::max<std::size_t>(1, static_cast<std::size_t>(std::floor(rho * static_cast<double>(n) + 1e-9)));
  for (std::size_t q = 0; q < keep; ++q)
    for (Index c = 0; c < s.C; ++c) f[static_cast<std::size_t>(c)] += u[order[q]][static_cast<std::size_t>(c)];
  double norm = 0;
  for (double x : f) norm += x * x;
  norm = std::sqrt(norm);
  for (double& x : f) x = norm > 0 ? x / norm : 0.0;
  return f;
}

}  // namespace

TEST_CASE_TEMPLATE("descriptor: hand-computed cases", S, float, double) {
  // One node, C = 2. Frames: a = (2, 0), a' = (0.5, 0) (same direction), b = (0, 3).
  // Scores: a: (1 + 0) / 2, a': (1 + 0) / 2, b: 0. rho = 0.5: keep floor(1.5) = 1, the tie
  // between a and a' goes to the earlier frame: f = (1, 0).
  Samples<S> s = samples<S>(3, 1, 2);
  s.g = {S(2), S(0), S(0.5), S(0), S(0), S(3)};
  auto f = describe(s, 0.5);
  CHECK(f[0] == doctest::Approx(1.0));
  CHECK(f[1] == doctest::Approx(0.0));
  // rho = 1: the average of all unit samples, (2, 1) / sqrt(5).
  f = describe(s, 1.0);
  CHECK(f[0] == doctest::Approx(2.0 / std::sqrt(5.0)));
  CHECK(f[1] == doctest::Approx(1.0 / std::sqrt(5.0)));
  // All samples mutually orthogonal: all scores 0, keep 1: the earliest frame.
  s.T = 2;
  s.g = {S(0), S(4), S(5), S(0)};
  f = describe(s, 0.5);
  CHECK(f[0] == doctest::Approx(0.0));
  CHECK(f[1] == doctest::Approx(1.0));
  // A single visible sample: itself, normalised.
  s.T = 1;
  s.g = {S(3), S(-4)};
  f = describe(s, 0.5);
  CHECK(f[0] == doctest::Approx(0.6));
  CHECK(f[1] == doctest::Approx(-0.8));
}

TEST_CASE("descriptor: a few outlier samples do not move it") {
  SMG_TEST_RNG(rng, 31);
  const Index C = 16, T = 20;
  Eigen::VectorXd truth(C), wrong(C);
  for (Index c = 0; c < C; ++c) truth(c) = rng.normal();
  for (Index c = 0; c < C; ++c) wrong(c) = rng.normal();
  truth.normalize();
  wrong.normalize();
  Samples<double> s = samples<double>(T, 1, C);
  for (Index t = 0; t < T; ++t) {
    // 5 of 20 samples agree with each other on a wrong direction (e.g. an occluder), with
    // large norms; the others are noisy and rescaled copies of the truth.
    const bool outlier = t % 4 == 1;
    const double scale = outlier ? 10.0 : rng.uniform(0.5, 2.0);
    for (Index c = 0; c < C; ++c)
      s.at(t, 0)[c] = scale * ((outlier ? wrong(c) : truth(c)) + 0.05 * rng.normal());
  }
  const auto f = describe(s, 0.5);
  Eigen::Map<const Eigen::VectorXd> fv(f.data(), C);
  CHECK(fv.norm() == doctest::Approx(1.0));
  CHECK(fv.dot(truth) > 0.995);
  // The plain mean of the unit samples (rho = 1) is pulled away by the outliers.
  const auto mean = describe(s, 1.0);
  Eigen::Map<const Eigen::VectorXd> mv(mean.data(), C);
  CHECK(mv.dot(truth) < 0.97);
}

TEST_CASE("descriptor: equals the pairwise reference; invisible frames are ignored; scale-invariant") {
  SMG_TEST_RNG(rng, 32);
  for (int trial = 0; trial < 10; ++trial) {
    const Index T = rng.integer(1, 40), C = rng.integer(1, 9);
    Samples<double> s = samples<double>(T, 12, C);
    for (auto& x : s.g) x = rng.normal() + 0.7;  // a common bias: scores are not all ties
    s.v.resize(static_cast<std::size_t>(s.T * s.N));
    for (auto& b : s.v) b = rng.uniform(0, 1) < 0.6 ? 1 : 0;
    for (double rho : {0.25, 0.5, 1.0}) {
      const auto f = describe(s, rho);
      CAPTURE(trial);
      CAPTURE(rho);
      CAPTURE(s.C);
      CAPTURE(s.T);
      for (Index i = 0; i < s.N; ++i) {
        CAPTURE(i);
        const auto ref = reference_descriptor(s, i, rho);
        for (Index c = 0; c < s.C; ++c) CHECK(f[static_cast<std::size_t>(i * s.C + c)] == doctest::Approx(ref[static_cast<std::size_t>(c)]).epsilon(1e-12));
      }
      // Garbage in invisible frames and positive rescaling of samples change nothing.
      auto t = s;
      for (Index k = 0; k < t.T * t.N; ++k)
        for (Index c = 0; c < t.C; ++c) {
          auto& x = t.g[static_cast<std::size_t>(k * t.C + c)];
          x = t.v[static_cast<std::size_t>(k)] ? x * static_cast<double>(1 + k % 5) : 1e6 * rng.normal();
        }
      const auto g = describe(t, rho);
      for (std::size_t q = 0; q < f.size(); ++q) CHECK(g[q] == doctest::Approx(f[q]).epsilon(1e-12));
    }
  }
}

TEST_CASE("descriptor: zero samples, invisible nodes, and counts") {
  Samples<double> s = samples<double>(3, 3, 2);
  s.v = {1, 0, 1,   // t = 0
         1, 0, 0,   // t = 1
         0, 0, 0};  // t = 2
  // Node 0: samples (1, 0) and zero: zero stays zero (score 0); the nonzero sample has score
  // 0 too; keep 1 (earliest frame) -> (1, 0). Node 1: never visible. Node 2: only a zero sample.
  s.at(0, 0)[0] = 1.0;
  smg::DescriptorStats st;
  const auto f = describe(s, 0.5, &st);
  CHECK(f == std::vector<double>{1, 0, 0, 0, 0, 0});
  CHECK(st.nodes_without_visible_frame == 1);
  CHECK(st.zero_descriptors == 2);
  // Two opposite samples cancel: zero descriptor with rho = 1.
  Samples<double> o = samples<double>(2, 1, 2);
  o.g = {1, 1, -2, -2};
  CHECK(describe(o, 1.0, &st) == std::vector<double>{0, 0});
  CHECK(st.zero_descriptors == 1);
  CHECK(st.nodes_without_visible_frame == 0);
}

TEST_CASE("descriptor: float agrees with double; bit-identical for 1, 2 and 7 threads") {
  SMG_TEST_RNG(rng, 33);
  Samples<double> d = samples<double>(25, 700, 8);
  for (auto& x : d.g) x = static_cast<float>(rng.normal() + 0.5);
  Samples<float> f = samples<float>(d.T, d.N, d.C);
  f.g.assign(d.g.begin(), d.g.end());
  const auto fd = describe(d, 0.5, nullptr, 1);
  const auto ff = describe(f, 0.5, nullptr, 1);
  // Rankings may differ where scores are within float rounding, so compare by angle.
  double worst = 1;
  for (Index i = 0; i < d.N; ++i) {
    double dot = 0;
    for (Index c = 0; c < d.C; ++c) dot += fd[static_cast<std::size_t>(i * d.C + c)] * static_cast<double>(ff[static_cast<std::size_t>(i * d.C + c)]);
    worst = std::min(worst, dot);
  }
  CHECK(worst > 0.999);
  for (int threads : {2, 7}) {
    CHECK(describe(d, 0.5, nullptr, threads) == fd);
    CHECK(describe(f, 0.5, nullptr, threads) == ff);
  }
}

TEST_CASE("descriptor: validation") {
  Samples<double> s = samples<double>(2, 3, 4, 1.0);
  std::vector<double> out(12);
  smg::DescriptorOptions o;
  auto msg = [&](const Samples<double>& x, const smg::DescriptorOptions& opt, Index rows, Index cols) {
    return smg::validate_semantic_descriptors<double>(x.view(), x.vis(), opt, {out.data(), rows, cols}).message();
  };
  CHECK(msg(s, o, 3, 4).empty());
  auto bad = o;
  bad.rho = 0;
  CHECK(msg(s, bad, 3, 4) == "rho: must be in (0, 1], got 0");
  bad.rho = 1.5;
  CHECK(msg(s, bad, 3, 4) == "rho: must be in (0, 1], got 1.5");
  bad.rho = std::numeric_limits<double>::quiet_NaN();
  CHECK(msg(s, bad, 3, 4) == "rho: must be in (0, 1], got nan");
  CHECK(msg(s, o, 3, 3) == "descriptors: expected shape [N=3][C=4], got [3][3]");
  auto nan = s;
  nan.g[13] = std::numeric_limits<double>::infinity();
  CHECK(msg(nan, o, 3, 4) == "feature_samples: element [t=1][i=0] is Inf");
  const std::vector<std::uint8_t> v(4, 1);
  CHECK(smg::validate_semantic_descriptors<double>(s.view(), {v.data(), 2, 2}, o, {out.data(), 3, 4}).message() ==
        "visibility: expected shape [T=2][N=3], got [T=2][N=2]");
}
