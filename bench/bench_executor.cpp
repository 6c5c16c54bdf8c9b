// The caller's executor (smg/core/parallel.hpp): C-ARAP + LRM with gradients (float, N = 5000,
// T = 100, K = 16, gaps {1, 2, 4}, 2 threads) called right after an OpenMP parallel region, as
// in a PyTorch process whose intra-op OpenMP threads have just finished an operator. Rows:
//   std_pool      smg's own std::thread pool (the default)
//   openmp        smg::openmp_executor(): smg's chunks run on the same OpenMP threads
//   alone         no OpenMP region before the call (the reference)
// Run it with OMP_WAIT_POLICY=active to emulate OpenMP threads that spin between regions (what a
// PyTorch process at 2 threads shows); with the default policy they spin briefly, then sleep.
// Time column: wall time of the smg call only (manual time; the OpenMP region is not timed);
// `cpu` is the process CPU time of the whole iteration, OpenMP region included. Counter call_ms:
// the mean of the same wall time. Parameters (flags or SMG_BENCH_*, --smg_help): --n=5000
// --t=100 --k=16 --threads=2 --reps=1.
#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>
#include <vector>

#include "bench_common.hpp"
#include "energy/scene.hpp"
#include "smg/energy.hpp"

namespace {

using smg::Index;

Index g_n = 5000, g_t = 100, g_k = 16;
int g_threads = 2;

const smg::test::Scene<float>& scene() {
  static const smg::test::Scene<float> s = [] {
    smg::test::Rng rng(7);
    return smg::test::random_scene(g_t, g_n, g_k, rng, true).cast<float>();
  }();
  return s;
}

// A short OpenMP region on --threads threads (about a millisecond of arithmetic), like a small tensor op.
float openmp_region(std::vector<float>& buf) {
  float sum = 0;
#ifdef _OPENMP
#pragma omp parallel for num_threads(g_threads) reduction(+ : sum)
#endif
  for (Index k = 0; k < Index(buf.size()); ++k) {
    buf[k] = std::sqrt(buf[k] + 1.0f);
    sum += buf[k];
  }
  return sum;
}

void BM_after_openmp(benchmark::State& state) {
  const int mode = static_cast<int>(state.range(0));  // 0 std_pool, 1 openmp, 2 alone
  const auto& s = scene();
  const Index T = s.T, N = s.N;
  std::vector<float> gx(T * N * 3), gr(T * N * 3), buf(1 << 20, 1.0f);
  smg::EnergyWorkspace<float> ws;
  smg::ParallelOptions po;
  po.threads = g_threads;
#ifdef _OPENMP
  const smg::ScopedExecutor scoped(mode == 1 ? smg::openmp_executor() : smg::Executor{});
#else
  if (mode == 1) {
    state.SkipWithError("built without OpenMP");
    return;
  }
#endif
  double total_ms = 0;
  for (auto _ : state) {
    if (mode != 2) benchmark::DoNotOptimize(openmp_region(buf));
    const auto t0 = std::chrono::steady_clock::now();
    double e = smg::carap<float>(s.positions(), s.rotations(), s.confidence(), s.graph(),
                                 smg::CarapOptions{}, {gx.data(), T, N},
                                 smg::TangentsView<float>(gr.data(), T, N), &ws, po);
    e += smg::lrm<float>(s.positions(), s.confidence(), s.graph(), smg::LrmOptions{},
                         {gx.data(), T, N}, &ws, po);
    benchmark::DoNotOptimize(e);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    state.SetIterationTime(ms / 1e3);
    total_ms += ms;
  }
  state.counters["call_ms"] = total_ms / static_cast<double>(state.iterations());
  state.SetLabel(mode == 0 ? "std_pool" : mode == 1 ? "openmp" : "alone");
}
}  // namespace

int main(int argc, char** argv) {
  smg_bench::Params p(argc, argv, "executor");
  g_n = p.integer("n", 5000, "nodes N");
  g_t = p.integer("t", 100, "frames T");
  g_k = p.integer("k", 16, "neighbours K");
  g_threads = static_cast<int>(p.integer("threads", 2, "threads of smg and of the OpenMP region"));
  const int reps = p.reps(1);
  p.finish();
  auto* b = benchmark::RegisterBenchmark("BM_after_openmp", BM_after_openmp)->Arg(0)->Arg(1)->Arg(2);
  smg_bench::protocol(b, reps, /*manual_time=*/true)->Unit(benchmark::kMillisecond);
  return smg_bench::run(argc, argv);
}
