// bench/bench_floor.cpp — the machine's peak behind every floor (bench/floor.hpp; issue 59).
//
//   bench_floor [--probe_threads=N] [Google Benchmark flags]
//       one row per figure (scripts/bench.sh runs it as the module "floor"): BM_fma<float|double>/
//       base|avx2 (counter gflops: multiply-add throughput on `probe_threads` threads, default all
//       hardware threads; the base ISA is the one this binary was compiled for, SSE2 on x86-64
//       without -march; avx2 is bench/floor_avx2.cpp, 0 without AVX2+FMA) and BM_triad (gb_per_s).
//   bench_floor --json=FILE [--probe_threads=N] [--runs=R --pause=S]
//       the probe alone, printed and written to FILE, the JSON that bench_energy --floor=FILE and
//       bench/torch/floor.py --floor-json read. --runs=R repeats the whole probe R times, S seconds
//       apart (default 15), and keeps each figure's best: on a shared machine a probe while another
//       process holds a core measures about half the all-core peak, and the peak is what the
//       machine can do.
//   bench_floor --counts
//       the count functions at fixed shapes, one JSON object per line (bench/torch/floor.py --check).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>

#include "bench_common.hpp"
#include "floor.hpp"

namespace {

namespace rl = smg_bench::roofline;

// The shapes bench/torch/floor.py's --check evaluates too: the regulariser problem at 5k × 100,
// K = 16, gaps 1, 2, 4 (smg_torch's int64 indices, quaternion gradients) and the compat cases.
void print_counts() {
  rl::Shape s;
  s.T = 100;
  s.N = 5000;
  s.E = 80000;
  s.pair_frames = 3 * s.T - 7;
  s.scalar = 4;
  s.index = 8;
  s.vis = 1;
  s.rot_grad = 4;
  auto line = [](const char* name, rl::Work w) {
    std::printf("{\"case\": \"%s\", \"flops\": %.17g, \"bytes\": %.17g}\n", name, w.flops, w.bytes);
  };
  line("confidences", rl::confidences(s));
  line("carap", rl::rigidity(s, true, false));
  line("carap_grad", rl::rigidity(s, true, true));
  line("arap", rl::rigidity(s, false, false));
  line("arap_grad", rl::rigidity(s, false, true));
  line("lrm", rl::lrm(s, 0));
  line("lrm_grad", rl::lrm(s, 1));
  line("lrm_detached_grad", rl::lrm(s, 2));
  line("step", rl::step(s, false));
  line("step_grad", rl::step(s, true));
  line("carap_plus_lrm", rl::carap_plus_lrm(s));
  line("accel", rl::accel(s));
  line("som_accel", rl::som_accel(40000.0 * 8, 40000.0 * 3 * 8 * 3, false));
  line("som_accel_shared", rl::som_accel(40000.0 * 28, 40000.0 * 30 * 3, true));
  line("mosca_arap", rl::mosca_arap(25, 10000, 150000, 25 * 3 - 10, 10000.0 * 16 * 9));
  line("mosca_vel_acc", rl::mosca_vel_acc(25, 10000));
  line("d3dgs", rl::d3dgs(100000, 20));
}
// The probe alone (--json): `runs` probes `pause` seconds apart, each figure's best.
int probe(int threads, const std::string& json, int runs, int pause) {
  rl::Machine m = rl::measure_machine(threads);
  for (int r = 1; r < runs; ++r) {
    std::this_thread::sleep_for(std::chrono::seconds(pause));
    const rl::Machine n = rl::measure_machine(threads);
    std::printf("run %d: FP32 %.1f GFLOP/s, %.1f GB/s (load %s)\n", r + 1, n.fp32_gflops, n.bandwidth_gbs,
                n.loadavg.c_str());
    m.fp32_base = std::max(m.fp32_base, n.fp32_base);
    m.fp64_base = std::max(m.fp64_base, n.fp64_base);
    m.fp32_avx2 = std::max(m.fp32_avx2, n.fp32_avx2);
    m.fp64_avx2 = std::max(m.fp64_avx2, n.fp64_avx2);
    m.fp32_gflops = std::max(m.fp32_gflops, n.fp32_gflops);
    m.fp64_gflops = std::max(m.fp64_gflops, n.fp64_gflops);
    m.bandwidth_gbs = std::max(m.bandwidth_gbs, n.bandwidth_gbs);
  }
  if (runs > 1) m.loadavg += " (first run; best of " + std::to_string(runs) + " runs)";
  std::printf("threads %d, load average before %s\n", m.threads, m.loadavg.c_str());
  std::printf("FP32 multiply-add peak: %.1f GFLOP/s with %s; %.1f GFLOP/s with AVX2+FMA%s\n", m.fp32_base,
              m.base_isa.c_str(), m.fp32_avx2, m.fp32_avx2 > 0 ? "" : " (not available)");
  std::printf("FP64 multiply-add peak: %.1f GFLOP/s with %s; %.1f GFLOP/s with AVX2+FMA\n", m.fp64_base,
              m.base_isa.c_str(), m.fp64_avx2);
  std::printf("memory bandwidth (triad, 3 x 128 MB): %.1f GB/s\n", m.bandwidth_gbs);
  std::printf("the floor uses FP32 %.1f GFLOP/s (%s), FP64 %.1f GFLOP/s, %.1f GB/s\n", m.fp32_gflops,
              m.best_isa.c_str(), m.fp64_gflops, m.bandwidth_gbs);
  rl::Shape s;
  s.T = 100;
  s.N = 5000;
  s.E = 80000;
  s.pair_frames = 3 * s.T - 7;
  const rl::Work w = rl::step(s, true);
  std::printf("fused step with gradients at N 5000, T 100, K 16, gaps 1,2,4, float: %.2f GFLOP, %.1f MB, "
              "floor %.2f ms\n", w.flops / 1e9, w.bytes / 1e6, m.floor_seconds(w) * 1e3);
  FILE* f = std::fopen(json.c_str(), "w");
  if (!f) {
    std::perror(json.c_str());
    return 1;
  }
  std::fprintf(f, "%s\n", m.json().c_str());
  std::fclose(f);
  return 0;
}

int threads_of(const benchmark::State& state) {
  return state.range(0) > 0 ? static_cast<int>(state.range(0))
                            : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}
// BM_fma<S>/<isa>: kAvx2 false = this binary's ISA, true = bench/floor_avx2.cpp's.
template <class S, bool kAvx2>
void BM_fma(benchmark::State& state) {
  double best = 0;
  for (auto _ : state) {
    best = std::max(best, rl::detail::all_threads(threads_of(state), 50, [] {
      return kAvx2 ? rl::avx2_fma_chains(sizeof(S) == 8, 4000000) : rl::detail::base_chains<S>(4000000);
    }));
  }
  state.counters["gflops"] = best / 1e9;
  state.SetLabel(kAvx2 ? "AVX2+FMA" : rl::detail::base_isa_name());
}
void BM_triad(benchmark::State& state) {
  double best = 0;
  for (auto _ : state) best = std::max(best, rl::detail::triad_gbs(threads_of(state), std::size_t(16) << 20, 5));
  state.counters["gb_per_s"] = best;
}

}  // namespace

int main(int argc, char** argv) {
  for (int a = 1; a < argc; ++a)
    if (std::strcmp(argv[a], "--counts") == 0) {
      print_counts();
      return 0;
    }
  smg_bench::Params p(argc, argv, "floor");
  const int threads = static_cast<int>(p.integer("probe_threads", 0, "threads of the probe (0: all hardware threads)"));
  const std::string json = p.text("json", "", "FILE: run the probe alone and write its JSON (bench_energy --floor=FILE)");
  const int runs = static_cast<int>(p.integer("runs", 1, "--json: probes, each figure's best"));
  const int pause = static_cast<int>(p.integer("pause", 15, "--json: seconds between probes"));
  p.finish();
  if (!json.empty()) return probe(threads, json, std::max(1, runs), std::max(0, pause));
  auto add = [&](const char* name, void (*f)(benchmark::State&)) {
    benchmark::RegisterBenchmark(name, f)->Arg(threads)->ArgName("threads")->Iterations(1)->UseRealTime()->Unit(
        benchmark::kMillisecond);
  };
  add("BM_fma<float>/base", BM_fma<float, false>);
  add("BM_fma<float>/avx2", BM_fma<float, true>);
  add("BM_fma<double>/base", BM_fma<double, false>);
  add("BM_fma<double>/avx2", BM_fma<double, true>);
  add("BM_triad", BM_triad);
  return smg_bench::run(argc, argv);
}
