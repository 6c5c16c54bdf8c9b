// smg/energy/edge_isometry.hpp — isometry of a neighbour table against per-edge rest lengths
// (E26, docs/math/energy.md "Isometry against rest lengths"), Dynamic 3D Gaussians' "iso" loss
// (train.py get_loss: weighted_l2_loss_v1 of the neighbour distances against neighbor_dist):
//   ℓ_ij^t = sqrt(‖x_j^t − x_i^t‖² + ε_ℓ),   E = k Σ_t Σ_i Σ_{j ∈ N(i)} P(w_ij, ℓ_ij^t − d0_ij)
// with P the penalty (E22) on the scalar residual (sqrt_weighted by default: sqrt(w r² + ε), the
// weight inside the root) and k = the weight. A separate operator over every frame given, not a
// term of the fused step: its rest lengths are a per-edge input the term list has no place for.
//
// Schedule: the nodes in chunks on every core; a node's gradient rows are gathered from its
// out-edges and, through the in-edges (a reverse adjacency built per call in slot order), the
// edges into it, so each edge's term is evaluated by both its ends and no row is written by two
// chunks: bit-identical results for any thread count, no atomics, no per-thread copy.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/common.hpp"  // Accumulator
#include "smg/energy/lanes.hpp"   // sqrt_array
#include "smg/energy/options.hpp"
#include "smg/energy/penalty.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

// Options of edge_isometry() (E26).
struct EdgeIsometryOptions {
  double weight = 1.0;                       // k, the overall factor
  Penalty penalty = Penalty::sqrt_weighted;  // (E22) on r = ℓ − d0; D3DGS's weighted_l2_loss_v1
  double penalty_eps = 1e-20;                // ε of sqrt_weighted, finite and > 0
  double length_eps = 1e-20;                 // ε_ℓ inside the length's root (D3DGS's), finite, >= 0
  ParallelOptions parallel;                  // CPU threads
};

// (E26) on a batch of n edges: e = x_j − x_i as ex, ey, ez [n], weights w [n], rest lengths d0 [n],
// the factor k, the penalty's ε and the length's floor len_eps. Adds the n energies to `*energy`
// (in order) when it is not null (a batch of in-edges, whose energies their tails count, passes
// null) and, when gx is not null, writes g = ∂E/∂e into gx, gy, gz [n] (x_j's gradient; x_i's is
// −g); ell [n] is scratch. The lengths through one vectorised square root (sqrt_array); at
// ℓ = 0 (e = 0 with len_eps = 0) the gradient is 0 (the length's derivative pinned there, as (E10)'s).
template <class S>
inline void edge_isometry_batch(Penalty p, S k, S eps, S len_eps, Index n, const S* SMG_RESTRICT ex,
                                const S* SMG_RESTRICT ey, const S* SMG_RESTRICT ez, const S* SMG_RESTRICT w,
                                const S* SMG_RESTRICT d0, S* SMG_RESTRICT ell, S* SMG_RESTRICT gx,
                                S* SMG_RESTRICT gy, S* SMG_RESTRICT gz, Accumulator<S>* energy) {
  using L = Literal<S>;
  for (Index a = 0; a < n; ++a) ell[a] = ex[a] * ex[a] + ey[a] * ey[a] + ez[a] * ez[a] + len_eps;
  detail::sqrt_array(ell, ell, n);
  for (Index a = 0; a < n; ++a) {
    const S r = ell[a] - d0[a];
    S h;
    const S e = penalty_of_square<S, L>(p, k, w[a], eps, r * r, h);
    if (energy) *energy += Accumulator<S>(e);
    if (!gx) continue;
    const S c = ell[a] > S(0) ? S(h * r / ell[a]) : S(0);
    gx[a] = c * ex[a];
    gy[a] = c * ey[a];
    gz[a] = c * ez[a];
  }
}

// Checks the arguments of edge_isometry(): positions [T][N][3] finite; graph [N][K]
// (validate_neighbors); rest [N][K] finite (any value on padding); the options; grad empty or
// [T][N][3]. One line naming the argument.
template <class S, class I>
Status validate_edge_isometry(PositionsView<const S> positions, const NeighborsView<S, I>& graph,
                              TableView<const S, Eigen::Dynamic> rest, const EdgeIsometryOptions& o,
                              PositionsView<S> grad_positions = {}) {
  if (Status s = validate_positions<S>(positions, -1, -1, "positions"); !s) return s;
  const Index N = positions.nodes();
  if (Status s = validate_neighbors(graph, N, "graph"); !s) return s;
  if (rest.rows() != N || rest.cols() != graph.k()) {
    std::ostringstream m;
    m << "rest: expected shape [N=" << N << "][K=" << graph.k() << "] (the graph's), got [" << rest.rows() << "]["
      << rest.cols() << "]";
    return Status::error(m.str());
  }
  for (Index i = 0; i < N; ++i)
    for (Index k = 0; k < graph.k(); ++k)
      if (!std::isfinite(rest(i, k))) {
        std::ostringstream m;
        m << "rest: entry [i=" << i << "][k=" << k << "] is not finite";
        return Status::error(m.str());
      }
  if (!(std::isfinite(o.weight)))
    return Status::error("EdgeIsometryOptions::weight must be finite");
  if (!(std::isfinite(o.penalty_eps) && o.penalty_eps > 0))
    return Status::error("EdgeIsometryOptions::penalty_eps must be finite and > 0");
  if (!(std::isfinite(o.length_eps) && o.length_eps >= 0))
    return Status::error("EdgeIsometryOptions::length_eps must be finite and >= 0");
  if (o.penalty != Penalty::squared && o.penalty != Penalty::norm && o.penalty != Penalty::sqrt_weighted)
    return Status::error("EdgeIsometryOptions::penalty is not a listed Penalty");
  return validate_optional_output(grad_positions, positions.frames(), N, "grad_positions");
}

// (E26) over every frame of positions [T][N][3] (world units) with graph [N][K] (weights w ≥ 0,
// −1 padding) and rest [N][K] (d0, world units; read on valid slots only). Returns E; adds ∂E/∂x
// to grad_positions [T][N][3] when it is not empty. Preconditions: validate_edge_isometry.
template <class S, class I>
Accumulator<S> edge_isometry(PositionsView<const S> positions, const NeighborsView<S, I>& graph,
                             TableView<const S, Eigen::Dynamic> rest, const EdgeIsometryOptions& o,
                             PositionsView<S> grad_positions = {}) {
  using L = Literal<S>;
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  if (T == 0 || N == 0 || K == 0) return Accumulator<S>(0);
  const bool grad = grad_positions.data() != nullptr;
  // The in-edges of every node, in slot order (i·K + k increasing): counts, offsets, entries.
  std::vector<std::int64_t> in_offsets, in_slots;
  if (grad) {
    in_offsets.assign(static_cast<std::size_t>(N + 1), 0);
    for (Index i = 0; i < N; ++i)
      for (Index k = 0; k < K && graph.indices(i, k) >= 0; ++k) ++in_offsets[static_cast<std::size_t>(graph.indices(i, k)) + 1];
    for (Index n = 0; n < N; ++n) in_offsets[static_cast<std::size_t>(n + 1)] += in_offsets[static_cast<std::size_t>(n)];
    in_slots.resize(static_cast<std::size_t>(in_offsets[static_cast<std::size_t>(N)]));
    std::vector<std::int64_t> fill(in_offsets.begin(), in_offsets.end() - 1);
    for (Index i = 0; i < N; ++i)
      for (Index k = 0; k < K && graph.indices(i, k) >= 0; ++k)
        in_slots[static_cast<std::size_t>(fill[static_cast<std::size_t>(graph.indices(i, k))]++)] = i * K + k;
  }
  const S k_f = S(L(o.weight)), eps = S(L(o.penalty_eps)), len_eps = S(L(o.length_eps));
  const Penalty p = o.penalty;
  ParallelOptions po = o.parallel;
  po.grain = std::max<Index>(256, (N + 63) / 64);  // a function of N only (determinism)
  std::vector<Accumulator<S>> partial(static_cast<std::size_t>(parallel_chunk_count(N, po.grain)));
  constexpr Index kBatch = 32;  // edges per batch (the arrays live on the stack)
  parallel_for_chunks(
      N,
      [&](Index c, Index n0, Index n1) {
        Accumulator<S> sum(0);
        S ex[kBatch], ey[kBatch], ez[kBatch], w[kBatch], d0[kBatch], ell[kBatch], gx[kBatch], gy[kBatch],
            gz[kBatch];
        S* const gxp = grad ? gx : nullptr;
        for (Index t = 0; t < T; ++t)
          for (Index n = n0; n < n1; ++n) {
            const S* xn = positions.ptr(t, n);
            S gn[3] = {S(0), S(0), S(0)};
            // The batch's edges: out-edges n -> j (their energy counted here; −g into x_n), then
            // in-edges m -> n (+g into x_n; their energy is counted by m).
            Index m = 0;
            auto flush = [&](bool out) {
              edge_isometry_batch<S>(p, k_f, eps, len_eps, m, ex, ey, ez, w, d0, ell, gxp, gy, gz,
                                     out ? &sum : nullptr);
              if (grad) {
                const S sign = out ? S(-1) : S(1);
                for (Index a = 0; a < m; ++a) {
                  gn[0] += sign * gx[a];
                  gn[1] += sign * gy[a];
                  gn[2] += sign * gz[a];
                }
              }
              m = 0;
            };
            auto push = [&](const S* tail, const S* head, S weight, S rest_length, bool out) {
              ex[m] = head[0] - tail[0];
              ey[m] = head[1] - tail[1];
              ez[m] = head[2] - tail[2];
              w[m] = weight;
              d0[m] = rest_length;
              if (++m == kBatch) flush(out);
            };
            for (Index k = 0; k < K && graph.indices(n, k) >= 0; ++k)
              push(xn, positions.ptr(t, graph.indices(n, k)), graph.weights(n, k), rest(n, k), true);
            if (m > 0) flush(true);
            if (!grad) continue;
            const std::size_t a0 = static_cast<std::size_t>(in_offsets[static_cast<std::size_t>(n)]);
            const std::size_t a1 = static_cast<std::size_t>(in_offsets[static_cast<std::size_t>(n + 1)]);
            for (std::size_t a = a0; a < a1; ++a) {
              const Index slot = static_cast<Index>(in_slots[a]), i = slot / K, s = slot - i * K;
              push(positions.ptr(t, i), xn, graph.weights(i, s), rest(i, s), false);
            }
            if (m > 0) flush(false);
            S* dst = grad_positions.ptr(t, n);
            for (int d = 0; d < 3; ++d) dst[d] += gn[d];
          }
        partial[static_cast<std::size_t>(c)] = sum;
      },
      po);
  Accumulator<S> total(0);
  for (const Accumulator<S>& s : partial) total += s;
  return total;
}

}  // namespace smg
