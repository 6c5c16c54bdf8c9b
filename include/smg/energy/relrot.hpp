// smg/energy/relrot.hpp — relative-rotation consistency (E25) as a separate operator: along every
// edge (i, j) and pair of consecutive frames, the relative rotations r^t = q̂^{t+1} ⊗ q̂^{t*} of
// the two ends compared as 4-vectors under a penalty (docs/math/terms/relrot.md), with the
// rotation gradient of both ends. The same term the fused step runs (regularizers.hpp,
// options.terms.relrot), through the same driver: a one-term call.
#pragma once

#include "smg/core/config.hpp"

#include "smg/energy/one_term.hpp"
#include "smg/energy/terms/relrot.hpp"

namespace smg {

inline namespace SMG_ISA_NAMESPACE {

// Relative-rotation consistency (E25), returned in Accumulator<S> (double for float):
// Σ_t Σ_i Σ_{j ∈ N(i)} P(w_ij, r_j^t − r_i^t) times options.weight (divided by (T − 1) · edges
// with Normalization::mean), P the penalty (E22; sqrt_weighted by default). rotations [T][N][4]
// (w, x, y, z; normalised on entry), graph [N][K] (indices, −1 padding; weights ≥ 0); the
// gradient (right tangent [T][N][3] or raw quaternions [T][N][4], (Q5)) is *added* to
// grad_rotations. Bit-identical for any thread count. Precondition: validate_relrot.
template <class S, class I>
Accumulator<S> relrot(detail::NonDeducedT<QuaternionsView<const S>> rotations,
                      const NeighborsView<S, I>& graph, const RelrotOptions& options,
                      detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                      EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  const Index T = rotations.frames(), N = rotations.nodes();
  SMG_ASSERT(graph.nodes() == N, "relrot: graph rows");
  SMG_ASSERT(detail::absent_or_shape(grad_rotations, T, N), "relrot: grad_rotations shape");
  if (T == 0 || N == 0) return Accumulator<S>(0);
  detail::RelrotTerm<S, I> term;
  term.configure(options, T, edge_count(graph));
  term.want_rotations = !grad_rotations.empty();
  if (!term.on()) return Accumulator<S>(0);
  // No positions read: an empty [T][N][3] view gives the driver the shapes.
  return detail::drive_one_term<S, I>(PositionsView<const S>(nullptr, T, N), rotations,
                                      FrameScalarsView<const S>(), graph, PositionsView<S>(),
                                      grad_rotations, workspace, parallel, term)
      .relrot;
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace smg
