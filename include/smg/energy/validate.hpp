// smg/energy/validate.hpp — the argument checks of the separate energy operators:
// validate_confidence (node_confidences), validate_carap, validate_arap, validate_lrm and the
// fused step's validate_regularizers; one line naming the bad argument. A term's own one-term
// call has its validator in its term header (validate_accel in energy/terms/accel.hpp, ...),
// pool-free as these are.
//
// Why a header of their own: the CUDA launchers' device-memory validators (cuda/validate.cuh)
// call these on host copies, so that the messages are exactly the CPU's, and device headers
// must not reach the CPU thread pool (core/parallel.hpp), which the operators' headers include.
// Nothing here loops over the graph beyond the checks, or starts a thread.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/core/rotation_gradient.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/block.hpp"    // detail::validate_gradient_outputs
#include "smg/energy/common.hpp"   // validate_optional_confidence
#include "smg/energy/term_list.hpp"  // validate_options, the terms' options
#include "smg/graph/neighbors.hpp"

namespace smg {

// Checks the inputs and outputs of node_confidences. `visibility` and every output may be empty
// views (visibility: all visible; outputs: not computed).
template <class S, class I>
Status validate_confidence(detail::NonDeducedT<PositionsView<const S>> positions,
                           VisibilityView<const std::uint8_t> visibility,
                           const NeighborsView<S, I>& graph, const ConfidenceOptions& options,
                           FrameScalarsView<S> confidence, FrameScalarsView<S> motion = {},
                           FrameScalarsView<S> rigidity = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  return detail::first_error(
      {validate_positions<S>(positions, -1, -1, "positions"),
       visibility.data() != nullptr ? validate_visibility<std::uint8_t>(visibility, T, N, "visibility")
                                    : Status::ok(),
       validate_neighbors(graph, N, "graph"), validate_options(options),
       validate_optional_output(confidence, T, N, "confidence"),
       validate_optional_output(motion, T, N, "motion"), validate_optional_output(rigidity, T, N, "rigidity")});
}

// Checks the inputs and outputs of carap(). `confidence` [T][N] may be empty (all 1), and each
// gradient may be empty (not computed). Confidences must lie in [0, 1].
template <class S, class I>
Status validate_carap(detail::NonDeducedT<PositionsView<const S>> positions,
                      detail::NonDeducedT<QuaternionsView<const S>> rotations,
                      detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                      const NeighborsView<S, I>& graph,
                      const CarapOptions& options, PositionsView<S> grad_positions = {},
                      detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  return detail::first_error(
      {validate_positions<S>(positions, -1, -1, "positions"),
       validate_quaternions<S>(rotations, T, N, QuaternionNorm::normalize_on_entry, "rotations"),
       validate_optional_confidence<S>(confidence, T, N), validate_neighbors(graph, N, "graph"),
       validate_options(options), detail::validate_gradient_outputs<S>(grad_positions, grad_rotations, T, N)});
}

// Checks the inputs and outputs of arap().
template <class S, class I>
Status validate_arap(detail::NonDeducedT<PositionsView<const S>> positions,
                     detail::NonDeducedT<QuaternionsView<const S>> rotations,
                     const NeighborsView<S, I>& graph, const ArapOptions& options,
                     PositionsView<S> grad_positions = {},
                     detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  if (Status s = validate_options(options); !s) return s;
  return validate_carap<S>(positions, rotations, {}, graph, carap_options_for_arap(options),
                           grad_positions, grad_rotations);
}

// Checks the inputs and outputs of lrm(). `confidence` may be empty (all 1); the gradient and
// omega outputs may be empty (not computed).
template <class S, class I>
Status validate_lrm(detail::NonDeducedT<PositionsView<const S>> positions,
                    detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                    const NeighborsView<S, I>& graph, const LrmOptions& options,
                    PositionsView<S> grad_positions = {}, TangentsView<S> omega = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  return detail::first_error({validate_positions<S>(positions, -1, -1, "positions"),
                              validate_optional_confidence<S>(confidence, T, N),
                              validate_neighbors(graph, N, "graph"), validate_options(options),
                              validate_optional_output(grad_positions, T, N, "grad_positions"),
                              validate_optional_output(omega, T, N, "omega")});
}

// Checks the arguments of regularizers(); one line naming the bad argument. `rotations` may be
// empty when no term that reads them is on (C-ARAP, ARAP, angle, relrot: reads_rotations); `visibility`
// [T][N] (0/1) may be empty (all visible); `confidence` [T][N] is the output with
// terms.confidence, else the caller's confidences (finite, in [0, 1]) or empty; the gradients
// may be empty (not computed).
template <class S, class I>
Status validate_regularizers(detail::NonDeducedT<PositionsView<const S>> positions,
                             detail::NonDeducedT<QuaternionsView<const S>> rotations,
                             VisibilityView<const std::uint8_t> visibility,
                             const NeighborsView<S, I>& graph, const RegularizerOptions& options,
                             FrameScalarsView<S> confidence = {},
                             PositionsView<S> grad_positions = {},
                             detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  const RegularizerTerms& on = options.terms;
  if (Status s = validate_positions<S>(positions, -1, -1, "positions"); !s) return s;
  if (reads_rotations(on) || rotations.data() != nullptr)
    if (Status s = validate_quaternions<S>(rotations, T, N, QuaternionNorm::normalize_on_entry,
                                           "rotations");
        !s)
      return s;
  if (visibility.data() != nullptr)
    if (Status s = validate_visibility<std::uint8_t>(visibility, T, N, "visibility"); !s) return s;
  if (Status s = validate_neighbors(graph, N, "graph"); !s) return s;
  if (Status s = validate_options(options); !s) return s;
  if (on.confidence) {
    if (Status s = validate_optional_output(confidence, T, N, "confidence"); !s) return s;
  } else if (Status s = validate_optional_confidence<S>(
                 FrameScalarsView<const S>(confidence.data(), confidence.frames(), confidence.nodes()), T, N);
             !s) {
    return s;  // the caller's confidences (input): [T][N], finite, in [0, 1]
  }
  return detail::validate_gradient_outputs<S>(grad_positions, grad_rotations, T, N);
}

}  // namespace smg
