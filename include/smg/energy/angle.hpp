// smg/energy/angle.hpp — the rotation-angle velocity or acceleration (E23) as a separate
// operator: the angles θ_i^t of R_i^{t+1} R_i^{tT} summed (or their changes |θ_i^{t+1} − θ_i^t|),
// weighted by given confidences or 1, with the rotation gradient (docs/math/terms/angle.md). The
// same term the fused step runs (regularizers.hpp, options.terms.angle), through the same driver:
// a one-term call.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/energy/one_term.hpp"
#include "smg/energy/terms/angle.hpp"

namespace smg {

inline namespace SMG_ISA_NAMESPACE {

// Rotation-angle smoothness (E23), returned in Accumulator<S> (double for float): with the
// acceleration form Σ_i Σ_t w_i^t |θ_i^{t+1} − θ_i^t| times options.weight (the velocity form:
// Σ_i Σ_t w_i^t θ_i^t), θ_i^t ∈ [0, π] the angle of R_i^{t+1} R_i^{tT}, w = confidence(t, i) at the
// earliest frame when options.confidence_weighted, else 1. rotations [T][N][4] (w, x, y, z;
// normalised on entry); the gradient (right tangent [T][N][3] or raw quaternions [T][N][4], (Q5))
// is *added* to grad_rotations. Bit-identical for any thread count. Precondition: validate_angle.
template <class S>
Accumulator<S> angle(detail::NonDeducedT<QuaternionsView<const S>> rotations,
                     detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                     const AngleOptions& options,
                     detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                     EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  const Index T = rotations.frames(), N = rotations.nodes();
  SMG_ASSERT(detail::absent_or_shape(confidence, T, N), "angle: confidence shape");
  SMG_ASSERT(detail::absent_or_shape(grad_rotations, T, N), "angle: grad_rotations shape");
  if (T == 0 || N == 0) return Accumulator<S>(0);
  using I = std::int32_t;
  detail::AngleTerm<S, I> term;
  term.configure(options, T, N);
  term.want_rotations = !grad_rotations.empty();
  if (!term.on()) return Accumulator<S>(0);
  // No graph and no positions read: an empty [T][N][3] view gives the driver the shapes.
  return detail::drive_one_term<S, I>(
             PositionsView<const S>(nullptr, T, N), rotations,
             options.confidence_weighted ? confidence : FrameScalarsView<const S>(),
             NeighborsView<S, I>(nullptr, nullptr, N, 0), PositionsView<S>(), grad_rotations,
             workspace, parallel, term)
      .angle;
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace smg
