// smg/cuda/point_knn.cuh — the exact point KNN (docs/math/graph.md (G15)) on the GPU: every
// query scans every point, in tiles staged through shared memory, and keeps its row with the
// CPU search's own steps (graph/point_knn_element.hpp: point_distance2, point_knn_insert), so
// the rows equal the CPU's (point_knn, point_knn_brute_force) bit for bit, ties by index, for
// any launch shape. O(N²) work: meant for the tables a trainer builds once (or now and then) at
// the field's sizes (10⁴–10⁵ points), where the scan runs at the device's arithmetic rate; a
// grid or tree search is the step beyond it.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <type_traits>

#include "smg/core/status.hpp"
#include "smg/core/views.hpp"
#include "smg/cuda/common.cuh"
#include "smg/graph/point_knn_element.hpp"

namespace smg::cuda {

namespace detail {

// Points per shared-memory tile (3 values each) of the scan.
constexpr int kPointKnnTile = 256;

// Scans `count` points, xyz-interleaved at `tile`, whose indices are first, first + 1, ... into
// query i's row (dist/idx, `found` entries, at most k; (G15)): skips i itself unless include_self.
// The whole search of one query is this over [0, N) in any split into tiles: the host test calls
// it once over every point.
template <class S, class I>
SMG_HOST_DEVICE inline void point_knn_scan(const S* tile, Index count, Index first, const S* q, Index i,
                                           bool include_self, S r2, int k, int& found, S* dist, I* idx) {
  for (Index m = 0; m < count; ++m) {
    const Index j = first + m;
    if (!include_self && j == i) continue;
    point_knn_insert(point_distance2(tile + 3 * m, q), static_cast<I>(j), r2, k, found, dist, idx);
  }
}

// One thread per query. KMax > 0: the row lives in the thread's local array and is written once
// at the end; KMax = 0 (k > 32): the row is kept in place in the output.
template <class S, class I, int KMax>
__global__ void point_knn_kernel(const S* points, Index N, int k, S r2, bool include_self, I* indices,
                                 S* distances2) {
  __shared__ S tile[3 * kPointKnnTile];
  const Index i = Index(blockIdx.x) * blockDim.x + threadIdx.x;
  const bool active = i < N;
  S q[3] = {S(0), S(0), S(0)};
  if (active)
    for (int c = 0; c < 3; ++c) q[c] = points[3 * i + c];
  S local_d[KMax > 0 ? KMax : 1];
  I local_i[KMax > 0 ? KMax : 1];
  S* dist = KMax > 0 ? local_d : (active ? distances2 + i * k : nullptr);
  I* idx = KMax > 0 ? local_i : (active ? indices + i * k : nullptr);
  int found = 0;
  for (Index first = 0; first < N; first += kPointKnnTile) {
    const Index count = N - first < kPointKnnTile ? N - first : kPointKnnTile;
    __syncthreads();
    for (Index v = threadIdx.x; v < 3 * count; v += blockDim.x) tile[v] = points[3 * first + v];
    __syncthreads();
    if (active) point_knn_scan(tile, count, first, q, i, include_self, r2, k, found, dist, idx);
  }
  if (!active) return;
  point_knn_pad(k, found, dist, idx);
  if (KMax > 0)
    for (int c = 0; c < k; ++c) {
      distances2[i * k + c] = dist[c];
      indices[i * k + c] = idx[c];
    }
}

}  // namespace detail

// point_knn (G15) on device memory: points [N][3] (finite: not checked here, the array is on the
// device; smg_torch checks it with one reduction first), rows of k by (d², j) within `radius`
// (d² <= r², r² rounded to S), j = i only when include_self, into indices [N][k] (int32 or
// int64) and distances2 [N][k], padded −1 / +inf. Queued on `stream`; arguments checked on the
// host first (the messages of validate_point_knn).
template <class S, class I>
Status point_knn(smg::detail::NonDeducedT<TableView<const S, 3>> points, int k, double radius, bool include_self,
                 TableView<I, Eigen::Dynamic> indices, TableView<S, Eigen::Dynamic> distances2,
                 cudaStream_t stream) {
  const Index N = points.rows();
  if (Status s = smg::detail::check_point_knn_arguments<S, I>(N, k, radius, points.data(), indices, distances2); !s)
    return s;
  if (N == 0) return Status::ok();
  const S r2 = smg::detail::point_knn_radius2<S>(radius);
  const unsigned blocks = grid_for(N);
  auto launch = [&](auto kmax) {
    detail::point_knn_kernel<S, I, decltype(kmax)::value><<<blocks, kThreads, 0, stream>>>(
        points.data(), N, k, r2, include_self, indices.data(), distances2.data());
  };
  if (k <= 8)
    launch(std::integral_constant<int, 8>());
  else if (k <= 16)
    launch(std::integral_constant<int, 16>());
  else if (k <= 32)
    launch(std::integral_constant<int, 32>());
  else
    launch(std::integral_constant<int, 0>());
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::point_knn launch");
  return Status::ok();
}

}  // namespace smg::cuda
