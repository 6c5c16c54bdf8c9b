// smg/energy/arap.hpp — plain as-rigid-as-possible energy for ablations (docs/design.md "Plain
// ARAP"): C-ARAP with every confidence 1 and α = 1, so w̃_ij^t = w_ij (docs/math/energy.md
// (E9) with c ≡ 1). Same kernel, same gradients, same determinism.
#pragma once

#include "smg/core/config.hpp"

#include "smg/energy/carap.hpp"
#include "smg/energy/validate.hpp"

namespace smg {

// Plain ARAP energy; gradients (positions; rotations in the right tangent [T][N][3] or raw
// quaternion coordinates [T][N][4]) are added to the given buffers like carap(). Precondition: validate_arap.
template <class S, class I>
Accumulator<S> arap(detail::NonDeducedT<PositionsView<const S>> positions,
                    detail::NonDeducedT<QuaternionsView<const S>> rotations,
                    const NeighborsView<S, I>& graph, const ArapOptions& options,
                    PositionsView<S> grad_positions = {},
                    detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                    EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  return carap<S>(positions, rotations, {}, graph, carap_options_for_arap(options),
                  grad_positions, grad_rotations, workspace, parallel);
}

}  // namespace smg
