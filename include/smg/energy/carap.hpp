// smg/energy/carap.hpp — confidence-aware as-rigid-as-possible energy (C-ARAP) with its exact
// gradient (docs/design.md "C-ARAP"; paper section 3.2; docs/math/energy.md (E7)-(E10)).
//
//   d_ij^t = (R_i^t)ᵀ (x_j^t − x_i^t)                                                   (E8)
//   w̃_ij^t = w_ij (α + (1 − α) c_{t,j})                                                  (E7)
//   L = Σ_δ γ_δ Σ_{t=0}^{T−1−δ} Σ_i Σ_{j∈N(i)} w̃_ij^t [ λc ‖d_ij^{t+δ} − d_ij^t‖²
//                                                  + λl (‖d_ij^{t+δ}‖ − ‖d_ij^t‖)² ]       (E9)
//
// The weight is taken at the earlier frame t; gaps δ >= T add nothing; the derivative of ‖d‖ at
// d = 0 is taken as 0 (pinned). Confidences c are constants (stop-gradient): compute them with
// node_confidences() and pass them in. Gradients (E10) are w.r.t. every position x_i^t and every
// rotation R_i^t in the right tangent (R <- R Exp(φ)), and are *added* to the caller's buffers,
// so several energies can accumulate into one gradient.
//
// Evaluation (docs/math/energy.md "Determinism"): the regulariser driver (energy/driver.hpp) with
// the rigid term alone (energy/terms/rigid.hpp): the frames are cut into blocks whose size
// depends only on T and max δ; a block owns the gradient rows of its frames and computes every
// term whose earlier frame it holds; contributions to the up to max(δ) frames past its end go to
// the block's spill, added afterwards in block order. No float atomics, no buffer per edge:
// bit-identical for any thread count; extra memory at most the inputs' bytes (driver.hpp).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>

#include "smg/energy/one_term.hpp"
#include "smg/energy/terms/rigid.hpp"

namespace smg {

// Number of terms of (E9): Σ_δ max(0, T − δ) · Σ_i |N(i)| (every listed gap counts, also one
// with weight 0). Normalization::mean divides by this; 0 terms give energy 0.
template <class S, class I>
inline Index carap_term_count(const NeighborsView<S, I>& graph, Index frames,
                              const GapList& gaps) {
  Index pairs = 0;
  for (const Gap& g : gaps) pairs += std::max<Index>(0, frames - g.delta);
  return pairs * edge_count(graph);
}

// C-ARAP energy (E9), returned in Accumulator<S> (double for float). When given, adds the
// gradient w.r.t. positions to grad_positions [T][N][3] and w.r.t. rotations to grad_rotations
// (E10): a TangentsView [T][N][3] receives the right-tangent gradient (R <- R Exp(φ)), a
// QuaternionsView [T][N][4] the gradient for the raw (w, x, y, z) coordinates of `rotations`
// (Q5). rotations [T][N][4] are normalised on entry. confidence [T][N] may be empty (all 1).
// Precondition: validate_carap.
template <class S, class I>
Accumulator<S> carap(detail::NonDeducedT<PositionsView<const S>> positions,
                     detail::NonDeducedT<QuaternionsView<const S>> rotations,
                     detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                     const NeighborsView<S, I>& graph,
                     const CarapOptions& options, PositionsView<S> grad_positions = {},
                     detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                     EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  // Debug-build checks of the preconditions that would otherwise read or write out of bounds.
  SMG_ASSERT(rotations.frames() == T && rotations.nodes() == N, "carap: rotations shape");
  SMG_ASSERT(detail::graph_operator_shapes(confidence, graph, grad_positions, T, N),
             "carap: confidence, graph or grad_positions shape");
  SMG_ASSERT(detail::absent_or_shape(grad_rotations, T, N), "carap: grad_rotations shape");
  if (T == 0 || N == 0 || K == 0) return Accumulator<S>(0);
  // One term of the driver: C-ARAP alone, with the caller's confidences (or 1).
  detail::RigidTerm<S, I> rigid;
  rigid.configure(&options, nullptr, T, edge_count(graph));
  rigid.want_rotations = !grad_rotations.empty();
  if (!rigid.on()) return Accumulator<S>(0);
  return detail::drive_one_term<S, I>(positions, rotations, confidence, graph, grad_positions,
                                      grad_rotations, workspace, parallel, rigid)
      .carap;
}

}  // namespace smg
