// smg/cuda/validate.cuh — the CPU validators (validate_confidence, validate_carap, validate_arap,
// validate_lrm) for inputs in device memory: the arrays are copied to the host once and checked
// there, so that the messages are exactly the CPU's. The launchers themselves check shapes and
// options only (they never read device data, so that a launch stays asynchronous); run these on
// untrusted data first, once per new input, not in a training loop.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <vector>

#include "smg/cuda/common.cuh"
#include "smg/energy/validate.hpp"  // the CPU checks, free of the CPU thread pool

namespace smg::cuda {

namespace detail {
// A host copy of n elements at a device pointer (empty for null); synchronises the stream.
template <class T>
Status host_copy(const T* device, Index n, cudaStream_t stream, std::vector<T>& out) {
  out.clear();
  if (device == nullptr || n <= 0) return Status::ok();
  out.resize(static_cast<std::size_t>(n));
  SMG_CUDA_TRY(cudaMemcpyAsync(out.data(), device, static_cast<std::size_t>(n) * sizeof(T),
                               cudaMemcpyDeviceToHost, stream),
               "smg::cuda validation: copy to host");
  SMG_CUDA_TRY(cudaStreamSynchronize(stream), "smg::cuda validation: synchronise");
  return Status::ok();
}

// The same views over host copies of what device views show.
template <class S, class I>
struct HostInputs {
  std::vector<S> x, q, c, w;
  std::vector<I> idx;
  std::vector<std::uint8_t> vis;
  Status copy(PositionsView<const S> positions, QuaternionsView<const S> rotations,
              FrameScalarsView<const S> confidence, VisibilityView<const std::uint8_t> visibility,
              const NeighborsView<S, I>& graph, cudaStream_t stream) {
    for (Status s : {host_copy(positions.data(), positions.size(), stream, x),
                     host_copy(rotations.data(), rotations.size(), stream, q),
                     host_copy(confidence.data(), confidence.size(), stream, c),
                     host_copy(visibility.data(), visibility.size(), stream, vis),
                     host_copy(graph.indices.data(), graph.indices.size(), stream, idx),
                     host_copy(graph.weights.data(), graph.weights.size(), stream, w)})
      if (!s) return s;
    return Status::ok();
  }
  template <class V, class T>
  static V like(const V& device_view, const std::vector<T>& host) {
    if (device_view.data() == nullptr) return V();
    return V(host.data(), device_view.frames(), device_view.nodes());
  }
  NeighborsView<S, I> graph(const NeighborsView<S, I>& g) const {
    return NeighborsView<S, I>(idx.data(), w.data(), g.indices.rows(), g.indices.cols());
  }
};
}  // namespace detail

// validate_confidence on device inputs (outputs: shapes only).
template <class S, class I>
Status validate_confidence(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                           VisibilityView<const std::uint8_t> visibility,
                           const NeighborsView<S, I>& graph, const ConfidenceOptions& options,
                           smg::detail::NonDeducedT<FrameScalarsView<S>> confidence, cudaStream_t stream = nullptr) {
  detail::HostInputs<S, I> h;
  if (Status s = h.copy(positions, {}, {}, visibility, graph, stream); !s) return s;
  return smg::validate_confidence<S, I>(h.like(positions, h.x), h.like(visibility, h.vis),
                                        h.graph(graph), options, confidence);
}

// validate_carap on device inputs (gradient outputs: shapes only).
template <class S, class I>
Status validate_carap(smg::detail::NonDeducedT<PositionsView<const S>> positions, smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
                      smg::detail::NonDeducedT<FrameScalarsView<const S>> confidence, const NeighborsView<S, I>& graph,
                      const CarapOptions& options, smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {},
                      smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                      cudaStream_t stream = nullptr) {
  detail::HostInputs<S, I> h;
  if (Status s = h.copy(positions, rotations, confidence, {}, graph, stream); !s) return s;
  return smg::validate_carap<S, I>(h.like(positions, h.x), h.like(rotations, h.q),
                                   h.like(confidence, h.c), h.graph(graph), options,
                                   grad_positions, grad_rotations);
}

// validate_arap on device inputs.
template <class S, class I>
Status validate_arap(smg::detail::NonDeducedT<PositionsView<const S>> positions, smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
                     const NeighborsView<S, I>& graph, const ArapOptions& options,
                     smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {},
                     smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                     cudaStream_t stream = nullptr) {
  detail::HostInputs<S, I> h;
  if (Status s = h.copy(positions, rotations, {}, {}, graph, stream); !s) return s;
  return smg::validate_arap<S, I>(h.like(positions, h.x), h.like(rotations, h.q), h.graph(graph),
                                  options, grad_positions, grad_rotations);
}

// validate_lrm on device inputs.
template <class S, class I>
Status validate_lrm(smg::detail::NonDeducedT<PositionsView<const S>> positions, smg::detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                    const NeighborsView<S, I>& graph, const LrmOptions& options,
                    smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {}, TangentsView<S> omega = {},
                    cudaStream_t stream = nullptr) {
  detail::HostInputs<S, I> h;
  if (Status s = h.copy(positions, {}, confidence, {}, graph, stream); !s) return s;
  return smg::validate_lrm<S, I>(h.like(positions, h.x), h.like(confidence, h.c), h.graph(graph),
                                 options, grad_positions, omega);
}

}  // namespace smg::cuda
