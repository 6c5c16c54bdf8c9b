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
// This file holds the checks and the CPU loops; the per-node maths they run is
// elements/confidence.hpp, shared with the CUDA kernels (cuda/confidence.cuh).
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/core/parallel.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/elements/confidence.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/validate.hpp"
#include "smg/energy/velocities.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/energy/workspace.hpp"
#include "smg/graph/neighbors.hpp"

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
  detail::WorkspaceRef<S> ws(workspace);
  S* const edge_change = ws->edge_change(static_cast<std::size_t>(T * N));
  // Velocities once (E1) and 1 / Σ_k w_ik per row (0 for an empty row).
  S* const vel = ws->velocity(static_cast<std::size_t>(T * N * 3 + N));
  S* const inv_w = vel + T * N * 3;
  velocities<S>(positions, PositionsView<S>(vel, T, N), parallel);
  for (Index i = 0; i < N; ++i) inv_w[i] = inverse_row_weight(graph, i);
  // Pass 1: e_i^t (E4) of every node and frame; pass 2 reads the neighbours' values.
  parallel_for(
      T * N,
      [&](Index begin, Index end) {
        for (Index item = begin; item < end; ++item)
          edge_change[item] =
              confidence_edge_change(positions, graph, inv_w[item % N], item / N, item % N);
      },
      parallel);
  // Pass 2: the residuals, their normalisers and the two factors (E2)-(E6).
  const ConfidenceConstants<S> p(options);
  parallel_for(
      T * N,
      [&](Index begin, Index end) {
        for (Index item = begin; item < end; ++item) {
          const Index t = item / N, i = item % N;
          S m(0), r(0);
          const S c = confidence_node(vel, edge_change, graph, inv_w[i], t, i, p,
                                      motion.data() ? &m : nullptr,
                                      rigidity.data() ? &r : nullptr);
          if (motion.data()) motion(t, i) = m;
          if (rigidity.data()) rigidity(t, i) = r;
          if (confidence.data()) {
            const S vis = visibility.data() ? S(visibility(t, i) ? 1 : 0) : S(1);
            confidence(t, i) = vis * c;
          }
        }
      },
      parallel);
}

}  // namespace smg
