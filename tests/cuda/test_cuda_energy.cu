// CUDA against CPU: node confidences, C-ARAP and plain ARAP (energies and gradients) on random
// and hard cases, in double (1e-12 relative) and float (1e-5), and bit-identical repeat runs.
#include <cstdint>
#include <random>
#include <type_traits>
#include <vector>

#include "cuda/cuda_support.cuh"
#include "smg/cuda/carap.cuh"
#include "smg/cuda/confidence.cuh"
#include "smg/cuda/validate.cuh"
#include "smg/smg.hpp"

using smg::Index;
using namespace smg_test;

namespace {

// A random scene: T frames of N nodes, K neighbours per row (padding, zero weights and an empty
// row included), unnormalised rotations, confidences in [0, 1].
template <class S, class I>
struct Scene {
  Index T, N, K;
  std::vector<S> x, q, conf, w;
  std::vector<I> idx;
  std::vector<std::uint8_t> vis;
  Scene(Index T_, Index N_, Index K_, unsigned seed, bool hard = false) : T(T_), N(N_), K(K_) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> nd;
    std::uniform_real_distribution<double> ud(0, 1);
    x.resize(T * N * 3);
    q.resize(T * N * 4);
    conf.resize(T * N);
    vis.resize(T * N);
    for (Index i = 0; i < N; ++i) {
      const double b[3] = {nd(rng), nd(rng), nd(rng)};
      for (Index t = 0; t < T; ++t)
        for (int c = 0; c < 3; ++c) x[(t * N + i) * 3 + c] = S(b[c] + 0.1 * t * nd(rng) * 0.3);
    }
    for (auto& v : q) v = S(nd(rng));
    for (Index k = 0; k < T * N; ++k) {
      conf[k] = S(hard ? 0.0 : ud(rng));
      vis[k] = ud(rng) < 0.8;
    }
    idx.assign(N * K, I(-1));
    w.assign(N * K, S(0));
    for (Index i = 0; i < N; ++i) {
      if (i == 3) continue;  // an empty row
      const Index deg = (i % 5 == 0) ? K - 2 : K;  // some rows padded
      Index k = 0;
      for (Index a = 1; k < deg && a < N; ++a) {
        const Index j = (i + a * 7 + (i % 3)) % N;
        if (j == i) continue;
        bool dup = false;
        for (Index m = 0; m < k; ++m) dup = dup || idx[i * K + m] == I(j);
        if (dup) continue;
        idx[i * K + k] = I(j);
        w[i * K + k] = (i % 7 == 1 && k == 0) ? S(0) : S(0.1 + ud(rng));
        ++k;
      }
    }
    if (hard) {  // zero-length edges: node 1 sits on node 0's neighbours at every frame
      for (Index t = 0; t < T; ++t)
        for (int c = 0; c < 3; ++c) x[(t * N + 1) * 3 + c] = x[(t * N + idx[0]) * 3 + c];
    }
  }
  smg::PositionsView<const S> X() const { return {x.data(), T, N}; }
  smg::QuaternionsView<const S> Q() const { return {q.data(), T, N}; }
  smg::NeighborsView<S, I> G() const { return {idx.data(), w.data(), N, K}; }
};

template <class S, class I>
void check_confidences(const Scene<S, I>& s, double tol) {
  const Index T = s.T, N = s.N;
  std::vector<S> c(T * N), m(T * N), r(T * N);
  smg::ConfidenceOptions o;
  REQUIRE(smg::validate_confidence<S, I>(s.X(), {s.vis.data(), T, N}, s.G(), o, {c.data(), T, N}));
  smg::node_confidences<S, I>(s.X(), {s.vis.data(), T, N}, s.G(), o, {c.data(), T, N},
                              {m.data(), T, N}, {r.data(), T, N});
  DeviceVector<S> dx(s.x), dw(s.w), dc(T * N), dm(T * N), dr(T * N);
  DeviceVector<I> di(s.idx);
  DeviceVector<std::uint8_t> dv(s.vis);
  smg::NeighborsView<S, I> g(di.p, dw.p, N, s.K);
  const smg::Status st = smg::cuda::node_confidences<S, I>(
      {dx.p, T, N}, {dv.p, T, N}, g, o, {dc.p, T, N}, {dm.p, T, N}, {dr.p, T, N}, nullptr);
  REQUIRE_MESSAGE(st, st.message());
  CUDA_CHECK(cudaDeviceSynchronize());
  if constexpr (std::is_same_v<S, double>) {
    CHECK(max_relative(dc.host(), c) <= tol);
    CHECK(max_relative(dm.host(), m) <= tol);
    CHECK(max_relative(dr.host(), r) <= tol);
  } else {
    // c^r is ill-conditioned (it divides a difference of edge-length changes by their spread),
    // and the GPU contracts to FMAs and its expf is within 2 ulp where glibc's is within 1: in
    // float, each side is compared with double on the same inputs, and the GPU must be within
    // 1e-5 or within 4x the CPU's own float error, whichever is larger (measured on an H100:
    // c^r 1.96e-5 on the GPU against 0.96e-5 on the CPU).
    const std::vector<double> xd(s.x.begin(), s.x.end()), wd(s.w.begin(), s.w.end());
    std::vector<double> cd(T * N), md(T * N), rd(T * N);
    smg::NeighborsView<double, I> gd(s.idx.data(), wd.data(), N, s.K);
    smg::node_confidences<double, I>({xd.data(), T, N}, {s.vis.data(), T, N}, gd, o,
                                     {cd.data(), T, N}, {md.data(), T, N}, {rd.data(), T, N});
    auto within = [&](const std::vector<S>& gpu, const std::vector<S>& cpu,
                      const std::vector<double>& ref) {
      const double eg = max_relative(gpu, ref), ec = max_relative(cpu, ref);
      INFO("gpu float error " << eg << ", cpu float error " << ec);
      CHECK(eg <= std::max(tol, 4 * ec));
    };
    within(dc.host(), c, cd);
    within(dm.host(), m, md);
    within(dr.host(), r, rd);
  }
}

template <class S, class I>
void check_carap(const Scene<S, I>& s, double tol, bool raw, bool arap) {
  using Acc = smg::Accumulator<S>;
  const Index T = s.T, N = s.N;
  smg::CarapOptions o;
  o.alpha = 0.3;
  o.lambda_l = 0.7;
  o.gaps = {{1, 1.0}, {2, 0.5}, {4, 0.25}};
  smg::ArapOptions ao;
  ao.lambda_l = 0.7;
  ao.gaps = o.gaps;
  std::vector<S> gx(T * N * 3, S(0.5)), gr(T * N * (raw ? 4 : 3), S(-0.25));
  const std::vector<S> gx0 = gx, gr0 = gr;
  smg::RotationGradientView<S> grv =
      raw ? smg::RotationGradientView<S>(smg::QuaternionsView<S>(gr.data(), T, N))
          : smg::RotationGradientView<S>(smg::TangentsView<S>(gr.data(), T, N));
  smg::FrameScalarsView<const S> conf(s.conf.data(), T, N);
  const Acc e = arap ? smg::arap<S, I>(s.X(), s.Q(), s.G(), ao, {gx.data(), T, N}, grv)
                     : smg::carap<S, I>(s.X(), s.Q(), conf, s.G(), o, {gx.data(), T, N}, grv);

  DeviceVector<S> dx(s.x), dq(s.q), dconf(s.conf), dw(s.w), dgx(gx0), dgr(gr0);
  DeviceVector<I> di(s.idx);
  DeviceVector<Acc> de(1);
  smg::NeighborsView<S, I> g(di.p, dw.p, N, s.K);
  smg::cuda::ReverseGraph rev;
  REQUIRE(smg::cuda::build_reverse_graph(di.p, N, s.K, nullptr, rev));
  smg::RotationGradientView<S> dgrv =
      raw ? smg::RotationGradientView<S>(smg::QuaternionsView<S>(dgr.p, T, N))
          : smg::RotationGradientView<S>(smg::TangentsView<S>(dgr.p, T, N));
  auto run = [&](Acc* energy, smg::PositionsView<S> gpx, smg::RotationGradientView<S> gpr) {
    const smg::Status st =
        arap ? smg::cuda::arap<S, I>({dx.p, T, N}, {dq.p, T, N}, g, ao, rev, energy, gpx, gpr, nullptr)
             : smg::cuda::carap<S, I>({dx.p, T, N}, {dq.p, T, N}, {dconf.p, T, N}, g, o, rev,
                                      energy, gpx, gpr, nullptr);
    REQUIRE_MESSAGE(st, st.message());
    CUDA_CHECK(cudaDeviceSynchronize());
  };
  run(de.p, {dgx.p, T, N}, dgrv);
  const Acc eg = de.host()[0];
  INFO("cpu energy " << double(e) << " gpu " << double(eg));
  CHECK(std::abs(double(eg - e)) <= tol * std::abs(double(e)));
  CHECK(max_relative(dgx.host(), gx) <= tol);
  CHECK(max_relative(dgr.host(), gr) <= tol);

  // Energy only, and a second run: the same bits.
  DeviceVector<Acc> de2(1);
  run(de2.p, {}, {});
  CHECK(bit_identical(de.host().data(), de2.host().data(), sizeof(Acc)));
  DeviceVector<S> dgx2(gx0), dgr2(gr0);
  smg::RotationGradientView<S> dgrv2 =
      raw ? smg::RotationGradientView<S>(smg::QuaternionsView<S>(dgr2.p, T, N))
          : smg::RotationGradientView<S>(smg::TangentsView<S>(dgr2.p, T, N));
  run(de2.p, {dgx2.p, T, N}, dgrv2);
  const auto a = dgx.host(), b = dgx2.host(), ra = dgr.host(), rb = dgr2.host();
  CHECK(bit_identical(a.data(), b.data(), a.size() * sizeof(S)));
  CHECK(bit_identical(ra.data(), rb.data(), ra.size() * sizeof(S)));
}

}  // namespace

TEST_CASE("cuda node_confidences equal the CPU's (double, float; int32, int64)") {
  check_confidences(Scene<double, std::int32_t>(9, 60, 6, 1), 1e-12);
  check_confidences(Scene<double, std::int64_t>(7, 45, 5, 2, true), 1e-12);
  check_confidences(Scene<float, std::int32_t>(9, 60, 6, 3), 1e-5);
}

TEST_CASE("cuda carap and arap equal the CPU's: energy, position and rotation gradients") {
  for (bool raw : {false, true}) {
    CAPTURE(raw);
    check_carap(Scene<double, std::int32_t>(11, 50, 6, 4), 1e-12, raw, false);
    check_carap(Scene<double, std::int64_t>(6, 40, 5, 5, true), 1e-12, raw, false);
    check_carap(Scene<double, std::int32_t>(11, 50, 6, 6), 1e-12, raw, true);
    check_carap(Scene<float, std::int32_t>(11, 50, 6, 7), 1e-5, raw, false);
    check_carap(Scene<float, std::int64_t>(3, 30, 4, 8, true), 1e-5, raw, true);
    // K = 40 in double: the gather's shared-memory tile would exceed 48 KiB, the direct path runs.
    check_carap(Scene<double, std::int32_t>(4, 90, 40, 12), 1e-12, raw, false);
  }
}

TEST_CASE("cuda carap reports bad shapes and options before launching") {
  Scene<double, std::int32_t> s(4, 10, 3, 9);
  DeviceVector<double> dx(s.x), dq(s.q), dw(s.w);
  DeviceVector<std::int32_t> di(s.idx);
  DeviceVector<double> de(1);
  smg::NeighborsView<double> g(di.p, dw.p, s.N, s.K);
  smg::cuda::ReverseGraph rev;
  REQUIRE(smg::cuda::build_reverse_graph(di.p, s.N, s.K, nullptr, rev));
  smg::CarapOptions bad;
  bad.alpha = 2;
  // Mutable views and no template arguments: S and I come from the graph.
  smg::Status st = smg::cuda::carap(smg::PositionsView<double>(dx.p, 4, 10),
                                    smg::QuaternionsView<double>(dq.p, 4, 10), {}, g, bad, rev, de.p,
                                    {}, {}, nullptr);
  CHECK(!st);
  CHECK(st.message() == smg::validate_options(bad).message());
  st = smg::cuda::carap<double>({dx.p, 4, 10}, {dq.p, 3, 10}, {}, g, {}, rev, de.p, {}, {}, nullptr);
  CHECK(!st);
  CHECK(st.message().rfind("rotations:", 0) == 0);
}

TEST_CASE("cuda validate_* give the CPU validators' messages; mean normalisation equals the CPU's") {
  Scene<double, std::int64_t> s(5, 20, 4, 10);
  s.x[(2 * 20 + 7) * 3 + 1] = std::nan("");
  s.idx[4 * 4 + 1] = 999;
  DeviceVector<double> dx(s.x), dq(s.q), dw(s.w), dc(s.conf);
  DeviceVector<std::int64_t> di(s.idx);
  smg::NeighborsView<double, std::int64_t> g(di.p, dw.p, s.N, s.K);
  const smg::Status cpu = smg::validate_carap<double, std::int64_t>(s.X(), s.Q(), {s.conf.data(), 5, 20}, s.G(), {});
  const smg::Status gpu = smg::cuda::validate_carap<double, std::int64_t>({dx.p, 5, 20}, {dq.p, 5, 20}, {dc.p, 5, 20}, g, {});
  REQUIRE(!cpu);
  CHECK(gpu.message() == cpu.message());
  s.x[(2 * 20 + 7) * 3 + 1] = 0.5;
  DeviceVector<double> dx2(s.x);
  const smg::Status cpu2 = smg::validate_lrm<double, std::int64_t>(s.X(), {}, s.G(), {});
  const smg::Status gpu2 = smg::cuda::validate_lrm<double, std::int64_t>({dx2.p, 5, 20}, {}, g, {});
  REQUIRE(!cpu2);
  CHECK(gpu2.message() == cpu2.message());

  Scene<double, std::int32_t> m(6, 30, 5, 11);
  smg::CarapOptions o;
  o.normalization = smg::Normalization::mean;
  o.weight = 3.0;
  const double e = smg::carap<double, std::int32_t>(m.X(), m.Q(), {m.conf.data(), 6, 30}, m.G(), o);
  DeviceVector<double> mx(m.x), mq(m.q), mw(m.w), mc(m.conf), me(1);
  DeviceVector<std::int32_t> mi(m.idx);
  smg::cuda::ReverseGraph rev;
  REQUIRE(smg::cuda::build_reverse_graph(mi.p, m.N, m.K, nullptr, rev));
  const smg::Status st = smg::cuda::carap<double, std::int32_t>(
      {mx.p, 6, 30}, {mq.p, 6, 30}, {mc.p, 6, 30}, {mi.p, mw.p, m.N, m.K}, o, rev, me.p, {}, {}, nullptr);
  REQUIRE(st);
  CHECK(std::abs(me.host()[0] - e) <= 1e-12 * std::abs(e));
}
