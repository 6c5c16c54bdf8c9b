// smg/energy/carap_directed.hpp — the directed reading of C-ARAP's asymmetric edge weights, an
// option beside carap() (docs/math/energy.md (E20); the paper's default is carap()).
//
// carap() differentiates every term (i, j) of (E9) with respect to all its variables: lowering
// w̃_ij (an unreliable neighbour j, E7) weakens the pull on both ends. The paper's wording, "the
// motion of nodes with low confidence should be guided by nearby reliable nodes rather than vice
// versa", also reads as a directed influence: term (i, j) moves only node i (x_i, R_i), with x_j
// held constant (a stop-gradient on the neighbour's side, PyTorch's `.detach()`). Then an
// unreliable j barely moves a reliable i (small w̃_ij), while a reliable i moves an unreliable j
// at full strength through j's own term (j, i), weighted by c_i. The update is
//   u_{x_i} = Σ_{δ, t, j ∈ N(i)} ∂E_ij/∂x_i,   u_{φ_i} = Σ_{δ, t, j ∈ N(i)} ∂E_ij/∂φ_i      (E20)
// (φ_i the right tangent of R_i): node by node, the gradient of node i's own terms with its
// neighbours held fixed. u is not the gradient of a single energy (the field is not
// conservative: the energy no longer decreases along -u in general), so an optimiser that takes
// "a gradient" follows it as a defined update. Its rotation part equals carap()'s, because R_i
// enters node i's own terms only.
//
// Each term is carap_residual_block()'s (one source of truth with carap() and the residual
// form); this is a per-node loop over those blocks, about 5x slower than carap()'s vectorised
// kernel: meant for stage-1 sized problems and for comparing the two readings.
#pragma once

#include "smg/core/config.hpp"

#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/energy/carap_residuals.hpp"

namespace smg {

// Energy (E9), the same value as carap(), and the directed update (E20) *added* to
// update_positions [T][N][3] (world frame) and update_rotations [T][N][3] (right tangent); either
// may be empty. Deterministic for any thread count (each node's rows are written by one chunk,
// the energy summed in node order). Precondition: validate_carap() with the same arguments.
template <class S, class I>
S carap_directed(detail::NonDeducedT<PositionsView<const S>> positions,
                 detail::NonDeducedT<QuaternionsView<const S>> rotations,
                 detail::NonDeducedT<FrameScalarsView<const S>> confidence, const NeighborsView<S, I>& graph,
                 const CarapOptions& options, PositionsView<S> update_positions = {},
                 TangentsView<S> update_rotations = {}, ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  SMG_ASSERT(rotations.frames() == T && rotations.nodes() == N, "carap_directed: rotations shape");
  SMG_ASSERT(update_positions.data() == nullptr || (update_positions.frames() == T && update_positions.nodes() == N),
             "carap_directed: update_positions shape");
  SMG_ASSERT(update_rotations.data() == nullptr || (update_rotations.frames() == T && update_rotations.nodes() == N),
             "carap_directed: update_rotations shape");
  const bool jacobians = update_positions.data() != nullptr || update_rotations.data() != nullptr;
  const double scale = carap_residual_scale(graph, T, options);
  const Index G = static_cast<Index>(options.gaps.size());
  std::vector<S> node_energy(static_cast<std::size_t>(N), S(0));
  parallel_for(
      N,
      [&](Index begin, Index end) {
        CarapResidualBlock<S> b;
        // Filled by carap_residual_block whenever they are read; zeroed once so that the compiler
        // can see it (g++ 12 -Wmaybe-uninitialized).
        for (auto* J : {&b.J_xi_t, &b.J_xj_t, &b.J_rot_i_t, &b.J_xi_s, &b.J_xj_s, &b.J_rot_i_s}) J->setZero();
        b.r.setZero();
        for (Index i = begin; i < end; ++i) {
          S e(0);
          for (Index g = 0; g < G; ++g) {
            if (options.gaps[static_cast<std::size_t>(g)].weight == 0.0) continue;
            for (Index t = 0; t < T; ++t)
              for (Index k = 0; k < graph.k(); ++k) {
                if (graph.indices(i, k) < 0) break;
                if (!carap_residual_block(positions, rotations, confidence, graph, options, g, t, i, k, b,
                                          jacobians, scale))
                  continue;
                e += b.r.squaredNorm();
                if (update_positions.data()) {
                  update_positions(b.t, i) += S(2) * b.J_xi_t.transpose() * b.r;
                  update_positions(b.s, i) += S(2) * b.J_xi_s.transpose() * b.r;
                }
                if (update_rotations.data()) {
                  update_rotations(b.t, i) += S(2) * b.J_rot_i_t.transpose() * b.r;
                  update_rotations(b.s, i) += S(2) * b.J_rot_i_s.transpose() * b.r;
                }
              }
          }
          node_energy[static_cast<std::size_t>(i)] = e;
        }
      },
      parallel);
  S energy(0);
  for (const S& e : node_energy) energy += e;
  return energy;
}

}  // namespace smg
