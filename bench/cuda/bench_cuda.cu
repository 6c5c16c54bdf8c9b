// bench/cuda/bench_cuda.cu — smg's CUDA kernels alone (no framework around them), timed with CUDA
// events (Google Benchmark manual time): node confidences, C-ARAP, ARAP and LRM energy and
// energy + gradients, the reverse graph, in float and double; DQB forward and forward + backward
// of SMG_BENCH_P (32768) points with K + 1 drivers each (drivers and weights computed once on
// the CPU, as a trainer keeps them), one query frame. Without a CUDA device it prints
// one line and exits 0 (CI compiles it; bench/torch/bench_cuda.py compares with PyTorch).
//
// Size at run time: SMG_BENCH_N (5000), SMG_BENCH_T (100), SMG_BENCH_K (16); gaps 1, 2, 4. The
// scene is tests/energy/scene.hpp's rigid bodies with noise (random node order).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "energy/scene.hpp"
#include "smg/cuda/carap.cuh"
#include "smg/cuda/confidence.cuh"
#include "smg/cuda/dqb.cuh"
#include "smg/cuda/lrm.cuh"
#include "smg/smg.hpp"
#include "support/random.hpp"

namespace {

using smg::Index;

Index env_size(const char* name, Index fallback) {
  const char* v = std::getenv(name);
  return v != nullptr && *v != '\0' ? static_cast<Index>(std::atoll(v)) : fallback;
}

const smg::test::Scene<double>& scene() {
  static const smg::test::Scene<double> s = [] {
    const Index T = env_size("SMG_BENCH_T", 100), N = env_size("SMG_BENCH_N", 5000),
                K = env_size("SMG_BENCH_K", 16);
    return smg::test::rigid_bodies_scene(T, N, K);
  }();
  return s;
}

template <class T>
struct Dev {
  T* p = nullptr;
  explicit Dev(const std::vector<T>& h) {
    cudaMalloc(&p, h.size() * sizeof(T));
    cudaMemcpy(p, h.data(), h.size() * sizeof(T), cudaMemcpyHostToDevice);
  }
  explicit Dev(std::size_t n) { cudaMalloc(&p, n * sizeof(T)); cudaMemset(p, 0, n * sizeof(T)); }
  Dev(const Dev&) = delete;
  Dev& operator=(const Dev&) = delete;
  ~Dev() { cudaFree(p); }
};

// Device copies of the scene in S.
template <class S>
struct DeviceScene {
  Index T, N, K;
  Dev<S> x, q, c, w;
  Dev<std::int32_t> idx;
  Dev<std::uint8_t> v;
  Dev<S> gx, gq, conf;
  Dev<smg::Accumulator<S>> energy;
  smg::cuda::ReverseGraph rev;
  explicit DeviceScene(const smg::test::Scene<double>& s)
      : T(s.T), N(s.N), K(s.K), x(std::vector<S>(s.x.begin(), s.x.end())),
        q(std::vector<S>(s.q.begin(), s.q.end())), c(std::vector<S>(s.c.begin(), s.c.end())),
        w(std::vector<S>(s.w.begin(), s.w.end())), idx(s.idx), v(s.v),
        gx(static_cast<std::size_t>(s.T * s.N * 3)), gq(static_cast<std::size_t>(s.T * s.N * 4)),
        conf(static_cast<std::size_t>(s.T * s.N)), energy(1) {
    smg::cuda::build_reverse_graph(idx.p, N, K, nullptr, rev);
    cudaDeviceSynchronize();
  }
  smg::NeighborsView<S> graph() const { return {idx.p, w.p, N, K}; }
};

// Times f() (queued on the default stream) with CUDA events per iteration.
template <class F>
void cuda_loop(benchmark::State& state, F&& f) {
  cudaEvent_t a, b;
  cudaEventCreate(&a);
  cudaEventCreate(&b);
  f();  // warm-up (scratch pool, caches)
  cudaDeviceSynchronize();
  for (auto _ : state) {
    cudaEventRecord(a);
    const smg::Status st = f();
    cudaEventRecord(b);
    cudaEventSynchronize(b);
    if (!st) {
      state.SkipWithError(st.message().c_str());
      break;
    }
    float ms = 0;
    cudaEventElapsedTime(&ms, a, b);
    state.SetIterationTime(ms * 1e-3);
  }
  cudaEventDestroy(a);
  cudaEventDestroy(b);
  const auto& s = scene();
  state.counters["T"] = static_cast<double>(s.T);
  state.counters["N"] = static_cast<double>(s.N);
  state.counters["K"] = static_cast<double>(s.K);
}

template <class S>
void BM_cuda_confidences(benchmark::State& state) {
  DeviceScene<S> d(scene());
  cuda_loop(state, [&] {
    return smg::cuda::node_confidences<S>({d.x.p, d.T, d.N}, {d.v.p, d.T, d.N}, d.graph(), {},
                                          {d.conf.p, d.T, d.N}, {}, {}, nullptr);
  });
}

template <class S, bool kGradient, bool kPlain>
void BM_cuda_carap(benchmark::State& state) {
  DeviceScene<S> d(scene());
  smg::CarapOptions o;
  cuda_loop(state, [&] {
    smg::PositionsView<S> gx;
    smg::RotationGradientView<S> gq;
    if (kGradient) {
      gx = {d.gx.p, d.T, d.N};
      gq = smg::QuaternionsView<S>(d.gq.p, d.T, d.N);
    }
    if (kPlain)
      return smg::cuda::arap<S>({d.x.p, d.T, d.N}, {d.q.p, d.T, d.N}, d.graph(), {}, d.rev,
                                d.energy.p, gx, gq, nullptr);
    return smg::cuda::carap<S>({d.x.p, d.T, d.N}, {d.q.p, d.T, d.N}, {d.c.p, d.T, d.N}, d.graph(),
                               o, d.rev, d.energy.p, gx, gq, nullptr);
  });
}

template <class S, bool kGradient>
void BM_cuda_lrm(benchmark::State& state) {
  DeviceScene<S> d(scene());
  cuda_loop(state, [&] {
    smg::PositionsView<S> gx;
    if (kGradient) gx = {d.gx.p, d.T, d.N};
    return smg::cuda::lrm<S>({d.x.p, d.T, d.N}, {d.c.p, d.T, d.N}, d.graph(), {}, d.rev,
                             d.energy.p, gx, {}, nullptr);
  });
}

// P points anchored at random nodes with the skin drivers (anchor + its K neighbours) and the
// distance-aware weights of the CPU library, uploaded once.
template <class S>
struct DeviceSkin {
  Index T, N, P, D;
  Dev<S> x, q, pts, pq, w, out_x, out_q, gx, gq, gp, gpq, go_x, go_q;
  Dev<std::int32_t> drivers, t_ref, t_query;
  smg::cuda::ReverseGraph incidence;
  static std::vector<std::int32_t> anchors(Index P, Index N) {
    std::vector<std::int32_t> a(static_cast<std::size_t>(P));
    for (Index p = 0; p < P; ++p) a[static_cast<std::size_t>(p)] = static_cast<std::int32_t>((p * 7919) % N);
    return a;
  }
  struct Host {
    std::vector<std::int32_t> drivers;
    std::vector<S> weights, points, quats;
  };
  static Host host_skin(const smg::test::Scene<double>& s, Index P) {
    Host h;
    const Index D = s.K + 1;
    const std::vector<std::int32_t> a = anchors(P, s.N);
    h.drivers.resize(static_cast<std::size_t>(P * D));
    smg::skin_drivers(s.graph(), smg::SkinIndexView(a.data(), P),
                      smg::TableView<std::int32_t, Eigen::Dynamic>(h.drivers.data(), P, D));
    std::vector<double> pts(static_cast<std::size_t>(P * 3)), quats(static_cast<std::size_t>(P * 4));
    smg::test::Rng rng(7);
    for (Index p = 0; p < P; ++p) {
      const smg::Vector3<double> v = s.pos(0, a[static_cast<std::size_t>(p)]) + rng.vec3(0.05);
      for (int c = 0; c < 3; ++c) pts[static_cast<std::size_t>(p * 3 + c)] = v[c];
      const smg::Quaternion<double> r = rng.quaternion();
      quats[static_cast<std::size_t>(p * 4)] = r.w();
      quats[static_cast<std::size_t>(p * 4 + 1)] = r.x();
      quats[static_cast<std::size_t>(p * 4 + 2)] = r.y();
      quats[static_cast<std::size_t>(p * 4 + 3)] = r.z();
    }
    const std::vector<std::int32_t> t_ref(static_cast<std::size_t>(P), 0);
    const std::vector<double> sigma(static_cast<std::size_t>(s.N), 0.15);
    std::vector<double> w(static_cast<std::size_t>(P * D));
    smg::skinning_weights<double>(s.positions(), smg::SkinDriversView(h.drivers.data(), P, D),
                                  smg::SkinIndexView(t_ref.data(), P),
                                  smg::TableView<const double, 3>(pts.data(), P),
                                  smg::TableView<const double, 1>(sigma.data(), s.N),
                                  smg::TableView<double, Eigen::Dynamic>(w.data(), P, D));
    h.weights.assign(w.begin(), w.end());
    h.points.assign(pts.begin(), pts.end());
    h.quats.assign(quats.begin(), quats.end());
    return h;
  }
  DeviceSkin(const smg::test::Scene<double>& s, Index P_, const Host& h)
      : T(s.T), N(s.N), P(P_), D(s.K + 1), x(std::vector<S>(s.x.begin(), s.x.end())),
        q(std::vector<S>(s.q.begin(), s.q.end())), pts(h.points), pq(h.quats), w(h.weights),
        out_x(static_cast<std::size_t>(P * 3)), out_q(static_cast<std::size_t>(P * 4)),
        gx(static_cast<std::size_t>(T * N * 3)), gq(static_cast<std::size_t>(T * N * 4)),
        gp(static_cast<std::size_t>(P * 3)), gpq(static_cast<std::size_t>(P * 4)),
        go_x(std::vector<S>(static_cast<std::size_t>(P * 3), S(0.1))),
        go_q(std::vector<S>(static_cast<std::size_t>(P * 4), S(0.1))), drivers(h.drivers),
        t_ref(std::vector<std::int32_t>(static_cast<std::size_t>(P), 0)),
        t_query(std::vector<std::int32_t>(1, static_cast<std::int32_t>(s.T / 2))) {
    smg::cuda::build_driver_incidence(drivers.p, P, D, N, nullptr, incidence);
    cudaDeviceSynchronize();
  }
  smg::SkinNodes<S> nodes() const { return {{x.p, T, N}, {q.p, T, N}}; }
  smg::SkinPoints<S> points() const {
    smg::SkinPoints<S> p;
    p.drivers = smg::SkinDriversView(drivers.p, P, D);
    p.weights = smg::TableView<const S, Eigen::Dynamic>(w.p, P, D);
    p.t_ref = smg::SkinIndexView(t_ref.p, P);
    p.positions = smg::TableView<const S, 3>(pts.p, P);
    p.quaternions = smg::TableView<const S, 4>(pq.p, P);
    return p;
  }
};

template <class S, bool kBackward>
void BM_cuda_dqb(benchmark::State& state) {
  const Index P = env_size("SMG_BENCH_P", 32768);
  static const auto host = DeviceSkin<double>::host_skin(scene(), P);
  typename DeviceSkin<S>::Host h{host.drivers, std::vector<S>(host.weights.begin(), host.weights.end()),
                                 std::vector<S>(host.points.begin(), host.points.end()),
                                 std::vector<S>(host.quats.begin(), host.quats.end())};
  DeviceSkin<S> d(scene(), P, h);
  smg::SkinOptions opt;
  cuda_loop(state, [&] {
    smg::SkinBlendOutputs<S> o;
    o.positions = smg::SequenceView<S, 3>(d.out_x.p, 1, P);
    o.quaternions = smg::SequenceView<S, 4>(d.out_q.p, 1, P);
    const smg::SkinIndexView tq(d.t_query.p, 1);
    smg::Status st = smg::cuda::skin_blend<S>(d.nodes(), d.points(), tq, o, opt, nullptr);
    if (!st || !kBackward) return st;
    smg::SkinBlendOutputGradients<S> go;
    go.positions = smg::SequenceView<const S, 3>(d.go_x.p, 1, P);
    go.quaternions = smg::SequenceView<const S, 4>(d.go_q.p, 1, P);
    smg::SkinBlendGradients<S> g;
    g.node_positions = smg::PositionsView<S>(d.gx.p, d.T, d.N);
    g.node_quaternions = smg::QuaternionsView<S>(d.gq.p, d.T, d.N);
    g.points = smg::TableView<S, 3>(d.gp.p, P);
    g.point_quaternions = smg::TableView<S, 4>(d.gpq.p, P);
    return smg::cuda::skin_blend_backward<S>(d.nodes(), d.points(), tq, go, g, d.incidence, opt,
                                             nullptr);
  });
  state.counters["P"] = static_cast<double>(P);
}

template <class S>
void BM_cuda_reverse_graph(benchmark::State& state) {
  DeviceScene<S> d(scene());
  cuda_loop(state, [&] {
    smg::cuda::ReverseGraph r;
    return smg::cuda::build_reverse_graph(d.idx.p, d.N, d.K, nullptr, r);
  });
}

}  // namespace

#define SMG_CUDA_BENCH(...) BENCHMARK(__VA_ARGS__)->UseManualTime()->Unit(benchmark::kMicrosecond)
SMG_CUDA_BENCH(BM_cuda_confidences<float>);
SMG_CUDA_BENCH(BM_cuda_confidences<double>);
SMG_CUDA_BENCH(BM_cuda_carap<float, false, false>)->Name("BM_cuda_carap_energy<float>");
SMG_CUDA_BENCH(BM_cuda_carap<float, true, false>)->Name("BM_cuda_carap_gradient<float>");
SMG_CUDA_BENCH(BM_cuda_carap<double, true, false>)->Name("BM_cuda_carap_gradient<double>");
SMG_CUDA_BENCH(BM_cuda_carap<float, true, true>)->Name("BM_cuda_arap_gradient<float>");
SMG_CUDA_BENCH(BM_cuda_lrm<float, false>)->Name("BM_cuda_lrm_energy<float>");
SMG_CUDA_BENCH(BM_cuda_lrm<float, true>)->Name("BM_cuda_lrm_gradient<float>");
SMG_CUDA_BENCH(BM_cuda_lrm<double, true>)->Name("BM_cuda_lrm_gradient<double>");
SMG_CUDA_BENCH(BM_cuda_dqb<float, false>)->Name("BM_cuda_dqb_forward<float>");
SMG_CUDA_BENCH(BM_cuda_dqb<float, true>)->Name("BM_cuda_dqb_forward_backward<float>");
SMG_CUDA_BENCH(BM_cuda_dqb<double, true>)->Name("BM_cuda_dqb_forward_backward<double>");
SMG_CUDA_BENCH(BM_cuda_reverse_graph<float>);

int main(int argc, char** argv) {
  if (!smg::cuda::device_available()) {
    std::printf("bench_cuda: skipped, no CUDA device\n");
    return 0;
  }
  cudaDeviceProp prop{};
  cudaGetDeviceProperties(&prop, 0);
  benchmark::AddCustomContext("cuda_device", prop.name);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
