// bench/floor.hpp — the floor beside every figure (issue 59): the time a case cannot beat on
// this machine, max(flops / peak, bytes / bandwidth), from
//
//  * the machine's peak, measured, not assumed (measure_machine()): FP32 and FP64 multiply-add
//    throughput on all cores, best of 50 short passes (independent chains in registers,
//    vectorised; the ISA this binary was compiled for, plus AVX2+FMA from bench/floor_avx2.cpp
//    when the CPU has it; the floor uses the best) and the memory bandwidth on all cores (a
//    STREAM triad a = b + s·c over three arrays of 128 MB each, far larger than any L3; read +
//    write bytes, as STREAM counts them);
//  * the flop and byte counts of every benchmarked case family (the functions below), derived
//    in bench/notes/roofline.md: bytes = each input read once + each output written once; flops
//    = the arithmetic of the element functions (+, −, * one flop, an FMA two; sqrt, division,
//    exp one each; comparisons, abs, selects and index arithmetic none).
//
// The per-unit constants are the one copy of the counts: bench/torch/floor.py reads them from
// this file (its regex wants `constexpr double kName = number;`), mirrors the few formulas, and
// `python3 bench/torch/floor.py --check build/release/bench/bench_floor` compares its results with
// `bench_floor --counts` (both sides' totals at fixed shapes).
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace smg_bench::roofline {

// ---- per-unit counts (bench/notes/roofline.md) ------------------------------------------------
// Regulariser terms, per (edge, frame) "EF", per (edge, frame, gap) "EFG", per (node, frame) "NF".
// Node confidences: confidence_edge_change 36 + confidence_node's edge loops 24; node part ≈ 30.
constexpr double kConfEF = 60;
constexpr double kConfNF = 30;
// C-ARAP with gradients: edge part 28 (e, d = Rᵀe, ‖e‖, 1/‖e‖, confidence weight 3) + backprop
// 40; per gap: Δd, Δℓ 4 + carap_term 18 + P, Q into G, H at both frames 8 (of the fused step's 12,
// whose C-ARAP and ARAP sums are shared); per (node, frame) R from q 30 + tangent back 30.
// Energy only: edge part 28, per gap Δd, Δℓ 4 + k and carap_term_energy and the sum 12, R from q.
constexpr double kCarapGradEF = 68;
constexpr double kCarapGradEFG = 30;
constexpr double kCarapGradNF = 60;
constexpr double kCarapEF = 28;
constexpr double kCarapEFG = 16;
constexpr double kCarapNF = 30;
// Plain ARAP: the same without the confidence weight (3 per (edge, frame)).
constexpr double kArapGradEF = 65;
constexpr double kArapGradEFG = 30;
constexpr double kArapGradNF = 60;
constexpr double kArapEF = 25;
constexpr double kArapEFG = 16;
constexpr double kArapNF = 30;
// LRM, per (edge, frame) neighbour entry: ŵ 2, centring 18, normal equations 27, residual and
// Huber 24, weight 3 (= 74, the energy); the exact gradient adds q, Q, z 19, ∂/∂x, ∂/∂u 63 and
// the scatter 9 (= 165); with ω held constant the ω chain (q, Q, z: 19) is not needed (= 146).
// Node part: Σa, two Ldlt3 solves, κ, m ≈ 80.
constexpr double kLrmEF = 74;
constexpr double kLrmGradEF = 165;
constexpr double kLrmDetachedGradEF = 146;
constexpr double kLrmNF = 80;
// The fused step (confidences + C-ARAP + ARAP + LRM): d, ‖e‖ and the backprop shared between
// C-ARAP and ARAP: per (edge, frame) 60 + 68 + 165 = 293, per gap 52, per (node, frame)
// 30 + 60 + 80 = 170. Energy only: 60 + 28 + 74 = 162, per gap 4 + 12 + 12 = 28, 30 + 30 + 80.
constexpr double kStepGradEF = 293;
constexpr double kStepGradEFG = 52;
constexpr double kStepGradNF = 170;
constexpr double kStepEF = 162;
constexpr double kStepEFG = 28;
constexpr double kStepNF = 140;
// Acceleration smoothness (accel), per second difference ((T − 2)·N): a = x⁺ − 2x + x⁻ 9,
// ‖a‖² and the sum 6, 2a 3, scatter into three frames 3 + 9 = 30.
constexpr double kAccelTerm = 30;
// Shape of Motion's compute_accel_loss / track smoothness, per second difference: a 9, ‖a‖ 5 +
// sqrt, the mean 1, backward a/‖a‖ scaled (1 division + 3) and the three gradient points
// (2g 3) = 23; + 6 where the points are shared between terms (accumulated, [G, T, 3]).
constexpr double kSomTerm = 23;
constexpr double kSomShared = 6;
// MoSca compute_arap_loss, per (edge, frame): local coordinate Rᵀ(x_s − x_n) 18, its length 5 +
// sqrt; backprop to x and R (as carap_edge_backprop) 40 = 64; per (edge, frame, shift): Δ coord 3,
// its norm 5 + sqrt, Δ length 1, weights and sums 4, backward into both frames 17 = 31; per
// (node, frame): R from the normalised quaternion and back 60.
constexpr double kMoscaArapEF = 64;
constexpr double kMoscaArapEFS = 31;
constexpr double kMoscaArapNF = 60;
// MoSca compute_vel_acc_loss: per (node, frame) the quaternion's normalisation and its backward
// 30; per consecutive pair: position velocity (3 + 5 + sqrt + 1, backward 10) 20 and rotation
// velocity (relative quaternion 28, angle 8, backward 72) 108 = 128; per triple: position
// acceleration 29 and the rotation velocity's change (abs, mean, backward) 4 = 33.
constexpr double kMoscaVelNF = 30;
constexpr double kMoscaVelPair = 128;
constexpr double kMoscaVelTriple = 33;
// Dynamic 3D Gaussians' rigid + rot + iso, per edge: offsets 6, Rᵀ·offset 15, rigid 11, rot 14,
// iso 12 forward (58); backward 63 = 121; per node: relative quaternion 28, R from it 30, and
// their backward 58 = 116.
constexpr double kD3dgsEdge = 121;
constexpr double kD3dgsNode = 116;

// ---- the work of one call ---------------------------------------------------------------------
struct Work {
  double flops = 0, bytes = 0;
};
inline Work operator+(Work a, Work b) { return {a.flops + b.flops, a.bytes + b.bytes}; }

// A regulariser problem's shape: T frames, N nodes, E valid edges, pair_frames = Σ_gaps (T − δ)
// (the (edge, frame, gap) terms are E·pair_frames), scalar = sizeof(S), index = the graph's index
// bytes (smg's C++ int32 4, smg_torch's int64 8), vis = visibility bytes per (node, frame) (0 when
// absent), rot_grad = the rotation gradient's width (C++ tangents 3, smg_torch quaternions 4).
struct Shape {
  double T = 0, N = 0, E = 0, pair_frames = 0, scalar = 4, index = 4, vis = 0, rot_grad = 3;
  double ef() const { return E * T; }
  double efg() const { return E * pair_frames; }
  double nf() const { return N * T; }
  double frame_array(double width) const { return T * N * width * scalar; }  // [T][N][width]
  double graph() const { return E * (index + scalar); }                        // indices + weights
};

// Node confidences: x, visibility and the graph read, the confidences written.
inline Work confidences(const Shape& s) {
  return {kConfEF * s.ef() + kConfNF * s.nf(),
          s.frame_array(3) + s.T * s.N * s.vis + s.graph() + s.frame_array(1)};
}
// C-ARAP (with_conf) or plain ARAP: x, q (and the confidences) and the graph read; with the
// gradient, ∂x and the rotation gradient written.
inline Work rigidity(const Shape& s, bool with_conf, bool grad) {
  const double ef = with_conf ? (grad ? kCarapGradEF : kCarapEF) : (grad ? kArapGradEF : kArapEF);
  const double efg = with_conf ? (grad ? kCarapGradEFG : kCarapEFG) : (grad ? kArapGradEFG : kArapEFG);
  const double nf = with_conf ? (grad ? kCarapGradNF : kCarapNF) : (grad ? kArapGradNF : kArapNF);
  return {ef * s.ef() + efg * s.efg() + nf * s.nf(),
          s.frame_array(3) + s.frame_array(4) + (with_conf ? s.frame_array(1) : 0) + s.graph() +
              (grad ? s.frame_array(3) + s.frame_array(s.rot_grad) : 0)};
}
// LRM; mode 0 energy only, 1 exact gradient, 2 gradient with ω held constant: x, the confidences
// and the graph read (the velocities are differences of x), ∂x written.
inline Work lrm(const Shape& s, int mode) {
  const double ef = mode == 0 ? kLrmEF : (mode == 1 ? kLrmGradEF : kLrmDetachedGradEF);
  return {ef * s.ef() + kLrmNF * s.nf(),
          s.frame_array(3) + s.frame_array(1) + s.graph() + (mode > 0 ? s.frame_array(3) : 0)};
}
// The fused step: x, q, visibility and the graph read; the confidences (and the gradients) written.
inline Work step(const Shape& s, bool grad) {
  return {(grad ? kStepGradEF : kStepEF) * s.ef() + (grad ? kStepGradEFG : kStepEFG) * s.efg() +
              (grad ? kStepGradNF : kStepNF) * s.nf(),
          s.frame_array(3) + s.frame_array(4) + s.T * s.N * s.vis + s.graph() + s.frame_array(1) +
              (grad ? s.frame_array(3) + s.frame_array(s.rot_grad) : 0)};
}
// C-ARAP + LRM with exact gradients into one ∂x: x, q, confidences and the graph read once; ∂x,
// the rotation gradient written once.
inline Work carap_plus_lrm(const Shape& s) {
  const Work c = rigidity(s, true, true), l = lrm(s, 1);
  return {c.flops + l.flops, c.bytes};
}
// Acceleration smoothness with its gradient: x read, ∂x written.
inline Work accel(const Shape& s) {
  return {kAccelTerm * std::max(0.0, s.T - 2) * s.N, 2 * s.frame_array(3)};
}

// ---- smg_torch.compat's cases (bench/torch/bench_compat.py), float32 -------------------------
// Shape of Motion: `terms` second differences over `elements` input scalars (read once, the
// gradient written once); shared: the points are shared between terms ([G, T, 3]).
inline Work som_accel(double terms, double elements, bool shared, double scalar = 4) {
  return {(kSomTerm + (shared ? kSomShared : 0)) * terms, 2 * elements * scalar};
}
// MoSca ARAP: T frames, M nodes, E edges with a non-zero weight over all levels, pair_frames =
// Σ_shifts (T − s); x [T, M, 3] and q [T, M, 4] read, their gradients written, the graph read
// (graph_bytes: indices, masks and weights as the call takes them).
inline Work mosca_arap(double T, double M, double E, double pair_frames, double graph_bytes,
                       double scalar = 4) {
  return {kMoscaArapEF * E * T + kMoscaArapEFS * E * pair_frames + kMoscaArapNF * M * T,
          2 * T * M * 7 * scalar + graph_bytes};
}
// MoSca vel/acc: x [T, M, 3] and q [T, M, 4] read, their gradients written.
inline Work mosca_vel_acc(double T, double M, double scalar = 4) {
  return {kMoscaVelNF * T * M + kMoscaVelPair * std::max(0.0, T - 1) * M +
              kMoscaVelTriple * std::max(0.0, T - 2) * M,
          2 * T * M * 7 * scalar};
}
// Dynamic 3D Gaussians: N Gaussians, K neighbours; fg_pts, fg_rot, prev_pts, prev_rot read, the
// graph (int64 indices, weights, initial distances) read, ∂fg_pts and ∂fg_rot written.
inline Work d3dgs(double N, double K, double scalar = 4) {
  return {kD3dgsEdge * N * K + kD3dgsNode * N, 3 * N * 7 * scalar + N * K * (8 + 2 * scalar)};
}

// ---- the machine ------------------------------------------------------------------------------
struct Machine {
  double fp32_gflops = 0, fp64_gflops = 0;    // the best ISA's
  double fp32_base = 0, fp64_base = 0;        // this binary's own ISA (its compile flags)
  double fp32_avx2 = 0, fp64_avx2 = 0;        // AVX2 + FMA (0: not available or not x86)
  double bandwidth_gbs = 0;                   // triad, read + write bytes
  int threads = 0;
  std::string base_isa, best_isa;
  std::string loadavg;  // /proc/loadavg before the probe (others' load lowers the all-core figures)
  // max(flops / peak, bytes / bandwidth) in seconds; peak by the scalar size (4: FP32, 8: FP64).
  double floor_seconds(const Work& w, double scalar = 4) const {
    const double peak = (scalar == 8 ? fp64_gflops : fp32_gflops) * 1e9;
    return std::max(peak > 0 ? w.flops / peak : 0.0, bandwidth_gbs > 0 ? w.bytes / (bandwidth_gbs * 1e9) : 0.0);
  }
  std::string json() const {
    char b[1024];
    std::snprintf(b, sizeof b,
                  "{\"fp32_gflops\": %.2f, \"fp64_gflops\": %.2f, \"fp32_base_gflops\": %.2f, "
                  "\"fp64_base_gflops\": %.2f, \"fp32_avx2_gflops\": %.2f, \"fp64_avx2_gflops\": %.2f, "
                  "\"bandwidth_gbs\": %.2f, \"threads\": %d, \"base_isa\": \"%s\", \"best_isa\": \"%s\", "
                  "\"loadavg\": \"%s\", "
                  "\"method\": \"bench/floor.hpp: multiply-add chains in registers on all threads, best of 50 passes of 4 M steps; "
                  "triad over 3 x 128 MB arrays, best of 5\"}",
                  fp32_gflops, fp64_gflops, fp32_base, fp64_base, fp32_avx2, fp64_avx2, bandwidth_gbs, threads,
                  base_isa.c_str(), best_isa.c_str(), loadavg.c_str());
    return b;
  }
};

// bench/floor_avx2.cpp (compiled with -mavx2 -mfma): runs one thread's chains of `iters` FMA
// steps and returns the flops done, or 0 when the CPU lacks AVX2 or FMA (or the target is not x86).
double avx2_fma_chains(bool fp64, long iters);

namespace detail {

// The baseline ISA's chains: GCC/Clang vector extensions, 16-byte vectors (SSE2 on x86-64
// without -march; NEON on AArch64), 12 independent accumulators, acc = acc·m + a: a multiply and
// an add (an FMA where the flags allow contraction), 2 flops per lane either way. Returns the
// flops done.
template <class T>
double base_chains(long iters) {
  typedef T V __attribute__((vector_size(16)));
  constexpr int kLanes = 16 / sizeof(T), kChains = 12;
  volatile T seed_m = T(0.999999), seed_a = T(1e-6);
  V m, a, acc[kChains];
  for (int l = 0; l < kLanes; ++l) {
    m[l] = seed_m;
    a[l] = seed_a;
  }
  for (int c = 0; c < kChains; ++c)
    for (int l = 0; l < kLanes; ++l) acc[c][l] = T(c + l);
  for (long i = 0; i < iters; ++i)
    for (int c = 0; c < kChains; ++c) acc[c] = acc[c] * m + a;
  T sum = 0;
  for (int c = 0; c < kChains; ++c)
    for (int l = 0; l < kLanes; ++l) sum += acc[c][l];
  volatile T sink = sum;
  (void)sink;
  return 2.0 * kLanes * kChains * static_cast<double>(iters);
}

// Flops per second of `threads` threads running work() (which returns the flops it did) at once:
// all flops over the wall time from the moment every thread is ready (a spin barrier) to the
// last one's end, so threads that do not overlap do not add up; best of `reps` passes.
template <class F>
double all_threads(int threads, int reps, F&& work) {
  double best = 0;
  for (int r = 0; r < reps; ++r) {
    std::vector<double> v(static_cast<std::size_t>(threads), 0.0);
    std::atomic<int> ready{0};
    std::atomic<bool> go{false};
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t)
      pool.emplace_back([&, t] {
        ready.fetch_add(1);
        while (!go.load(std::memory_order_acquire)) {
        }
        v[static_cast<std::size_t>(t)] = work();
      });
    while (ready.load() < threads) {
    }
    const auto t0 = std::chrono::steady_clock::now();
    go.store(true, std::memory_order_release);
    for (auto& th : pool) th.join();
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    double sum = 0;
    for (double x : v) sum += x;
    best = std::max(best, sum / s);
  }
  return best;
}

// STREAM triad a[i] = b[i] + s·c[i] over three arrays of `n` doubles, each thread on its own
// slice (first touch by the same thread); bytes 3·8·n per pass; best of `reps` after a warm-up.
inline double triad_gbs(int threads, std::size_t n, int reps) {
  std::vector<double> a(n), b(n), c(n);
  auto slice = [&](int t) {
    const std::size_t lo = n * static_cast<std::size_t>(t) / static_cast<std::size_t>(threads);
    const std::size_t hi = n * static_cast<std::size_t>(t + 1) / static_cast<std::size_t>(threads);
    return std::pair<std::size_t, std::size_t>(lo, hi);
  };
  auto run = [&](auto&& body) {
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t) pool.emplace_back([&, t] {
      const auto [lo, hi] = slice(t);
      body(lo, hi);
    });
    for (auto& th : pool) th.join();
  };
  run([&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) {
      a[i] = 0;
      b[i] = 1;
      c[i] = 2;
    }
  });
  volatile double vs = 0.5;
  const double s = vs;
  double best = 0;
  for (int r = 0; r <= reps; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    run([&](std::size_t lo, std::size_t hi) {
      double* __restrict pa = a.data();
      const double* __restrict pb = b.data();
      const double* __restrict pc = c.data();
      for (std::size_t i = lo; i < hi; ++i) pa[i] = pb[i] + s * pc[i];
    });
    const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (r > 0) best = std::max(best, 3.0 * 8.0 * static_cast<double>(n) / sec / 1e9);
  }
  volatile double sink = a[n / 2];
  (void)sink;
  return best;
}

inline const char* base_isa_name() {
#if defined(__AVX512F__)
  return "AVX-512 (compile flags)";
#elif defined(__FMA__) && defined(__AVX2__)
  return "AVX2+FMA (compile flags)";
#elif defined(__AVX__)
  return "AVX (compile flags)";
#elif defined(__SSE2__)
  return "SSE2 (x86-64 baseline)";
#elif defined(__ARM_NEON)
  return "NEON";
#else
  return "generic";
#endif
}

}  // namespace detail

// Measures the machine (~4 s on 2 cores): 50 passes per ISA and precision, 6 triads.
inline Machine measure_machine(int threads = 0) {
  Machine m;
  {
    std::ifstream f("/proc/loadavg");
    std::string a, b, c;
    if (f >> a >> b >> c) m.loadavg = a + " " + b + " " + c;
  }
  m.threads = threads > 0 ? threads : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const long iters = 4000000;  // 12 chains × 4 M steps: 8–30 ms per pass on a 3 GHz x86-64
  m.fp32_base = detail::all_threads(m.threads, 50, [&] { return detail::base_chains<float>(iters); }) / 1e9;
  m.fp64_base = detail::all_threads(m.threads, 50, [&] { return detail::base_chains<double>(iters); }) / 1e9;
  m.fp32_avx2 = detail::all_threads(m.threads, 50, [&] { return avx2_fma_chains(false, iters); }) / 1e9;
  m.fp64_avx2 = detail::all_threads(m.threads, 50, [&] { return avx2_fma_chains(true, iters); }) / 1e9;
  m.base_isa = detail::base_isa_name();
  m.fp32_gflops = std::max(m.fp32_base, m.fp32_avx2);
  m.fp64_gflops = std::max(m.fp64_base, m.fp64_avx2);
  m.best_isa = m.fp32_avx2 > m.fp32_base ? "AVX2+FMA (bench/floor_avx2.cpp)" : m.base_isa;
  m.bandwidth_gbs = detail::triad_gbs(m.threads, std::size_t(16) << 20, 5);  // 3 × 128 MB
  return m;
}

// Reads bench_floor --json=FILE's object (the numbers by their keys; no JSON library). An
// unreadable file or one without fp32_gflops and bandwidth_gbs gives ok = false.
inline Machine load_machine(const std::string& path, bool& ok) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string t = ss.str();
  auto number = [&](const char* key) {
    const std::string k = std::string("\"") + key + "\":";
    const auto p = t.find(k);
    return p == std::string::npos ? 0.0 : std::strtod(t.c_str() + p + k.size(), nullptr);
  };
  auto text = [&](const char* key) {
    const std::string k = std::string("\"") + key + "\": \"";
    const auto p = t.find(k);
    if (p == std::string::npos) return std::string();
    const auto e = t.find('"', p + k.size());
    return t.substr(p + k.size(), e == std::string::npos ? std::string::npos : e - p - k.size());
  };
  Machine m;
  m.fp32_gflops = number("fp32_gflops");
  m.fp64_gflops = number("fp64_gflops");
  m.fp32_base = number("fp32_base_gflops");
  m.fp64_base = number("fp64_base_gflops");
  m.fp32_avx2 = number("fp32_avx2_gflops");
  m.fp64_avx2 = number("fp64_avx2_gflops");
  m.bandwidth_gbs = number("bandwidth_gbs");
  m.threads = static_cast<int>(number("threads"));
  m.base_isa = text("base_isa");
  m.best_isa = text("best_isa");
  m.loadavg = text("loadavg");
  ok = m.fp32_gflops > 0 && m.bandwidth_gbs > 0;
  return m;
}

}  // namespace smg_bench::roofline
