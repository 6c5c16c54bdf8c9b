// smg/cuda/regularizers.cuh — the fused regulariser step on the GPU: any subset of node
// confidences (E2)-(E6), C-ARAP (E7)-(E10), plain ARAP, LRM (E11)-(E16) and trajectory smoothness
// (E21) with the gradients, the same quantities, options and result struct as the CPU
// smg::regularizers() (smg/energy/regularizers.hpp; docs/math/energy.md "The fused regulariser
// pass"). The launcher checks the arguments on the host and runs the CUDA driver
// (cuda/driver.cuh: its phases, plan and per-element steps) with kernels on one stream;
// tests/cuda/test_cuda_regularizers.cu runs the same driver in host loops against the CPU on
// machines without a GPU.
#pragma once

#include "smg/cuda/common.cuh"

#include <algorithm>
#include <cstdint>
#include <sstream>
#include <string>
#include <utility>

#include "smg/core/rotation_gradient.hpp"
#include "smg/core/views.hpp"
#include "smg/cuda/driver.cuh"
#include "smg/cuda/lrm.cuh"
#include "smg/cuda/validate.cuh"
#include "smg/energy/block.hpp"
#include "smg/energy/term_list.hpp"  // RegularizerOptions
#include "smg/graph/neighbors.hpp"

namespace smg::cuda {

// The peak scratch bytes smg::cuda::regularizers allocates for these shapes, options and outputs
// (the energy partials, the [T][N] confidences unless the caller takes them, and the largest
// chunk's scratch); at most regularizer_input_bytes (the inputs' bytes) except where one frame's
// chunk alone exceeds what is left (short sequences). The ReverseGraph, built once per graph by
// the caller, is not counted.
template <class S, class I>
std::size_t regularizers_extra_bytes(Index frames, Index nodes, Index k,
                                     const RegularizerOptions& options, bool grad_positions,
                                     bool grad_rotations, bool rotations_given,
                                     bool visibility_given, bool confidence_out) {
  return detail::fused_plan<S, I>(frames, nodes, k, options, grad_positions, grad_rotations,
                                  rotations_given, visibility_given, confidence_out)
      .extra_bytes;
}

// Checks the shapes and options of smg::cuda::regularizers on the host (the views are over
// device memory: contents are not read; run validate_regularizers below on untrusted data
// first). Same messages as the CPU validate_regularizers for what it checks; in addition
// K <= kLrmMaxK with LRM on, a CUDA pass for every term that is on (check_cuda_terms) and a
// ReverseGraph built for this graph.
template <class S, class I>
Status validate_regularizers_shapes(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                                    smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
                                    VisibilityView<const std::uint8_t> visibility,
                                    const NeighborsView<S, I>& graph,
                                    const RegularizerOptions& options,
                                    const ReverseGraph& reverse,
                                    smg::detail::NonDeducedT<FrameScalarsView<S>> confidence = {},
                                    smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {},
                                    smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  const RegularizerTerms& on = options.terms;
  auto shape = [&](Index t, Index n, const char* name, const char* what) -> Status {
    if (t == T && n == N) return Status::ok();
    std::ostringstream s;
    s << name << ": expected shape [T=" << T << "][N=" << N << "]" << what << ", got [" << t
      << "][" << n << "]";
    return Status::error(s.str());
  };
  if (positions.size() > 0 && positions.data() == nullptr)
    return Status::error("positions: null data pointer for a non-empty array");
  if (reads_rotations(on) && !(rotations.data() == nullptr && T * N == 0))
    if (Status s = shape(rotations.frames(), rotations.nodes(), "rotations", "[4]"); !s) return s;
  if (visibility.data() != nullptr)
    if (Status s = shape(visibility.frames(), visibility.nodes(), "visibility", ""); !s) return s;
  if (Status s = smg::detail::check_neighbors_shape(graph, N, "graph"); !s) return s;
  if (on.lrm)
    if (Status s = detail::check_lrm_max_k(K); !s) return s;
  if (Status s = validate_options(options); !s) return s;
  if (Status s = detail::check_cuda_terms<S, I>(options); !s) return s;
  if (confidence.data() != nullptr) {
    if (!on.confidence)
      return Status::error(
          "confidence: smg::cuda::regularizers takes no caller's confidences (options.terms.confidence is "
          "off); compute them (terms.confidence) or call the CPU regularizers()");
    if (Status s = shape(confidence.frames(), confidence.nodes(), "confidence", ""); !s) return s;
  }
  if (grad_positions.data() != nullptr)
    if (Status s = shape(grad_positions.frames(), grad_positions.nodes(), "grad_positions", "[3]");
        !s)
      return s;
  if (!grad_rotations.empty())
    if (Status s = shape(grad_rotations.frames(), grad_rotations.nodes(), "grad_rotations",
                         grad_rotations.is_raw() ? "[4]" : "[3]");
        !s)
      return s;
  return detail::check_reverse_graph(reverse, N, K);
}

// The CPU validate_regularizers on device inputs (copied to the host once; synchronises
// `stream`): the same messages as the CPU. For untrusted data, once, not in a training loop.
template <class S, class I>
Status validate_regularizers(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                             smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
                             VisibilityView<const std::uint8_t> visibility,
                             const NeighborsView<S, I>& graph, const RegularizerOptions& options,
                             smg::detail::NonDeducedT<FrameScalarsView<S>> confidence = {},
                             smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {},
                             smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                             cudaStream_t stream = nullptr) {
  detail::HostInputs<S, I> h;
  if (Status s = h.copy(positions, rotations, {}, visibility, graph, stream); !s) return s;
  return smg::validate_regularizers<S, I>(h.like(positions, h.x), h.like(rotations, h.q),
                                          h.like(visibility, h.vis), h.graph(graph), options,
                                          confidence, grad_positions, grad_rotations);
}

// The fused regulariser step on the GPU: the same energies and gradients as the CPU
// smg::regularizers() with the same options (to rounding: sums are associated differently).
// Every view is over DEVICE memory:
//   positions [T][N][3]; rotations [T][N][4] (w, x, y, z; normalised on use), may be empty
//   without C-ARAP, ARAP and angle (reads_rotations); visibility [T][N] (0/1) or empty; graph indices [N][K] (int32 or
//   int64, −1 padded; K <= kLrmMaxK with LRM) and weights [N][K];
//   reverse: build_reverse_graph(graph.indices.data(), N, K, stream, reverse), once per graph;
//   result_device: one RegularizerResult<S> (energies in Accumulator<S>), overwritten;
//   confidence [T][N]: receives c (E6) when given (terms.confidence on);
//   grad_positions [T][N][3], grad_rotations (right tangent [T][N][3] or raw [T][N][4], Q5): the
//   gradient of carap + arap + lrm + accel + angle is ADDED; empty = not computed.
// Confidences are constants for the gradient (stop-gradient), as on the CPU. Queued on
// `stream`; nothing is synchronised; bit-identical run to run on a given device. Shapes and
// options are checked on the host first (validate_regularizers_shapes); contents are the
// caller's precondition (validate_regularizers). Scratch: regularizers_extra_bytes.
template <class S, class I>
Status regularizers(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                    smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
                    VisibilityView<const std::uint8_t> visibility,
                    const NeighborsView<S, I>& graph, const RegularizerOptions& options,
                    const ReverseGraph& reverse, RegularizerResult<S>* result_device,
                    smg::detail::NonDeducedT<FrameScalarsView<S>> confidence = {},
                    smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {},
                    smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                    cudaStream_t stream = nullptr) {
  if (Status s = validate_regularizers_shapes<S, I>(positions, rotations, visibility, graph,
                                                    options, reverse, confidence,
                                                    grad_positions, grad_rotations);
      !s)
    return s;
  if (result_device == nullptr) return Status::error("result_device: null pointer");
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  const detail::FusedPlan p = detail::fused_plan<S, I>(
      T, N, K, options, grad_positions.data() != nullptr, !grad_rotations.empty(),
      rotations.data() != nullptr, visibility.data() != nullptr, confidence.data() != nullptr);
  return detail::drive<S, I>(detail::DeviceBackend{stream}, p, options, positions, rotations,
                             visibility, graph, reverse.offsets.get(), reverse.entries.get(),
                             reverse.edge_count(), result_device, confidence, grad_positions,
                             grad_rotations);
}

}  // namespace smg::cuda
