// bench/cuda/bench_cuda.cu — smg's CUDA kernels alone (no framework around them), timed with CUDA
// events (Google Benchmark manual time): node confidences, C-ARAP and ARAP energy and
// energy + gradients, the reverse graph, in float and double. Without a CUDA device it prints
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
#include "smg/smg.hpp"

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
