// Tests of smg/cuda/lrm.cuh: smg::cuda::lrm against the CPU smg::lrm on random and hard cases
// (double within 1e-12 of the largest magnitude, float within 1e-5), two GPU runs bit-identical,
// and the host-side validation.
#include <doctest/doctest.h>

#include <cstdint>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "smg/cuda/lrm.cuh"
#include "smg/energy/lrm.hpp"
#include "support/random.hpp"

#include "cuda/cuda_test_support.cuh"

namespace {

using smg::Index;
using namespace smg::test::cuda;

// A test problem in double (cast to the scalar of the run).
struct LrmCase : CaseSizes {
  std::vector<double> x;        // [T][N][3]
  std::vector<double> c;        // [T][N]; empty = no confidence
  std::vector<std::int64_t> idx;  // [N][K]
  std::vector<double> w;        // [N][K]
  smg::LrmOptions options;
};

// Random trajectories (a base position plus small per-frame motion, so that the Huber loss sees
// both branches), random graph with degrees in [min_deg, K] (−1 padding), random weights.
LrmCase random_case(const std::string& name, Index T, Index N, Index K, Index min_deg,
                    std::uint64_t seed, bool with_conf) {
  smg::test::Rng rng(seed);
  LrmCase c;
  static_cast<CaseSizes&>(c) = {name, T, N, K};
  c.x.resize(static_cast<std::size_t>(T * N * 3));
  std::vector<double> base(static_cast<std::size_t>(N * 3)), vel(static_cast<std::size_t>(N * 3));
  for (auto& v : base) v = rng.uniform();
  for (auto& v : vel) v = 0.02 * rng.uniform();
  for (Index t = 0; t < T; ++t)
    for (Index i = 0; i < N; ++i)
      for (int d = 0; d < 3; ++d)
        c.x[static_cast<std::size_t>((t * N + i) * 3 + d)] =
            base[static_cast<std::size_t>(i * 3 + d)] + double(t) * vel[static_cast<std::size_t>(i * 3 + d)] +
            0.01 * rng.uniform();
  if (with_conf) {
    c.c.resize(static_cast<std::size_t>(T * N));
    for (auto& v : c.c) v = rng.uniform(0.0, 1.0);
  }
  c.idx.assign(static_cast<std::size_t>(N * K), -1);
  c.w.assign(static_cast<std::size_t>(N * K), 0.0);
  for (Index i = 0; i < N; ++i) {
    const Index deg = std::min<Index>(N - 1, rng.integer(int(min_deg), int(K)));
    std::vector<Index> perm;
    for (Index j = 0; j < N; ++j)
      if (j != i) perm.push_back(j);
    std::shuffle(perm.begin(), perm.end(), rng.engine);
    for (Index k = 0; k < deg; ++k) {
      c.idx[static_cast<std::size_t>(i * K + k)] = perm[static_cast<std::size_t>(k)];
      c.w[static_cast<std::size_t>(i * K + k)] = rng.uniform(0.2, 1.0);
    }
  }
  c.options.huber_delta = 0.01;
  return c;
}

template <class I>
std::vector<I> cast_idx(const std::vector<std::int64_t>& v) {
  return std::vector<I>(v.begin(), v.end());
}

struct LrmResult {
  double energy = 0;
  std::vector<double> grad, omega;
};

// CPU reference: smg::lrm on the host, gradient added to `grad0`.
template <class S, class I>
LrmResult run_cpu(const LrmCase& c, const std::vector<S>& grad0) {
  const auto x = cast<S>(c.x), conf = cast<S>(c.c), w = cast<S>(c.w);
  const auto idx = cast_idx<I>(c.idx);
  std::vector<S> grad = grad0, omega(static_cast<std::size_t>(c.T * c.N * 3), S(0));
  const smg::NeighborsView<S, I> g(idx.data(), w.data(), c.N, c.K);
  smg::FrameScalarsView<const S> cv;
  if (!conf.empty()) cv = smg::FrameScalarsView<const S>(conf.data(), c.T, c.N);
  LrmResult r;
  r.energy = double(smg::lrm<S, I>(smg::PositionsView<const S>(x.data(), c.T, c.N), cv, g,
                                   c.options, smg::PositionsView<S>(grad.data(), c.T, c.N),
                                   nullptr, {}, smg::TangentsView<S>(omega.data(), c.T, c.N)));
  r.grad.assign(grad.begin(), grad.end());
  r.omega.assign(omega.begin(), omega.end());
  return r;
}

// GPU run: the same inputs uploaded, gradient added to `grad0`; results in S (for bitwise checks).
template <class S>
struct GpuRaw {
  smg::Accumulator<S> energy{};
  std::vector<S> grad, omega;
};
template <class S, class I>
GpuRaw<S> run_gpu(const LrmCase& c, const std::vector<S>& grad0, bool want_grad = true,
                  bool want_omega = true) {
  Stream st;
  DeviceArray<S> x(cast<S>(c.x)), conf(cast<S>(c.c)), w(cast<S>(c.w)), grad(grad0);
  DeviceArray<I> idx(cast_idx<I>(c.idx));
  DeviceArray<S> omega;
  omega.resize(static_cast<std::size_t>(c.T * c.N * 3));
  SMG_TEST_CUDA(cudaMemset(omega.get(), 0, omega.size() * sizeof(S)));
  DeviceArray<smg::Accumulator<S>> energy;
  energy.resize(1);
  smg::cuda::ReverseGraph rev;
  smg::Status s = smg::cuda::build_reverse_graph(idx.get(), c.N, c.K, st.s, rev);
  REQUIRE_MESSAGE(s.is_ok(), s.message());
  smg::FrameScalarsView<const S> cv;
  if (!c.c.empty()) cv = smg::FrameScalarsView<const S>(conf.get(), c.T, c.N);
  s = smg::cuda::lrm<S, I>(smg::PositionsView<const S>(x.get(), c.T, c.N), cv,
                           smg::NeighborsView<S, I>(idx.get(), w.get(), c.N, c.K), c.options, rev,
                           energy.get(),
                           want_grad ? smg::PositionsView<S>(grad.get(), c.T, c.N)
                                     : smg::PositionsView<S>(),
                           want_omega ? smg::TangentsView<S>(omega.get(), c.T, c.N)
                                      : smg::TangentsView<S>(),
                           st.s);
  REQUIRE_MESSAGE(s.is_ok(), s.message());
  st.sync();
  SMG_TEST_CUDA(cudaGetLastError());
  GpuRaw<S> r;
  r.energy = energy.download()[0];
  r.grad = grad.download();
  r.omega = omega.download();
  return r;
}

// GPU vs CPU (energy, gradient added to a nonzero start, ω) and two GPU runs bit-identical.
template <class S, class I>
void compare(const LrmCase& c) {
  CAPTURE(c.name);
  const std::string tag = c.name + (sizeof(S) == 8 ? " [double" : " [float") +
                          (sizeof(I) == 8 ? ", int64]" : ", int32]");
  CAPTURE(tag);
  smg::test::Rng rng(99);
  std::vector<S> grad0(static_cast<std::size_t>(c.T * c.N * 3));
  for (auto& v : grad0) v = S(rng.uniform());
  const LrmResult cpu = run_cpu<S, I>(c, grad0);
  const GpuRaw<S> a = run_gpu<S, I>(c, grad0), b = run_gpu<S, I>(c, grad0);
  const double tol = tolerance<S>();
  // The gradient is compared after removing the start value (so that its scale is the LRM part).
  std::vector<double> dg_gpu(a.grad.size()), dg_cpu(a.grad.size());
  for (std::size_t k = 0; k < a.grad.size(); ++k) {
    dg_gpu[k] = double(a.grad[k]) - double(grad0[k]);
    dg_cpu[k] = cpu.grad[k] - double(grad0[k]);
  }
  // Floors: an all-zero reference (no edges, no motion) is compared absolutely at tol · 1. The
  // gradient also at the start value's rounding: both sides add their terms to grad0 (|grad0| up
  // to 1), the GPU one at a time and the CPU in other groups, and each addition rounds at grad0's
  // ulp, which grad − grad0 cannot resolve; where the LRM part is small against grad0 (mean
  // normalisation: 1e-5 against 1) that, not tol, is the bound. (An H200, 2026-11-28: every mean
  // case differed by 2^-53 in double and 2^-24 or 2^-23 in float, within one ulp of grad0; the
  // same with -fmad=false.)
  double g0 = 0;
  for (const S v : grad0) g0 = std::max(g0, std::abs(double(v)));
  const double start_rounding = 4.0 * double(std::numeric_limits<S>::epsilon()) * g0;
  check_close_scalar(double(a.energy), cpu.energy, tol, tag + " energy", 1e-30);
  check_close(dg_gpu, dg_cpu, tol, tag + " gradient", std::max(1e-30, start_rounding / tol));
  check_close(std::vector<double>(a.omega.begin(), a.omega.end()), cpu.omega, tol, tag + " omega",
              1e-30);
  check_bitwise(std::vector<smg::Accumulator<S>>{a.energy}, std::vector<smg::Accumulator<S>>{b.energy},
                tag + " energy");
  check_bitwise(a.grad, b.grad, tag + " gradient");
  check_bitwise(a.omega, b.omega, tag + " omega");
  // Energy alone (no gradient, no ω) gives the same energy bits.
  const GpuRaw<S> e = run_gpu<S, I>(c, grad0, false, false);
  check_bitwise(std::vector<smg::Accumulator<S>>{a.energy}, std::vector<smg::Accumulator<S>>{e.energy},
                tag + " energy without gradient");
  check_bitwise(e.grad, grad0, tag + " gradient untouched when not requested");
}

template <class S>
void compare_both_index_types(const LrmCase& c) {
  compare<S, std::int32_t>(c);
  compare<S, std::int64_t>(c);
}

void compare_all(const LrmCase& c) {
  compare_both_index_types<double>(c);
  compare_both_index_types<float>(c);
}

}  // namespace

TEST_CASE("cuda lrm: random cases match the CPU (sum/mean, detach, weights, K up to 32)") {
  struct Cfg {
    Index T, N, K, min_deg;
    bool conf;
  };
  // Degrees >= 5 (then −1 padding): neighbourhoods of 1-3 random points are (nearly) collinear,
  // where ω along the line is decided by rounding noise over μ = c_μ trace(A) — amplified ~1e6
  // in double — so that no two implementations (CPU lanes vs GPU with contracted FMAs) agree to
  // 1e-12 there; with 4 points, float ω still loses ~1e-5 now and then (a host emulation with
  // FMA contraction measured 6e-6 worst over 100 seeds, 1.5e-6 with 5). Exactly degenerate
  // neighbourhoods are tested below with exact zeros.
  const Cfg cfgs[] = {{6, 40, 8, 5, true},  {5, 30, 6, 5, false}, {4, 50, 16, 5, true},
                      {3, 60, 24, 6, true}, {9, 40, 32, 5, true}, {2, 20, 5, 5, true},
                      {1, 25, 5, 5, true}};
  std::uint64_t seed = 1;
  for (const Cfg& f : cfgs) {
    std::ostringstream n;
    n << "random T=" << f.T << " N=" << f.N << " K=" << f.K << " seed=" << seed;
    LrmCase c = random_case(n.str(), f.T, f.N, f.K, f.min_deg, seed++, f.conf);
    compare_all(c);
    c.options.normalization = smg::Normalization::mean;
    c.options.weight = 0.7;
    c.options.alpha = 0.25;
    c.name = n.str() + " mean, weight 0.7, alpha 0.25";
    compare_all(c);
    c.options.detach_omega = true;
    c.options.huber_delta = 10.0;  // quadratic everywhere
    c.name = n.str() + " detach_omega, huber 10";
    compare_all(c);
  }
}

TEST_CASE("cuda lrm: hard cases (zero-weight rows, empty rows, confidences 0, degenerate)") {
  // Zero-weight rows (valid indices, all weights 0) and rows with no neighbour at all (all −1).
  LrmCase c = random_case("zero-weight and empty rows", 5, 30, 6, 5, 11, true);
  for (Index i = 0; i < c.N; i += 3)
    for (Index k = 0; k < c.K; ++k) c.w[static_cast<std::size_t>(i * c.K + k)] = 0.0;
  for (Index i = 1; i < c.N; i += 7)
    for (Index k = 0; k < c.K; ++k) {
      c.idx[static_cast<std::size_t>(i * c.K + k)] = -1;
      c.w[static_cast<std::size_t>(i * c.K + k)] = 0.0;
    }
  compare_all(c);

  // All confidences 0 (w̃ = α w) and α = 0 (every weight 0: energy 0, gradient 0).
  c = random_case("all confidences 0", 4, 30, 8, 5, 12, true);
  std::fill(c.c.begin(), c.c.end(), 0.0);
  compare_all(c);
  c.options.alpha = 0.0;
  c.name = "all confidences 0, alpha 0";
  compare_all(c);

  // Degenerate neighbourhoods, exactly: at frame 0 every node at the origin (x̃ = 0, trace(A) = 0:
  // the ω = 0 branch; only frame 0, since the velocity into a coincident frame is purely radial,
  // ω = 0 up to rounding noise), at even frames every node on the x axis (A singular along it: μ
  // decides ω_x = 0), and a plane z = 0 at every frame; the other frames are random, so the
  // velocities are not degenerate. Exact zeros keep rounding noise out of the singular direction.
  c = random_case("coincident at frame 0", 4, 24, 6, 5, 13, true);
  for (Index k = 0; k < c.N * 3; ++k) c.x[static_cast<std::size_t>(k)] = 0.0;
  compare_all(c);
  c = random_case("collinear along x at even frames", 5, 24, 6, 5, 14, true);
  for (Index t = 0; t < c.T; t += 2)
    for (Index k = 0; k < c.N * 3; ++k)
      if (k % 3 != 0) c.x[static_cast<std::size_t>(t * c.N * 3 + k)] = 0.0;
  compare_all(c);
  c = random_case("coplanar z = 0", 4, 24, 6, 5, 15, true);
  for (std::size_t k = 2; k < c.x.size(); k += 3) c.x[k] = 0.0;
  compare_all(c);

  // A graph with no edges at all (mean normalisation: 0 terms, energy 0, nothing added).
  c = random_case("no edges, mean", 3, 10, 4, 0, 17, false);
  std::fill(c.idx.begin(), c.idx.end(), -1);
  std::fill(c.w.begin(), c.w.end(), 0.0);
  c.options.normalization = smg::Normalization::mean;
  compare_all(c);
}

TEST_CASE("cuda lrm: validation before launch") {
  Stream st;
  LrmCase c = random_case("validation", 3, 10, 4, 1, 21, false);
  DeviceArray<double> x(c.x), w(c.w), grad(std::vector<double>(c.x.size(), 0.0));
  DeviceArray<std::int32_t> idx(cast_idx<std::int32_t>(c.idx));
  smg::cuda::ReverseGraph rev;
  REQUIRE(smg::cuda::build_reverse_graph(idx.get(), c.N, c.K, st.s, rev).is_ok());
  const smg::PositionsView<const double> xv(x.get(), c.T, c.N);
  const smg::NeighborsView<double> g(idx.get(), w.get(), c.N, c.K);

  smg::LrmOptions bad;
  bad.huber_delta = 0.0;
  smg::Status s = smg::cuda::lrm<double, std::int32_t>(xv, {}, g, bad, rev, nullptr,
                                                       smg::PositionsView<double>(grad.get(), c.T, c.N), {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("huber_delta") != std::string::npos);

  s = smg::cuda::lrm<double, std::int32_t>(xv, {}, g, c.options, rev, nullptr,
                                           smg::PositionsView<double>(grad.get(), c.T, c.N - 1), {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("grad_positions") != std::string::npos);

  const smg::NeighborsView<double> g_short(idx.get(), w.get(), c.N - 1, c.K);
  s = smg::cuda::lrm<double, std::int32_t>(xv, {}, g_short, c.options, rev, nullptr, {}, {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("graph") != std::string::npos);

  smg::cuda::ReverseGraph other;  // not built for this graph
  s = smg::cuda::lrm<double, std::int32_t>(xv, {}, g, c.options, other, nullptr, {}, {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("reverse") != std::string::npos);

  // K above the kernel's maximum.
  const Index K = smg::cuda::kLrmMaxK + 1;
  DeviceArray<std::int32_t> big_idx(std::vector<std::int32_t>(static_cast<std::size_t>(c.N * K), -1));
  DeviceArray<double> big_w(std::vector<double>(static_cast<std::size_t>(c.N * K), 0.0));
  smg::cuda::ReverseGraph big_rev;
  REQUIRE(smg::cuda::build_reverse_graph(big_idx.get(), c.N, K, st.s, big_rev).is_ok());
  s = smg::cuda::lrm<double, std::int32_t>(xv, {}, smg::NeighborsView<double>(big_idx.get(), big_w.get(), c.N, K),
                                           c.options, big_rev, nullptr, {}, {}, st.s);
  CHECK_FALSE(s.is_ok());
  CHECK(s.message().find("graph: K=33") != std::string::npos);
  st.sync();
}

// The launcher's host-side checks read only shapes, so they run without a GPU: host arrays stand
// in for device ones. The exact words pin the messages shared with smg::cuda::regularizers
// (check_neighbors_shape, check_lrm_max_k, check_reverse_graph).
TEST_SUITE("cuda-host") {
  TEST_CASE("cuda lrm: host-side argument checks, word for word") {
    const Index T = 3, N = 10, K = 4;
    std::vector<double> x(static_cast<std::size_t>(T * N * 3), 0.0);
    std::vector<std::int32_t> idx(static_cast<std::size_t>(N * (smg::cuda::kLrmMaxK + 1)), -1);
    std::vector<double> w(idx.size(), 0.0);
    const smg::PositionsView<const double> xv(x.data(), T, N);
    const smg::NeighborsView<double> g(idx.data(), w.data(), N, K);
    smg::cuda::ReverseGraph rev;  // shape only: nothing is read
    rev.nodes = N;
    rev.k = K;
    const smg::LrmOptions o;
    auto msg = [](const smg::Status& s) { return std::string(s.message()); };
    CHECK(smg::cuda::validate_lrm_cuda<double, std::int32_t>(xv, {}, g, o, rev).is_ok());
    CHECK(msg(smg::cuda::validate_lrm_cuda<double, std::int32_t>(
              xv, {}, smg::NeighborsView<double>(idx.data(), w.data(), N - 1, K), o, rev)) ==
          "graph: expected indices and weights of shape [N=10][K], got [9][4] and [9][4]");
    const Index wide = smg::cuda::kLrmMaxK + 1;
    smg::cuda::ReverseGraph rev_wide;
    rev_wide.nodes = N;
    rev_wide.k = wide;
    CHECK(msg(smg::cuda::validate_lrm_cuda<double, std::int32_t>(
              xv, {}, smg::NeighborsView<double>(idx.data(), w.data(), N, wide), o, rev_wide)) ==
          "graph: K=33 neighbours per node exceeds the CUDA LRM kernel's maximum of 32");
    smg::cuda::ReverseGraph other;  // not built for this graph
    CHECK(msg(smg::cuda::validate_lrm_cuda<double, std::int32_t>(xv, {}, g, o, other)) ==
          "reverse: built for a graph of shape [N=0][K=0], this graph is [N=10][K=4] "
          "(build_reverse_graph(graph.indices.data(), N, K, stream, reverse))");
  }
}
