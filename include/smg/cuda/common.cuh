// smg/cuda/common.cuh — what every smg CUDA launcher shares: CUDA errors as smg::Status,
// stream-ordered scratch memory, a deterministic sum, and the reverse adjacency of a graph.
//
// Headers under smg/cuda/ are for CUDA translation units only (nvcc). Their launchers take the
// same views as the CPU entry points, over device memory, and a cudaStream_t; they validate
// shapes and options on the host before launching, and return a Status (never throw). Results
// are deterministic for a given device: no float atomics; every sum has a fixed order.
#pragma once

#include "smg/core/config.hpp"

#if !defined(__CUDACC__)
#error "smg/cuda/*.cuh are CUDA headers: include them from a .cu file compiled by nvcc"
#endif

#include <cuda_runtime.h>

#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "smg/core/status.hpp"
#include "smg/core/types.hpp"

namespace smg::cuda {

// "what: cudaErrorX (message)" as an error Status; ok for cudaSuccess.
inline Status status_from(cudaError_t e, const char* what) {
  if (e == cudaSuccess) return Status::ok();
  return Status::error(std::string(what) + ": " + cudaGetErrorName(e) + " (" +
                       cudaGetErrorString(e) + ")");
}

// Returns the Status of a failed CUDA call from the enclosing function.
#define SMG_CUDA_TRY(expr, what)                                             \
  do {                                                                       \
    const cudaError_t smg_cuda_err_ = (expr);                                \
    if (smg_cuda_err_ != cudaSuccess) return ::smg::cuda::status_from(smg_cuda_err_, what); \
  } while (0)

// True when a CUDA device is present and usable (false on a machine without a GPU or driver).
inline bool device_available() {
  int n = 0;
  return cudaGetDeviceCount(&n) == cudaSuccess && n > 0;
}

// Stream-ordered device memory (cudaMallocAsync / cudaFreeAsync on the launch stream, so that
// scratch costs no device-wide synchronisation and is reused from the driver's pool).
template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept : p_(o.p_), n_(o.n_), stream_(o.stream_) {
    o.p_ = nullptr;
    o.n_ = 0;
  }
  ~DeviceBuffer() { reset(); }

  // (Re)allocates n elements on `stream` (contents undefined).
  Status allocate(std::size_t n, cudaStream_t stream) {
    reset();
    stream_ = stream;
    if (n == 0) return Status::ok();
    void* p = nullptr;
    SMG_CUDA_TRY(cudaMallocAsync(&p, n * sizeof(T), stream), "smg::cuda scratch allocation");
    p_ = static_cast<T*>(p);
    n_ = n;
    return Status::ok();
  }
  void reset() {
    if (p_ != nullptr) cudaFreeAsync(p_, stream_);
    p_ = nullptr;
    n_ = 0;
  }
  T* get() const { return p_; }
  std::size_t size() const { return n_; }

 private:
  T* p_ = nullptr;
  std::size_t n_ = 0;
  cudaStream_t stream_ = nullptr;
};

// Threads per block of the element-wise kernels.
constexpr int kThreads = 256;

inline unsigned grid_for(Index n, int threads = kThreads) {
  return static_cast<unsigned>((n + threads - 1) / threads);
}

namespace detail {
// Fixed decomposition of the deterministic sum: kSumBlocks blocks of kThreads threads, each
// thread summing a fixed strided subset, then a fixed tree in shared memory; a second launch
// sums the kSumBlocks partials the same way. The order depends on n only.
constexpr int kSumBlocks = 256;

template <class T>
__device__ inline T block_tree_sum(T v, T* shared) {
  shared[threadIdx.x] = v;
  __syncthreads();
  for (int s = blockDim.x / 2; s > 0; s >>= 1) {
    if (static_cast<int>(threadIdx.x) < s) shared[threadIdx.x] += shared[threadIdx.x + s];
    __syncthreads();
  }
  return shared[0];
}

template <class In, class T>
__global__ void sum_partials_kernel(const In* in, Index n, T* partial) {
  __shared__ T shared[kThreads];
  T v(0);
  for (Index k = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x; k < n;
       k += static_cast<Index>(gridDim.x) * blockDim.x)
    v += static_cast<T>(in[k]);
  const T s = block_tree_sum(v, shared);
  if (threadIdx.x == 0) partial[blockIdx.x] = s;
}

template <class T>
__global__ void sum_final_kernel(const T* partial, int n, T scale, T* out, bool accumulate) {
  __shared__ T shared[kThreads];
  T v(0);
  for (int k = threadIdx.x; k < n; k += blockDim.x) v += partial[k];
  const T s = block_tree_sum(v, shared) * scale;
  if (threadIdx.x == 0) *out = accumulate ? *out + s : s;
}
}  // namespace detail

// *out = scale · Σ_k in[k] (or *out += … with accumulate), summed in T in a fixed order (the same
// bits on every run on a given device). `out` is device memory; nothing is synchronised.
template <class In, class T>
Status deterministic_sum(const In* in, Index n, T* out, cudaStream_t stream, T scale = T(1),
                         bool accumulate = false) {
  DeviceBuffer<T> partial;
  if (Status s = partial.allocate(detail::kSumBlocks, stream); !s) return s;
  detail::sum_partials_kernel<In, T><<<detail::kSumBlocks, kThreads, 0, stream>>>(in, n, partial.get());
  detail::sum_final_kernel<T><<<1, kThreads, 0, stream>>>(partial.get(), detail::kSumBlocks, scale, out,
                                                          accumulate);
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::deterministic_sum launch");
  return Status::ok();
}

// The in-edges of every node of a graph [N][K] (row i lists the out-edges i -> j): for node j,
// the slots e = i·K + k with indices(i, k) = j, in increasing e, at entries[offsets[j] ..
// offsets[j+1]). Kernels use it to gather, in a fixed order, what the edges into a node
// contribute to its gradient (instead of scattering with atomics). Build it once per graph.
struct ReverseGraph {
  DeviceBuffer<std::int32_t> offsets;  // [N + 1]
  DeviceBuffer<std::int64_t> entries;  // [number of valid entries]
  Index nodes = 0;
  Index k = 0;
};

// Builds the reverse adjacency from device indices [N][K] (int32 or int64): copies the indices
// to the host, counts and orders them there (deterministic), and uploads the result on `stream`
// (synchronises that stream once). Indices must be valid (validate_neighbors).
template <class I>
Status build_reverse_graph(const I* indices_device, Index nodes, Index k, cudaStream_t stream,
                           ReverseGraph& out) {
  out.nodes = nodes;
  out.k = k;
  std::vector<I> idx(static_cast<std::size_t>(nodes * k));
  if (!idx.empty()) {
    SMG_CUDA_TRY(cudaMemcpyAsync(idx.data(), indices_device, idx.size() * sizeof(I),
                                 cudaMemcpyDeviceToHost, stream),
                 "build_reverse_graph: copy of graph indices");
    SMG_CUDA_TRY(cudaStreamSynchronize(stream), "build_reverse_graph: synchronise");
  }
  std::vector<std::int32_t> offsets(static_cast<std::size_t>(nodes + 1), 0);
  for (const I j : idx)
    if (j >= 0 && j < nodes) ++offsets[static_cast<std::size_t>(j) + 1];
  for (Index j = 0; j < nodes; ++j)
    offsets[static_cast<std::size_t>(j + 1)] += offsets[static_cast<std::size_t>(j)];
  std::vector<std::int64_t> entries(static_cast<std::size_t>(offsets.back()));
  std::vector<std::int32_t> fill(offsets.begin(), offsets.end() - 1);
  for (std::size_t e = 0; e < idx.size(); ++e) {
    const I j = idx[e];
    if (j >= 0 && j < nodes) entries[static_cast<std::size_t>(fill[static_cast<std::size_t>(j)]++)] =
        static_cast<std::int64_t>(e);
  }
  if (Status s = out.offsets.allocate(offsets.size(), stream); !s) return s;
  if (Status s = out.entries.allocate(entries.size(), stream); !s) return s;
  SMG_CUDA_TRY(cudaMemcpyAsync(out.offsets.get(), offsets.data(),
                               offsets.size() * sizeof(std::int32_t), cudaMemcpyHostToDevice, stream),
               "build_reverse_graph: upload");
  if (!entries.empty())
    SMG_CUDA_TRY(cudaMemcpyAsync(out.entries.get(), entries.data(),
                                 entries.size() * sizeof(std::int64_t), cudaMemcpyHostToDevice,
                                 stream),
                 "build_reverse_graph: upload");
  // The host vectors die at return: wait for the uploads.
  SMG_CUDA_TRY(cudaStreamSynchronize(stream), "build_reverse_graph: synchronise");
  return Status::ok();
}

}  // namespace smg::cuda
