// smg/energy/confidence.hpp — per-frame node confidences c_{t,i} (docs/design.md "Confidence";
// paper section 3.2; docs/math/energy.md (E2)-(E6)).
//
//   v̄_i = Σ_j ŵ_ij u_j,  r^v = ‖u_i − v̄_i‖,  s^v = Σ_j ŵ_ij ‖u_j − v̄_i‖            (E2)
//   e_i = Σ_j ŵ_ij |ℓ_ij^{t'} − ℓ_ij^t|,  ē_i = Σ_j ŵ_ij e_j,
//   r^ℓ = |e_i − ē_i|,  s^ℓ = Σ_j ŵ_ij |e_j − ē_i|                                      (E4)
//   c^m = exp(−(r^v / (κm (s^v + ε)))²),  c^r = exp(−(r^ℓ / (κr (s^ℓ + ε)))²)          (E3, E5)
//   c_{t,i} = v_{t,i} · (c^m)^λm · (c^r)^λr                                             (E6)
//
// ŵ_ij = w_ij / Σ_k w_ik: the topology weights of row i normalised to sum 1. The graph builder's
// rows already sum to 1, so this is docs/design.md's Σ_j w_ij exactly; for a hand-made graph it keeps
// v̄ and ē averages (documented deviation, docs/math/energy.md). A node without neighbours (or
// whose weights are all 0) has empty sums = 0 (pinned): v̄ = 0, s^v = 0, e_i = ē_i = 0.
//
// Confidences are functions of the positions but are used as constants by C-ARAP and LRM
// (stop-gradient), so no derivative is provided. Compute them once per iteration and pass the
// [T][N] array to carap()/lrm().
//
// This file holds the CPU entry point, a one-term call of the regulariser driver (energy/driver.hpp)
// with the confidence term (energy/terms/confidence.hpp); the per-node maths it runs is
// elements/confidence.hpp, shared with the CUDA kernels (cuda/confidence.cuh).
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/energy/one_term.hpp"
#include "smg/energy/elements/confidence.hpp"
#include "smg/energy/terms/confidence.hpp"

namespace smg {

// Writes c_{t,i} (E6) into `confidence` [T][N] and, when given, the factors c^m (E3) into
// `motion` and c^r (E5) into `rigidity` (each [T][N], in [0, 1]; exponents λ not applied).
// visibility [T][N] (0/1) may be an empty view: every node visible. Empty output views are not
// computed. Deterministic for any thread count. Precondition: validate_confidence.
template <class S, class I>
void node_confidences(detail::NonDeducedT<PositionsView<const S>> positions,
                      VisibilityView<const std::uint8_t> visibility, const NeighborsView<S, I>& graph,
                      const ConfidenceOptions& options, FrameScalarsView<S> confidence,
                      FrameScalarsView<S> motion = {}, FrameScalarsView<S> rigidity = {},
                      EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  SMG_ASSERT(visibility.data() == nullptr || (visibility.frames() == T && visibility.nodes() == N),
             "node_confidences: visibility shape");
  SMG_ASSERT(graph.nodes() == N && graph.weights.rows() == N && graph.weights.cols() == graph.k(),
             "node_confidences: graph shape");
  SMG_ASSERT(confidence.data() == nullptr || (confidence.frames() == T && confidence.nodes() == N),
             "node_confidences: confidence shape");
  SMG_ASSERT(motion.data() == nullptr || (motion.frames() == T && motion.nodes() == N),
             "node_confidences: motion shape");
  SMG_ASSERT(rigidity.data() == nullptr || (rigidity.frames() == T && rigidity.nodes() == N),
             "node_confidences: rigidity shape");
  if (T == 0 || N == 0) return;
  // The driver's confidence term alone (the one the fused step runs first), so the two give the
  // same bits: per block of frames, each frame's velocities (E1) and e_i^t (E4) of every node,
  // then c_{t,i} (E2)-(E6), in the block's slot; nothing of size T·N besides the outputs.
  detail::ConfidenceTerm<S, I> term;
  term.computed = true;
  term.constants = ConfidenceConstants<S>(options);
  term.vis = visibility;
  term.out = confidence;
  term.motion = motion;
  term.rigidity = rigidity;
  detail::drive_views<S, I>(positions, QuaternionsView<const S>(), visibility.data() != nullptr,
                            graph, PositionsView<S>(), RotationGradientView<S>(), workspace,
                            parallel, term);
}

}  // namespace smg
