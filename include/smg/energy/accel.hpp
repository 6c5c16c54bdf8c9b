// smg/energy/accel.hpp — trajectory smoothness (E21) as a separate operator: the squared
// acceleration (or velocity) of every node trajectory, weighted by given confidences or 1, with
// its gradient (docs/math/energy.md (E21)). The same term the fused step runs
// (regularizers.hpp, options.terms.accel), through the same driver: a one-term call.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/energy/one_term.hpp"
#include "smg/energy/terms/accel.hpp"

namespace smg {

inline namespace SMG_ISA_NAMESPACE {

// Trajectory smoothness (E21), returned in Accumulator<S> (double for float): with the
// acceleration form Σ_i Σ_t w_i^t ‖x_i^{t+2} − 2 x_i^{t+1} + x_i^t‖² times options.weight (the
// velocity form: first differences), w = confidence(t, i) at the earliest frame when
// options.confidence_weighted, else 1. positions [T][N][3] in scene units; the gradient
// w.r.t. positions is *added* to grad_positions [T][N][3]. Bit-identical for any thread count.
// Precondition: validate_accel.
template <class S>
Accumulator<S> accel(detail::NonDeducedT<PositionsView<const S>> positions,
                     detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                     const AccelOptions& options, PositionsView<S> grad_positions = {},
                     EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  SMG_ASSERT(detail::absent_or_shape(confidence, T, N), "accel: confidence shape");
  SMG_ASSERT(detail::absent_or_shape(grad_positions, T, N), "accel: grad_positions shape");
  if (T == 0 || N == 0) return Accumulator<S>(0);
  using I = std::int32_t;
  detail::AccelTerm<S, I> term;
  term.configure(options, T, N);
  if (!term.on()) return Accumulator<S>(0);
  // No graph: the term reads each node's own trajectory only.
  return detail::drive_one_term<S, I>(
             positions, QuaternionsView<const S>(),
             options.confidence_weighted ? confidence : FrameScalarsView<const S>(),
             NeighborsView<S, I>(nullptr, nullptr, N, 0), grad_positions, RotationGradientView<S>(),
             workspace, parallel, term)
      .accel;
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace smg
