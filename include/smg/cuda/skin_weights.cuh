// smg/cuda/skin_weights.cuh — the driver table (S1) and the distance-aware skinning weights
// (S2)-(S4) of many points on the GPU: the same results as the CPU smg::skin_drivers
// (smg/skin/drivers.hpp) and smg::skinning_weights (smg/skin/weights.hpp), computed by the same
// host-device per-point functions (skin_drivers_row, detail::skinning_weights_row): one thread
// per point, no atomics. The driver table is identical bit for bit; the weights differ from the
// CPU's only by the device's rounding (FMA contraction, exp).
#pragma once

#include "smg/cuda/common.cuh"

#include <cstdint>
#include <sstream>
#include <string>

#include "smg/core/validate.hpp"
#include "smg/cuda/dqb.cuh"
#include "smg/graph/neighbors.hpp"
#include "smg/skin/skin_views.hpp"
#include "smg/skin/weights_element.hpp"

namespace smg::cuda {

namespace detail {

template <class S, class I>
__global__ void skin_drivers_kernel(NeighborsView<S, I> graph, SkinIndexView anchor,
                                    TableView<std::int32_t, Eigen::Dynamic> out) {
  const Index p = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (p < anchor.rows()) skin_drivers_row(graph, anchor(p, 0), out.ptr(p));
}

template <class S, int DMax>
__global__ void skinning_weights_kernel(PositionsView<const S> positions, SkinDriversView drivers,
                                        SkinIndexView t_ref, TableView<const S, 3> points,
                                        TableView<const S, 1> sigma,
                                        TableView<S, Eigen::Dynamic> weights_out) {
  const Index p = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (p >= drivers.rows()) return;
  Vector3<S> x[DMax];
  S sg[DMax];
  smg::detail::skinning_weights_row<S>(positions, drivers, t_ref, points, sigma, weights_out, p, x,
                                       sg);
}

}  // namespace detail

// out[p] = (anchor[p], the valid neighbours of anchor[p] in graph order, −1 padding), D = K + 1
// columns: smg::skin_drivers on the GPU (identical table). graph ([N][K] int32 or int64 indices;
// its weights are not read), anchor [P] (int32) and out [P][K + 1] (int32) are over DEVICE
// memory. Shapes are checked on the host; the contents (graph indices −1 or in [0, N) with
// padding trailing, anchor in [0, N): validate_skin_drivers on the CPU) are the caller's
// precondition. Stream-ordered, nothing synchronised.
template <class S, class I>
Status skin_drivers(const NeighborsView<S, I>& graph, SkinIndexView anchor,
                    TableView<std::int32_t, Eigen::Dynamic> out, cudaStream_t stream) {
  const Index N = graph.nodes(), K = graph.k(), P = anchor.rows();
  if (graph.indices.rows() != N || K < 0) {
    std::ostringstream s;
    s << "graph: expected indices of shape [N][K], got [" << graph.indices.rows() << "][" << K
      << "]";
    return Status::error(s.str());
  }
  if (N * K > 0 && graph.indices.data() == nullptr)
    return Status::error("graph: null data pointer for a non-empty array");
  if (P > 0 && anchor.data() == nullptr) return Status::error("anchor: null data pointer");
  if (P > 0 && N == 0) return Status::error("anchor: points need at least one node (N=0)");
  const std::string shape = "[P=" + std::to_string(P) + "][K+1=" + std::to_string(K + 1) + "]";
  if (Status s = detail::table_shape(out.rows(), out.cols(), P, K + 1, out.data(), "drivers", shape);
      !s)
    return s;
  if (P == 0) return Status::ok();
  detail::skin_drivers_kernel<S, I><<<grid_for(P), kThreads, 0, stream>>>(graph, anchor, out);
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::skin_drivers: kernel launch");
  return Status::ok();
}

// weights_out[p][k] = w_pk (S2)-(S4), 0 on padding: smg::skinning_weights on the GPU. positions
// [T][N][3], drivers [P][D] (int32, −1 padded, D <= kSkinMaxD), t_ref [P] (int32), points [P][3],
// sigma [N] and weights_out [P][D] are over DEVICE memory. Shapes are checked on the host; the
// contents (validate_skinning_weights on the CPU: finite values, drivers in [−1, N) with entry 0
// valid, t_ref in [0, T), sigma > 0) are the caller's precondition. The number of fallback
// points (the CPU function's return value) is not counted. Stream-ordered, nothing
// synchronised; deterministic.
template <class S>
Status skinning_weights(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                        SkinDriversView drivers, SkinIndexView t_ref,
                        smg::detail::NonDeducedT<TableView<const S, 3>> points,
                        smg::detail::NonDeducedT<TableView<const S, 1>> sigma,
                        TableView<S, Eigen::Dynamic> weights_out, cudaStream_t stream) {
  const Index T = positions.frames(), N = positions.nodes(), P = drivers.rows(),
              D = drivers.cols();
  if (Status s = smg::detail::check_shape("positions", positions.data(), T, N, positions.dim(), -1,
                                          -1, 3, "T", "N");
      !s)
    return s;
  if (Status s = detail::check_driver_table(drivers, P); !s) return s;
  if (Status s = detail::check_t_ref(t_ref, P); !s) return s;
  const std::string ps = std::to_string(P), ns = std::to_string(N), ds = std::to_string(D);
  if (Status s = detail::table_shape(points.rows(), points.cols(), P, 3, points.data(), "points",
                                     "[P=" + ps + "][3]");
      !s)
    return s;
  if (Status s = detail::table_shape(sigma.rows(), sigma.cols(), N, 1, sigma.data(), "sigma",
                                     "[N=" + ns + "][1]");
      !s)
    return s;
  if (Status s = detail::table_shape(weights_out.rows(), weights_out.cols(), P, D,
                                     weights_out.data(), "weights", "[P=" + ps + "][D=" + ds + "]");
      !s)
    return s;
  if (P == 0) return Status::ok();
  const unsigned grid = grid_for(P);
  if (D <= 8)
    detail::skinning_weights_kernel<S, 8><<<grid, kThreads, 0, stream>>>(positions, drivers, t_ref,
                                                                         points, sigma, weights_out);
  else if (D <= 16)
    detail::skinning_weights_kernel<S, 16><<<grid, kThreads, 0, stream>>>(
        positions, drivers, t_ref, points, sigma, weights_out);
  else
    detail::skinning_weights_kernel<S, 32><<<grid, kThreads, 0, stream>>>(
        positions, drivers, t_ref, points, sigma, weights_out);
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::skinning_weights: kernel launch");
  return Status::ok();
}

}  // namespace smg::cuda
