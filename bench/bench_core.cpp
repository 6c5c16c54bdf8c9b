// Core rotation maths: Exp, Log and rotate, with and without Jacobians, float vs double.
//
// Each benchmark evaluates a batch of random inputs per iteration (--n, default 1024, so the
// compiler cannot hoist the work) and reports:
//   ns_per_call      wall time per call (plain number, nanoseconds)
//   err_vs_double    for float: max over the batch of the relative error of the float result
//                    against the double result on the same float-representable inputs (the
//                    inputs are rounded to float first; 0 for double itself); with Jacobians, the
//                    max of the value error and the Jacobian error.
// Parameters (bench/bench_common.hpp, --smg_help): --n --precision=float|double|both --reps=3.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "bench_common.hpp"
#include "smg/core/so3.hpp"
#include "support/finite_diff.hpp"

namespace {

int kBatch = 1024;  // --n

struct Inputs {
  std::vector<smg::Vector3<double>> phi, v;
  std::vector<smg::Quaternion<double>> q;
};
const Inputs& inputs() {
  static const Inputs in = [] {
    Inputs r;
    std::mt19937_64 g(7);
    std::normal_distribution<double> n(0, 1);
    std::uniform_real_distribution<double> angle(0, M_PI);
    for (int k = 0; k < kBatch; ++k) {
      smg::Vector3<double> axis(n(g), n(g), n(g));
      axis.normalize();
      // Float-representable inputs: float and double rows see identical values.
      r.phi.push_back((angle(g) * axis).cast<float>().cast<double>());
      r.q.push_back(smg::so3::exp(r.phi.back()).cast<float>().cast<double>());
      r.v.push_back(smg::Vector3<double>(n(g), n(g), n(g)).cast<float>().cast<double>());
    }
    return r;
  }();
  return in;
}

template <class S>
std::vector<smg::Vector3<S>> cast_all(const std::vector<smg::Vector3<double>>& a) {
  std::vector<smg::Vector3<S>> out;
  for (const auto& x : a) out.push_back(x.template cast<S>());
  return out;
}
template <class S>
std::vector<smg::Quaternion<S>> cast_all(const std::vector<smg::Quaternion<double>>& a) {
  std::vector<smg::Quaternion<S>> out;
  for (const auto& x : a) out.push_back(x.template cast<S>());
  return out;
}
// Relative error of a float result against the double one (no floor: the references are never 0).
template <class A, class B>
double rel(const A& a, const B& b) {
  return smg::test::relative_error(a, b, 1e-300);
}

void report(benchmark::State& state, const smg_bench::Stopwatch& clock, double err) {
  state.counters["ns_per_call"] = smg_bench::per(state, clock.seconds(), kBatch, 1e9);
  state.counters["err_vs_double"] = err;
}

// ---- Exp ----
template <class S, bool kJacobian>
void BM_exp(benchmark::State& state) {
  const auto phi = cast_all<S>(inputs().phi);
  double err = 0;
  for (int k = 0; k < kBatch; ++k) {
    smg::Matrix3<S> J;
    smg::Matrix3<double> Jd;
    const auto q = smg::so3::exp(phi[k], kJacobian ? &J : nullptr);
    const auto qd = smg::so3::exp(inputs().phi[k], kJacobian ? &Jd : nullptr);
    err = std::max(err, rel(q.coeffs(), qd.coeffs()));
    if (kJacobian) err = std::max(err, rel(J, Jd));
  }
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    for (int k = 0; k < kBatch; ++k) {
      smg::Matrix3<S> J;
      auto q = smg::so3::exp(phi[k], kJacobian ? &J : nullptr);
      benchmark::DoNotOptimize(q);
      if (kJacobian) benchmark::DoNotOptimize(J);
    }
  }
  report(state, clock, std::is_same_v<S, double> ? 0.0 : err);
}

// ---- Log ----
template <class S, bool kJacobian>
void BM_log(benchmark::State& state) {
  const auto q = cast_all<S>(inputs().q);
  double err = 0;
  for (int k = 0; k < kBatch; ++k) {
    smg::Matrix3<S> J;
    smg::Matrix3<double> Jd;
    const auto phi = smg::so3::log(q[k], kJacobian ? &J : nullptr);
    const auto phid = smg::so3::log(inputs().q[k], kJacobian ? &Jd : nullptr);
    err = std::max(err, rel(phi, phid));
    if (kJacobian) err = std::max(err, rel(J, Jd));
  }
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    for (int k = 0; k < kBatch; ++k) {
      smg::Matrix3<S> J;
      auto phi = smg::so3::log(q[k], kJacobian ? &J : nullptr);
      benchmark::DoNotOptimize(phi);
      if (kJacobian) benchmark::DoNotOptimize(J);
    }
  }
  report(state, clock, std::is_same_v<S, double> ? 0.0 : err);
}

// ---- rotate (R v) with Jacobians w.r.t. rotation (right tangent) and vector ----
template <class S, bool kJacobian>
void BM_rotate(benchmark::State& state) {
  const auto q = cast_all<S>(inputs().q);
  const auto v = cast_all<S>(inputs().v);
  double err = 0;
  for (int k = 0; k < kBatch; ++k) {
    smg::Matrix3<S> Jq, Jv;
    smg::Matrix3<double> Jqd, Jvd;
    const auto y = smg::so3::rotate(q[k], v[k], kJacobian ? &Jq : nullptr, kJacobian ? &Jv : nullptr);
    const auto yd = smg::so3::rotate(inputs().q[k], inputs().v[k], kJacobian ? &Jqd : nullptr,
                                     kJacobian ? &Jvd : nullptr);
    err = std::max(err, rel(y, yd));
    if (kJacobian) err = std::max({err, rel(Jq, Jqd), rel(Jv, Jvd)});
  }
  const smg_bench::Stopwatch clock;
  for (auto _ : state) {
    for (int k = 0; k < kBatch; ++k) {
      smg::Matrix3<S> Jq, Jv;
      auto y = smg::so3::rotate(q[k], v[k], kJacobian ? &Jq : nullptr, kJacobian ? &Jv : nullptr);
      benchmark::DoNotOptimize(y);
      if (kJacobian) {
        benchmark::DoNotOptimize(Jq);
        benchmark::DoNotOptimize(Jv);
      }
    }
  }
  report(state, clock, std::is_same_v<S, double> ? 0.0 : err);
}

}  // namespace

int main(int argc, char** argv) {
  smg_bench::Params p(argc, argv, "core");
  kBatch = static_cast<int>(p.integer("n", 1024, "random inputs per iteration (the batch)"));
  p.precision();
  const int reps = p.reps(3);
  p.finish();
  if (kBatch < 1) return 2;
  auto add = [&](const char* name, void (*f)(benchmark::State&), bool is_double) {
    if (is_double ? p.runs<double>() : p.runs<float>())
      smg_bench::protocol(benchmark::RegisterBenchmark(name, f), reps);
  };
  add("BM_exp<double, false>", BM_exp<double, false>, true);
  add("BM_exp<float, false>", BM_exp<float, false>, false);
  add("BM_exp<double, true>", BM_exp<double, true>, true);
  add("BM_exp<float, true>", BM_exp<float, true>, false);
  add("BM_log<double, false>", BM_log<double, false>, true);
  add("BM_log<float, false>", BM_log<float, false>, false);
  add("BM_log<double, true>", BM_log<double, true>, true);
  add("BM_log<float, true>", BM_log<float, true>, false);
  add("BM_rotate<double, false>", BM_rotate<double, false>, true);
  add("BM_rotate<float, false>", BM_rotate<float, false>, false);
  add("BM_rotate<double, true>", BM_rotate<double, true>, true);
  add("BM_rotate<float, true>", BM_rotate<float, true>, false);
  return smg_bench::run(argc, argv);
}
