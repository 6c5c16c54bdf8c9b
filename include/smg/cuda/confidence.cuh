// smg/cuda/confidence.cuh — node confidences c_{t,i} on the GPU (docs/math/energy.md (E1)-(E6)):
// the same per-element functions as the CPU node_confidences (smg/energy/confidence.hpp), one
// thread per node and frame.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/cuda/common.cuh"
#include "smg/core/views.hpp"
#include "smg/energy/elements/confidence.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg::cuda {

namespace detail {
// Element (l, i) of the frames c0 … (all of them: c0 = 0, or one chunk of the fused step,
// cuda/regularizers.cuh): the velocity u_i^{c0+l} (E1) into u [frames][N][3] and the edge change
// e_i^{c0+l} (E4) into e [frames][N].
template <class S, class I>
SMG_HOST_DEVICE inline void confidence_inputs_at(Index l, Index i, Index c0, PositionsView<const S> x,
                                                 const NeighborsView<S, I>& graph, const S* inv_w,
                                                 S* u, S* e) {
  const Index T = x.frames(), N = x.nodes(), t = c0 + l;
  const VelocityFrames f = velocity_frames(t, T);  // (E1)
  S* out = u + (l * N + i) * 3;
  for (int c = 0; c < 3; ++c) out[c] = f.moving ? S(x.ptr(f.plus, i)[c] - x.ptr(f.minus, i)[c]) : S(0);
  e[l * N + i] = confidence_edge_change(x, graph, inv_w[i], t, i);  // (E4)
}

// Element (l, i): c_{c0+l, i} (E2)-(E6) into conf [T][N] from confidence_inputs_at's u and e,
// and c^m, c^r into motion and rigidity [T][N] when they are not null; visibility [T][N] (0/1)
// or null (all visible).
template <class S, class I>
SMG_HOST_DEVICE inline void confidence_at(Index l, Index i, Index c0,
                                          const NeighborsView<S, I>& graph, const S* inv_w,
                                          const S* u, const S* e, const ConfidenceConstants<S>& p,
                                          const std::uint8_t* visibility, S* conf, S* motion,
                                          S* rigidity) {
  const Index item = (c0 + l) * graph.nodes() + i;
  S m(0), r(0);
  const S c = confidence_node(u, e, graph, inv_w[i], l, i, p, motion ? &m : nullptr,
                              rigidity ? &r : nullptr);  // (E2)-(E5)
  if (motion) motion[item] = m;
  if (rigidity) rigidity[item] = r;
  if (conf) conf[item] = (visibility == nullptr || visibility[item] ? S(1) : S(0)) * c;  // (E6)
}

template <class S, class I>
__global__ void inverse_row_weight_kernel(NeighborsView<S, I> graph, S* inv_w) {
  const int i = frame_item(graph.nodes());
  if (i < 0) return;
  inv_w[i] = inverse_row_weight(graph, i);
}

template <class S, class I>
__global__ void confidence_inputs_kernel(Index c0, Index frames, PositionsView<const S> x,
                                         NeighborsView<S, I> graph, const S* inv_w, S* u, S* e) {
  const int i = frame_item(x.nodes());
  if (i < 0) return;
  SMG_CUDA_FOR_FRAMES(l, frames) confidence_inputs_at(l, Index(i), c0, x, graph, inv_w, u, e);
}

template <class S, class I>
__global__ void confidence_kernel(Index c0, Index frames, NeighborsView<S, I> graph,
                                  const S* inv_w, const S* u, const S* e, ConfidenceConstants<S> p,
                                  const std::uint8_t* visibility, S* conf, S* motion,
                                  S* rigidity) {
  const int i = frame_item(graph.nodes());
  if (i < 0) return;
  SMG_CUDA_FOR_FRAMES(l, frames)
  confidence_at(l, Index(i), c0, graph, inv_w, u, e, p, visibility, conf, motion, rigidity);
}
}  // namespace detail

// node_confidences on device memory: writes c (E6) into `confidence` [T][N] and, when given, c^m
// into `motion` and c^r into `rigidity` (empty views: not computed); visibility [T][N] may be
// empty (all visible). Every view is over device memory; the work is queued on `stream` (no
// synchronisation). Shapes and options are checked on the host before launch (the messages of
// validate_confidence); the array contents are not read here: run cuda::validate_... on
// untrusted data first (smg::cuda::validate_confidence, smg/cuda/validate.cuh). Results equal the CPU function's to round-off.
template <class S, class I>
Status node_confidences(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                        VisibilityView<const std::uint8_t> visibility,
                        const NeighborsView<S, I>& graph, const ConfidenceOptions& options,
                        smg::detail::NonDeducedT<FrameScalarsView<S>> confidence, smg::detail::NonDeducedT<FrameScalarsView<S>> motion,
                        smg::detail::NonDeducedT<FrameScalarsView<S>> rigidity, cudaStream_t stream) {
  const Index T = positions.frames(), N = positions.nodes();
  if (Status s = validate_options(options); !s) return s;
  auto shape_ok = [&](Index t, Index n) { return t == T && n == N; };
  if (visibility.data() && !shape_ok(visibility.frames(), visibility.nodes()))
    return Status::error("visibility: expected shape [T][N] of positions");
  if (graph.nodes() != N || graph.weights.rows() != N || graph.weights.cols() != graph.k())
    return Status::error("graph: expected indices and weights of shape [N][K] with N of positions");
  if (confidence.data() && !shape_ok(confidence.frames(), confidence.nodes()))
    return Status::error("confidence: expected shape [T][N] of positions");
  if (motion.data() && !shape_ok(motion.frames(), motion.nodes()))
    return Status::error("motion: expected shape [T][N] of positions");
  if (rigidity.data() && !shape_ok(rigidity.frames(), rigidity.nodes()))
    return Status::error("rigidity: expected shape [T][N] of positions");
  if (T == 0 || N == 0) return Status::ok();
  if (Status s = check_frame_items(N, "positions"); !s) return s;
  DeviceBuffer<S> u, inv_w, e;
  if (Status s = u.allocate(static_cast<std::size_t>(T * N * 3), stream); !s) return s;
  if (Status s = inv_w.allocate(static_cast<std::size_t>(N), stream); !s) return s;
  if (Status s = e.allocate(static_cast<std::size_t>(T * N), stream); !s) return s;
  const dim3 grid = frame_grid(N, T);
  detail::inverse_row_weight_kernel<S, I><<<grid_for(N), kThreads, 0, stream>>>(graph, inv_w.get());
  detail::confidence_inputs_kernel<S, I><<<grid, kThreads, 0, stream>>>(0, T, positions, graph,
                                                                          inv_w.get(), u.get(), e.get());
  detail::confidence_kernel<S, I><<<grid, kThreads, 0, stream>>>(
      0, T, graph, inv_w.get(), u.get(), e.get(), ConfidenceConstants<S>(options),
      visibility.data(), confidence.data(), motion.data(), rigidity.data());
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::node_confidences launch");
  return Status::ok();
}

}  // namespace smg::cuda
