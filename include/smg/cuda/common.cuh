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
#include <mutex>
#include <string>
#include <type_traits>

#include "smg/core/status.hpp"
#include "smg/core/types.hpp"
#include "smg/energy/common.hpp"  // detail::scale_over_count, Normalization::mean

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

// Where smg's launchers take their scratch memory from. The default is stream-ordered
// allocation (cudaMallocFromPoolAsync / cudaFreeAsync on the launch stream, from a pool of smg's
// own that keeps freed memory for the next call; no device-wide synchronisation); a
// framework with its own caching allocator installs it with set_allocator (smg_torch installs
// PyTorch's, so that smg's scratch is reused from torch's cache). allocate returns nullptr on
// failure. Process-wide, like smg::set_executor; set it before launching, not during.
struct Allocator {
  void* (*allocate)(std::size_t bytes, cudaStream_t stream, void* context) = nullptr;
  void (*deallocate)(void* pointer, cudaStream_t stream, void* context) = nullptr;
  void* context = nullptr;
};

namespace detail {
// smg's own stream-ordered memory pool of the current device, created on first use with no
// release threshold: scratch freed at the end of one call is reused by the next instead of being
// returned to the driver at every synchronisation (what the device's default pool does, and
// which made a 400 MB scratch cost more than the kernels). The caller's default pool is left as
// it is.
inline cudaMemPool_t smg_pool() {
  constexpr int kMaxDevices = 64;
  static cudaMemPool_t pools[kMaxDevices] = {};
  static std::mutex mutex;
  int device = 0;
  if (cudaGetDevice(&device) != cudaSuccess || device < 0 || device >= kMaxDevices) return nullptr;
  std::lock_guard<std::mutex> lock(mutex);
  if (pools[device] == nullptr) {
    cudaMemPoolProps props{};
    props.allocType = cudaMemAllocationTypePinned;
    props.location.type = cudaMemLocationTypeDevice;
    props.location.id = device;
    cudaMemPool_t pool = nullptr;
    if (cudaMemPoolCreate(&pool, &props) != cudaSuccess) return nullptr;
    std::uint64_t keep = ~std::uint64_t(0);
    cudaMemPoolSetAttribute(pool, cudaMemPoolAttrReleaseThreshold, &keep);
    pools[device] = pool;
  }
  return pools[device];
}
inline void* default_allocate(std::size_t bytes, cudaStream_t stream, void*) {
  void* p = nullptr;
  const cudaMemPool_t pool = smg_pool();
  const cudaError_t e = pool != nullptr ? cudaMallocFromPoolAsync(&p, bytes, pool, stream)
                                        : cudaMallocAsync(&p, bytes, stream);
  return e == cudaSuccess ? p : nullptr;
}
inline void default_deallocate(void* p, cudaStream_t stream, void*) { cudaFreeAsync(p, stream); }
inline Allocator& allocator_slot() {
  static Allocator a{&default_allocate, &default_deallocate, nullptr};
  return a;
}
}  // namespace detail

// Installs `a` (an Allocator with null functions restores the default).
inline void set_allocator(const Allocator& a) {
  detail::allocator_slot() = a.allocate && a.deallocate
                                 ? a
                                 : Allocator{&detail::default_allocate, &detail::default_deallocate, nullptr};
}
inline const Allocator& current_allocator() { return detail::allocator_slot(); }

// Scratch device memory from the current Allocator, released on `stream` at scope exit.
template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept
      : p_(o.p_), n_(o.n_), stream_(o.stream_), alloc_(o.alloc_) {
    o.p_ = nullptr;
    o.n_ = 0;
  }
  ~DeviceBuffer() { reset(); }

  // (Re)allocates n elements on `stream` (contents undefined).
  Status allocate(std::size_t n, cudaStream_t stream) {
    reset();
    stream_ = stream;
    if (n == 0) return Status::ok();
    alloc_ = current_allocator();
    void* p = alloc_.allocate(n * sizeof(T), stream, alloc_.context);
    if (p == nullptr) {
      cudaGetLastError();  // clear a sticky-free allocation error
      return Status::error("smg::cuda: could not allocate " + std::to_string(n * sizeof(T)) +
                           " bytes of scratch device memory");
    }
    p_ = static_cast<T*>(p);
    n_ = n;
    return Status::ok();
  }
  void reset() {
    if (p_ != nullptr) alloc_.deallocate(p_, stream_, alloc_.context);
    p_ = nullptr;
    n_ = 0;
  }
  T* get() const { return p_; }
  std::size_t size() const { return n_; }

 private:
  T* p_ = nullptr;
  std::size_t n_ = 0;
  cudaStream_t stream_ = nullptr;
  Allocator alloc_;  // the one that allocated p_ frees it
};

// Threads per block of the element-wise kernels.
constexpr int kThreads = 256;

inline unsigned grid_for(Index n, int threads = kThreads) {
  return static_cast<unsigned>((n + threads - 1) / threads);
}

// Launch shape of the per-frame kernels: x over the items of one frame (nodes, or node-neighbour
// slots; 32-bit, see check_frame_items), y over the frames. Index arithmetic inside a frame then
// stays in 32 bits: a 64-bit division per thread costs more than the rest of a light kernel.
inline dim3 frame_grid(Index items_per_frame, Index frames) {
  return dim3(grid_for(items_per_frame),
              static_cast<unsigned>(frames < 65535 ? (frames > 0 ? frames : 1) : 65535));
}

// The item of this thread within its frame (-1 past the end).
__device__ inline int frame_item(Index items_per_frame) {
  const Index s = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  return s < items_per_frame ? static_cast<int>(s) : -1;
}

// Frames of this thread: t = blockIdx.y, blockIdx.y + gridDim.y, ... (more than 65535 frames).
#define SMG_CUDA_FOR_FRAMES(t, frames) \
  for (::smg::Index t = blockIdx.y; t < (frames); t += gridDim.y)

// Items per frame must fit the 32-bit in-frame index.
inline Status check_frame_items(Index items_per_frame, const char* what) {
  if (items_per_frame < (Index(1) << 31)) return Status::ok();
  return Status::error(std::string(what) + ": " + std::to_string(items_per_frame) +
                       " items per frame exceed the CUDA kernels' 32-bit index (2^31 - 1)");
}

// Four scalars loaded and stored as one aligned vector (one 16-byte access for float).
template <class S>
struct alignas(4 * sizeof(S)) Vec4 {
  S x, y, z, w;
};

namespace detail {
// Normalization::mean's factor over a count in device memory: the CPU's formula (energy/common.hpp).
using smg::detail::scale_over_count;

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
__global__ void sum_final_kernel(const T* partial, int n, double scale, T* out, bool accumulate,
                                 const std::int32_t* count, Index count_factor) {
  __shared__ T shared[kThreads];
  T v(0);
  for (int k = threadIdx.x; k < n; k += blockDim.x) v += partial[k];
  if (count != nullptr) scale = scale_over_count(scale, count_factor, count);  // the mean
  const T s = block_tree_sum(v, shared) * static_cast<T>(scale);
  if (threadIdx.x == 0) *out = accumulate ? *out + s : s;
}
}  // namespace detail

// *out = scale · Σ_k in[k] (or *out += … with accumulate), summed in T in a fixed order (the same
// bits on every run on a given device). `out` is device memory; nothing is synchronised. With
// `count` (device memory), scale becomes scale / (count_factor · *count): a mean over a number of
// terms known only on the device (0 when there are none).
template <class In, class T>
Status deterministic_sum(const In* in, Index n, T* out, cudaStream_t stream, T scale = T(1),
                         bool accumulate = false, const std::int32_t* count = nullptr,
                         Index count_factor = 1) {
  DeviceBuffer<T> partial;
  if (Status s = partial.allocate(detail::kSumBlocks, stream); !s) return s;
  detail::sum_partials_kernel<In, T><<<detail::kSumBlocks, kThreads, 0, stream>>>(in, n, partial.get());
  detail::sum_final_kernel<T><<<1, kThreads, 0, stream>>>(partial.get(), detail::kSumBlocks,
                                                          static_cast<double>(scale), out,
                                                          accumulate, count, count_factor);
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::deterministic_sum launch");
  return Status::ok();
}

// The in-edges of the targets of an index table [rows][width] whose entries index `nodes`
// targets: for target j, the slots e = r·width + c with table(r, c) = j, in increasing e, at
// entries[offsets[j] .. offsets[j+1]); entries outside [0, nodes) (−1 padding) are not edges.
// For a graph [N][K] (row i lists the out-edges i -> j; rows = nodes = N, width = K) these are
// the in-edges of every node (build_reverse_graph); for a driver table [P][D] the (point, driver)
// edges of every node (build_driver_incidence, cuda/dqb.cuh). Kernels use it to gather, in a
// fixed order, what the edges into a target contribute to its gradient (instead of scattering
// with float atomics). offsets[nodes] is the number of edges (for a graph Σ_i |N(i)|, edge_count
// of the CPU side), kept on the device.
struct ReverseGraph {
  DeviceBuffer<std::int32_t> offsets;  // [nodes + 1]
  DeviceBuffer<std::int64_t> entries;  // [rows·width] (at least 1), the first offsets[nodes] used
  Index nodes = 0;                     // targets
  Index k = 0;                         // width of the table (K of a graph, D of a driver table)
  const std::int32_t* edge_count() const { return offsets.get() + nodes; }
};

namespace detail {
// The per-element steps of build_in_edges (host-device: the kernels below are thin wrappers, and
// tests/cuda/test_cuda_host_steps.cu runs the steps in host loops without a GPU).

// counter += 1, returning the old value: an integer atomic on the device (the order of the
// increments does not matter to the result: the counts are sums, and each node's entries are
// sorted afterwards); a plain increment on the host, where the steps run one at a time.
SMG_HOST_DEVICE inline std::int32_t in_edges_increment(std::int32_t* counter) {
#if defined(__CUDA_ARCH__)
  return atomicAdd(counter, 1);
#else
  return (*counter)++;
#endif
}

// The target of slot e of the table, or −1 when the entry is no edge (outside [0, nodes)).
template <class I>
SMG_HOST_DEVICE inline Index in_edge_target(const I* table, Index e, Index nodes) {
  const I j = table[e];
  return j >= 0 && static_cast<Index>(j) < nodes ? static_cast<Index>(j) : Index(-1);
}

// Count step of slot e: counts[j] += 1 for its target j.
template <class I>
SMG_HOST_DEVICE inline void in_edges_count_at(Index e, const I* table, Index nodes,
                                              std::int32_t* counts) {
  const Index j = in_edge_target(table, e, nodes);
  if (j >= 0) in_edges_increment(counts + j);
}

// The scan splits the targets into `threads` fixed, contiguous chunks: chunk of `thread`.
SMG_HOST_DEVICE inline void in_edges_chunk(int thread, int threads, Index nodes, Index& begin,
                                           Index& end) {
  const Index per = (nodes + threads - 1) / threads;
  begin = thread * per;
  end = begin + per < nodes ? begin + per : nodes;
  if (begin > end) begin = end;
}

// Scan step 1 of `thread`: the sum of the counts of its chunk.
SMG_HOST_DEVICE inline std::int32_t in_edges_chunk_sum(int thread, int threads,
                                                       const std::int32_t* counts, Index nodes) {
  Index b, e;
  in_edges_chunk(thread, threads, nodes, b, e);
  std::int32_t sum = 0;
  for (Index j = b; j < e; ++j) sum += counts[j];
  return sum;
}

// Scan step 2 of `thread`, given `start` (the sum of the chunks before it): the offsets of its
// chunk, offsets[j] = start + Σ counts of the chunk before j.
SMG_HOST_DEVICE inline void in_edges_chunk_offsets(int thread, int threads,
                                                   const std::int32_t* counts, Index nodes,
                                                   std::int32_t start, std::int32_t* offsets) {
  Index b, e;
  in_edges_chunk(thread, threads, nodes, b, e);
  for (Index j = b; j < e; ++j) {
    offsets[j] = start;
    start += counts[j];
  }
}

// Fill step of slot e: entries[cursor[j]++] = e for its target j (cursor starts as a copy of
// the offsets; the position within j depends on the order of the steps).
template <class I>
SMG_HOST_DEVICE inline void in_edges_fill_at(Index e, const I* table, Index nodes,
                                             std::int32_t* cursor, std::int64_t* entries) {
  const Index j = in_edge_target(table, e, nodes);
  if (j >= 0) entries[in_edges_increment(cursor + j)] = e;
}

// Sort step of target j: its few entries in increasing slot order (insertion sort), so that the
// result does not depend on the order of the fill steps and the gathers sum in the CPU's order.
SMG_HOST_DEVICE inline void in_edges_sort_at(Index j, const std::int32_t* offsets,
                                             std::int64_t* entries) {
  for (std::int32_t a = offsets[j] + 1; a < offsets[j + 1]; ++a) {
    const std::int64_t v = entries[a];
    std::int32_t b = a;
    for (; b > offsets[j] && entries[b - 1] > v; --b) entries[b] = entries[b - 1];
    entries[b] = v;
  }
}

template <class I>
__global__ void in_edges_count_kernel(const I* table, Index slots, Index nodes,
                                      std::int32_t* counts) {
  const Index e = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (e < slots) in_edges_count_at(e, table, nodes, counts);
}

// offsets[0] = 0, offsets[j + 1] = offsets[j] + counts[j]: one block, a fixed sequential scan
// of per-thread chunk sums (the targets are at most a few million; this is not the hot path). A
// template only so that a header can define it (a __global__ function cannot be inline).
template <int = 0>
__global__ void in_edges_scan_kernel(const std::int32_t* counts, Index nodes,
                                     std::int32_t* offsets) {
  __shared__ std::int32_t part[kThreads];
  const int t = static_cast<int>(threadIdx.x);
  part[t] = in_edges_chunk_sum(t, kThreads, counts, nodes);
  __syncthreads();
  if (t == 0) {
    std::int32_t run = 0;
    for (int u = 0; u < kThreads; ++u) {
      const std::int32_t v = part[u];
      part[u] = run;
      run += v;
    }
    offsets[nodes] = run;
  }
  __syncthreads();
  in_edges_chunk_offsets(t, kThreads, counts, nodes, part[t], offsets);
}

template <class I>
__global__ void in_edges_fill_kernel(const I* table, Index slots, Index nodes,
                                     std::int32_t* cursor, std::int64_t* entries) {
  const Index e = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (e < slots) in_edges_fill_at(e, table, nodes, cursor, entries);
}

template <int = 0>
__global__ void in_edges_sort_kernel(const std::int32_t* offsets, Index nodes,
                                     std::int64_t* entries) {
  const Index j = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (j < nodes) in_edges_sort_at(j, offsets, entries);
}

// The in-edges of a device table [rows][width] (int32 or int64) over `nodes` targets into `out`
// (the struct's comment), on `stream`, entirely on the device: count (integer atomics), one-block
// scan, fill, per-target sort. Nothing is read back or synchronised. `what` names the caller in
// messages. rows·width must fit the 32-bit offsets (checked on the host).
template <class I>
Status build_in_edges(const I* table_device, Index rows, Index width, Index nodes,
                      cudaStream_t stream, ReverseGraph& out, const char* what) {
  out.nodes = nodes;
  out.k = width;
  if (rows < 0 || width < 0 || nodes < 0)
    return Status::error(std::string(what) + ": negative size");
  const Index slots = rows * width;
  if (slots >= (Index(1) << 31))
    return Status::error(std::string(what) + ": " + std::to_string(slots) +
                         " table entries exceed the 32-bit offsets (2^31 - 1)");
  if (slots > 0 && table_device == nullptr)
    return Status::error(std::string(what) + ": null data pointer");
  DeviceBuffer<std::int32_t> counts;
  if (Status s = out.offsets.allocate(static_cast<std::size_t>(nodes + 1), stream); !s) return s;
  if (Status s = out.entries.allocate(static_cast<std::size_t>(slots > 0 ? slots : 1), stream); !s)
    return s;
  if (Status s = counts.allocate(static_cast<std::size_t>(nodes + 1), stream); !s) return s;
  SMG_CUDA_TRY(cudaMemsetAsync(counts.get(), 0, sizeof(std::int32_t) * (nodes + 1), stream), what);
  if (slots > 0)
    in_edges_count_kernel<I><<<grid_for(slots), kThreads, 0, stream>>>(table_device, slots, nodes,
                                                                      counts.get());
  in_edges_scan_kernel<><<<1, kThreads, 0, stream>>>(counts.get(), nodes, out.offsets.get());
  // counts becomes the fill cursor: a copy of the offsets.
  SMG_CUDA_TRY(cudaMemcpyAsync(counts.get(), out.offsets.get(), sizeof(std::int32_t) * (nodes + 1),
                               cudaMemcpyDeviceToDevice, stream),
               what);
  if (slots > 0) {
    in_edges_fill_kernel<I><<<grid_for(slots), kThreads, 0, stream>>>(
        table_device, slots, nodes, counts.get(), out.entries.get());
    if (nodes > 0)
      in_edges_sort_kernel<><<<grid_for(nodes), kThreads, 0, stream>>>(out.offsets.get(), nodes,
                                                                       out.entries.get());
  }
  SMG_CUDA_TRY(cudaGetLastError(), (std::string(what) + " launch").c_str());
  return Status::ok();
}
}  // namespace detail

// Builds the reverse adjacency of device indices [N][K] (int32 or int64) on `stream`, entirely
// on the device (no synchronisation): detail::build_in_edges with rows = nodes = N. Indices must
// be -1 or in [0, N) (validate_neighbors); others are skipped. Build it once per graph and pass
// it to every energy over that graph.
template <class I>
Status build_reverse_graph(const I* indices_device, Index nodes, Index k, cudaStream_t stream,
                           ReverseGraph& out) {
  return detail::build_in_edges(indices_device, nodes, k, nodes, stream, out,
                                "build_reverse_graph");
}

}  // namespace smg::cuda
