// The penalties of trajectory smoothness (E21)-(E22), AccelOptions::penalty: each against an
// independent reference written here in plain loops, for every form and penalty of the library's
// lists (kAccelForms, kPenalties), weighted or not, sum or mean; the cases where torch's
// gradient is exactly 0 (a still or constant-velocity window: a = 0); sqrt_weighted with w = 0;
// the options' validation. The generic properties (central differences, AutoDiffScalar, float
// against double, thread counts, hard cases) run for every penalty through the operator list
// (tests/support/operators.hpp's AccelWithPenalty, tests/energy/test_terms.cpp).
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "smg/energy.hpp"
#include "support/finite_diff.hpp"
#include "support/random.hpp"

namespace {

using smg::Index;

// (E21)-(E22) written out: energy and gradient [T][N][3] in double.
struct AccelRef {
  double energy = 0;
  std::vector<double> g;
};
AccelRef accel_penalty_reference(const std::vector<double>& x, const std::vector<double>& c, Index T, Index N,
                                 const smg::AccelOptions& o) {
  AccelRef r;
  r.g.assign(x.size(), 0.0);
  const bool acc = o.form == smg::AccelForm::acceleration;
  const Index span = acc ? 2 : 1, terms = std::max<Index>(0, T - span) * N;
  const double k = o.normalization == smg::Normalization::mean && terms > 0 ? o.weight / double(terms) : o.weight;
  const double m2[3] = {1, -2, 1}, m1[2] = {-1, 1};
  for (Index t = 0; t + span < T; ++t)
    for (Index i = 0; i < N; ++i) {
      double a[3];
      for (int d = 0; d < 3; ++d) {
        a[d] = 0;
        for (Index p = 0; p <= span; ++p) a[d] += (acc ? m2[p] : m1[p]) * x[((t + p) * N + i) * 3 + d];
      }
      const double w = o.confidence_weighted ? c[t * N + i] : 1.0;
      const double aa = a[0] * a[0] + a[1] * a[1] + a[2] * a[2], n = std::sqrt(aa);
      double e = 0, h = 0;  // P(a) and ∂P/∂a = h a
      switch (o.penalty) {
        case smg::Penalty::squared: e = k * w * aa; h = 2 * k * w; break;
        case smg::Penalty::norm: e = k * w * n; h = n > 0 ? k * w / n : 0.0; break;
        case smg::Penalty::sqrt_weighted:
          e = k * std::sqrt(w * aa + o.penalty_eps);
          h = k * w / std::sqrt(w * aa + o.penalty_eps);
          break;
      }
      r.energy += e;
      for (Index p = 0; p <= span; ++p)
        for (int d = 0; d < 3; ++d) r.g[((t + p) * N + i) * 3 + d] += (acc ? m2[p] : m1[p]) * h * a[d];
    }
  return r;
}

template <class S>
struct AccelOut {
  double energy = 0;
  std::vector<S> g;
};
template <class S>
AccelOut<S> run_accel(const std::vector<S>& x, const std::vector<S>& c, Index T, Index N, const smg::AccelOptions& o,
                      int threads = 2) {
  AccelOut<S> r;
  r.g.assign(x.size(), S(0));
  smg::ParallelOptions par;
  par.threads = threads;
  REQUIRE(smg::validate_accel<S>({x.data(), T, N}, {c.data(), T, N}, o, {r.g.data(), T, N}));
  r.energy = double(smg::accel<S>({x.data(), T, N}, {c.data(), T, N}, o, {r.g.data(), T, N}, nullptr, par));
  return r;
}

std::vector<double> random_values(std::size_t n, double lo, double hi, unsigned seed) {
  smg::test::Rng rng(seed);
  std::vector<double> v(n);
  for (double& e : v) e = rng.uniform(lo, hi);
  return v;
}

}  // namespace

TEST_CASE("accel penalties: the default is squared") {
  CHECK(smg::AccelOptions{}.penalty == smg::Penalty::squared);
  CHECK(smg::AccelOptions{}.penalty_eps == 1e-20);
  CHECK(std::string(smg::to_string(smg::kPenalties[0])) == "squared");
}

TEST_CASE("accel penalties: energy and gradient equal the written-out (E22) for every form and penalty") {
  const Index T = 11, N = 23;
  const std::vector<double> x = random_values(static_cast<std::size_t>(3 * T * N), -1, 1, 4101);
  const std::vector<double> c = random_values(static_cast<std::size_t>(T * N), 0, 1, 4102);
  for (const smg::AccelForm form : smg::kAccelForms)
    for (const smg::Penalty penalty : smg::kPenalties)
      for (const bool weighted : {false, true})
        for (const smg::Normalization nm : {smg::Normalization::sum, smg::Normalization::mean}) {
          CAPTURE(smg::to_string(form));
          CAPTURE(smg::to_string(penalty));
          CAPTURE(weighted);
          CAPTURE(nm == smg::Normalization::mean);
          smg::AccelOptions o;
          o.form = form;
          o.penalty = penalty;
          o.confidence_weighted = weighted;
          o.normalization = nm;
          o.weight = 0.7;
          o.penalty_eps = 1e-3;  // large enough to matter in the value
          const AccelRef ref = accel_penalty_reference(x, c, T, N, o);
          const AccelOut<double> d = run_accel(x, c, T, N, o);
          CHECK(ref.energy > 0);
          CHECK(std::abs(d.energy - ref.energy) <= 1e-12 * ref.energy);
          CHECK(smg::test::relative_error(d.g, ref.g) < 1e-12);
          // float: same equation, float rounding.
          const std::vector<float> xf(x.begin(), x.end()), cf(c.begin(), c.end());
          const AccelOut<float> f = run_accel(xf, cf, T, N, o);
          CHECK(std::abs(f.energy - ref.energy) <= 1e-5 * ref.energy);
          CHECK(smg::test::relative_error(f.g, ref.g) < 1e-5);
        }
}

TEST_CASE("accel penalties: a still or constant-velocity window has exactly zero gradient") {
  // Dyadic coordinates and velocities: x^{t+2} − 2x^{t+1} + x^t is exactly 0 in float and double,
  // as in torch, whose norm backward then gives exactly 0. Node 3 moves with an acceleration,
  // so the energy is not 0; the others' gradients must be.
  const Index T = 6, N = 5;
  std::vector<double> x(static_cast<std::size_t>(3 * T * N));
  for (Index t = 0; t < T; ++t)
    for (Index i = 0; i < N; ++i)
      for (int d = 0; d < 3; ++d)
        x[static_cast<std::size_t>((t * N + i) * 3 + d)] =
            0.125 * double(i + d) + double(t) * 0.0625 * double(i * (d + 1)) + (i == 3 ? 0.03 * double(t * t) : 0.0);
  const std::vector<double> c(static_cast<std::size_t>(T * N), 0.5);
  for (const smg::Penalty penalty : smg::kPenalties)
    for (const bool weighted : {false, true}) {
      CAPTURE(smg::to_string(penalty));
      CAPTURE(weighted);
      smg::AccelOptions o;
      o.penalty = penalty;
      o.confidence_weighted = weighted;
      o.normalization = smg::Normalization::mean;
      const AccelOut<double> d = run_accel(x, c, T, N, o);
      const std::vector<float> xf(x.begin(), x.end()), cf(c.begin(), c.end());
      const AccelOut<float> f = run_accel(xf, cf, T, N, o);
      const AccelRef ref = accel_penalty_reference(x, c, T, N, o);
      CHECK(ref.energy > 0);
      CHECK(std::abs(d.energy - ref.energy) <= 1e-12 * ref.energy);
      for (Index t = 0; t < T; ++t)
        for (Index i = 0; i < N; ++i)
          for (int k = 0; k < 3; ++k) {
            const std::size_t at = static_cast<std::size_t>((t * N + i) * 3 + k);
            if (i != 3) {
              CHECK(d.g[at] == 0.0);
              CHECK(f.g[at] == 0.0f);
            }
          }
      // Every node still: norm and squared give exactly 0, sqrt_weighted k sqrt(ε) per term.
      std::vector<double> still = x;
      for (Index t = 0; t < T; ++t)
        for (int k = 0; k < 3; ++k)
          still[static_cast<std::size_t>((t * N + 3) * 3 + k)] = 0.125 * double(3 + k) + double(t) * 0.25;
      const AccelOut<double> s = run_accel(still, c, T, N, o);
      for (const double g : s.g) CHECK(g == 0.0);
      if (penalty == smg::Penalty::sqrt_weighted)
        CHECK(std::abs(s.energy - std::sqrt(o.penalty_eps)) <= 1e-12 * std::sqrt(o.penalty_eps));  // mean of sqrt(ε)
      else
        CHECK(s.energy == 0.0);
    }
}

TEST_CASE("accel penalties: sqrt_weighted with zero confidences is finite, k sqrt(eps) per term, no gradient") {
  const Index T = 7, N = 9;
  const std::vector<double> x = random_values(static_cast<std::size_t>(3 * T * N), -2, 2, 4103);
  std::vector<double> c = random_values(static_cast<std::size_t>(T * N), 0, 1, 4104);
  for (Index i = 0; i < N; ++i) c[static_cast<std::size_t>(2 * N + i)] = 0.0;  // frame 2: w = 0
  smg::AccelOptions o;
  o.penalty = smg::Penalty::sqrt_weighted;
  o.confidence_weighted = true;
  const AccelRef ref = accel_penalty_reference(x, c, T, N, o);
  const AccelOut<double> d = run_accel(x, c, T, N, o);
  CHECK(std::abs(d.energy - ref.energy) <= 1e-12 * ref.energy);
  CHECK(smg::test::relative_error(d.g, ref.g) < 1e-12);
  // Every confidence 0: the energy is the count times sqrt(1e-20), the gradient exactly 0.
  const std::vector<double> zero(c.size(), 0.0);
  for (const bool use_float : {false, true}) {
    CAPTURE(use_float);
    double e = 0;
    bool all_zero = true;
    if (use_float) {
      const std::vector<float> xf(x.begin(), x.end()), zf(zero.begin(), zero.end());
      const AccelOut<float> f = run_accel(xf, zf, T, N, o);
      e = f.energy;
      for (const float g : f.g) all_zero = all_zero && g == 0.0f;
    } else {
      const AccelOut<double> z = run_accel(x, zero, T, N, o);
      e = z.energy;
      for (const double g : z.g) all_zero = all_zero && g == 0.0;
    }
    CHECK(std::isfinite(e));
    const double expected = double((T - 2) * N) * 1e-10;  // k = 1, sqrt(1e-20) per term
    CHECK(std::abs(e - expected) <= 1e-6 * expected);
    CHECK(all_zero);
  }
}

TEST_CASE("accel penalties: the options are validated, naming the option") {
  auto message = [](const smg::AccelOptions& o) {
    const smg::Status s = smg::validate_options(o);
    return s ? std::string() : std::string(s.message());
  };
  smg::AccelOptions o;
  CHECK(message(o).empty());
  for (const double bad : {0.0, -1e-20, std::numeric_limits<double>::infinity(), std::nan("")}) {
    o.penalty_eps = bad;
    CAPTURE(bad);
    CHECK(message(o).rfind("AccelOptions.penalty_eps must be finite and > 0, got ", 0) == 0);
  }
  o = {};
  o.penalty = static_cast<smg::Penalty>(7);
  CHECK(message(o) == "AccelOptions.penalty must be squared, norm or sqrt_weighted, got 7");
  o = {};
  o.form = static_cast<smg::AccelForm>(5);
  CHECK(message(o) == "AccelOptions.form must be acceleration or velocity, got 5");
  // The fused step's validation names the option too.
  smg::RegularizerOptions r;
  r.terms.accel = true;
  r.accel.penalty_eps = -1;
  CHECK(std::string(smg::validate_options(r).message()).rfind("AccelOptions.penalty_eps", 0) == 0);
  // The operator's validator refuses it before reading anything.
  const std::vector<double> x(3 * 4 * 2, 0.0);
  CHECK(!smg::validate_accel<double>({x.data(), 4, 2}, {}, r.accel));
}
