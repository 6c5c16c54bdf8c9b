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
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <cstdint>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/carap.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/energy/workspace.hpp"
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
  if (Status s = validate_positions<S>(positions, -1, -1, "positions"); !s) return s;
  if (visibility.data() != nullptr)
    if (Status s = validate_visibility<std::uint8_t>(visibility, T, N, "visibility"); !s) return s;
  if (Status s = validate_neighbors(graph, N, "graph"); !s) return s;
  if (Status s = validate_options(options); !s) return s;
  if (confidence.data() != nullptr)
    if (Status s = validate_output(confidence, T, N, "confidence"); !s) return s;
  if (motion.data() != nullptr)
    if (Status s = validate_output(motion, T, N, "motion"); !s) return s;
  if (rigidity.data() != nullptr)
    if (Status s = validate_output(rigidity, T, N, "rigidity"); !s) return s;
  return Status::ok();
}

namespace detail {
// Σ_k w_ik of row i (the normaliser of ŵ).
template <class S, class I>
inline S row_weight(const NeighborsView<S, I>& g, Index i) {
  S W(0);
  for (Index k = 0; k < g.k(); ++k) {
    if (g.indices(i, k) < 0) break;
    W += g.weights(i, k);
  }
  return W;
}
}  // namespace detail

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
  using L = Literal<S>;
  using std::abs;
  using std::exp;
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  SMG_ASSERT(visibility.data() == nullptr || (visibility.frames() == T && visibility.nodes() == N),
             "node_confidences: visibility shape");
  SMG_ASSERT(graph.nodes() == N && graph.weights.rows() == N && graph.weights.cols() == K,
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
  for (Index i = 0; i < N; ++i) {
    const S W = detail::row_weight(graph, i);
    inv_w[i] = W > S(0) ? S(L(1) / W) : S(0);
  }
  auto u_of = [vel](Index t, Index N_, Index j) { return vel + (t * N_ + j) * 3; };

  // Pass 1: e_i^t, the weighted mean change of node i's edge lengths (E4). Squared lengths
  // are collected per node and square-rooted together (vectorised through Eigen).
  parallel_for_chunks(
      T * N,
      [&](Index, Index begin, Index end) {
        std::vector<S> sq(static_cast<std::size_t>(2 * K)), len(static_cast<std::size_t>(2 * K));
        for (Index item = begin; item < end; ++item) {
          const Index t = item / N, i = item % N;
          const VelocityFrames f = velocity_frames(t, T);
          S e(0);
          const Index n = graph.degree(i);
          if (f.moving && inv_w[i] > S(0) && n > 0) {
            const S* pi = positions.ptr(f.plus, i);
            const S* mi = positions.ptr(f.minus, i);
            for (Index k = 0; k < n; ++k) {
              const Index j = graph.indices(i, k);
              const S* pj = positions.ptr(f.plus, j);
              const S* mj = positions.ptr(f.minus, j);
              S a(0), b(0);
              for (int c = 0; c < 3; ++c) {
                a += (pj[c] - pi[c]) * (pj[c] - pi[c]);
                b += (mj[c] - mi[c]) * (mj[c] - mi[c]);
              }
              sq[static_cast<std::size_t>(k)] = a;
              sq[static_cast<std::size_t>(n + k)] = b;
            }
            detail::sqrt_array(sq.data(), len.data(), 2 * n);
            for (Index k = 0; k < n; ++k)
              e += graph.weights(i, k) * abs(len[static_cast<std::size_t>(k)] -
                                             len[static_cast<std::size_t>(n + k)]);
            e *= inv_w[i];
          }
          edge_change[item] = e;
        }
      },
      parallel);

  // Pass 2: the residuals, their normalisers and the two factors.
  const L kappa_m(options.kappa_m), kappa_r(options.kappa_r), lambda_m(options.lambda_m),
      lambda_r(options.lambda_r), eps(options.eps);
  parallel_for_chunks(
      T * N,
      [&](Index, Index begin, Index end) {
        std::vector<S> sq(static_cast<std::size_t>(K)), nrm(static_cast<std::size_t>(K));
        for (Index item = begin; item < end; ++item) {
          const Index t = item / N, i = item % N;
          const S* e_t = edge_change + t * N;
          const S* ui = u_of(t, N, i);
          S vb0(0), vb1(0), vb2(0), s_v(0), e_bar(0), s_l(0);
          const Index n = inv_w[i] > S(0) ? graph.degree(i) : 0;
          for (Index k = 0; k < n; ++k) {
            const Index j = graph.indices(i, k);
            const S w = graph.weights(i, k) * inv_w[i];
            const S* uj = u_of(t, N, j);
            vb0 += w * uj[0];
            vb1 += w * uj[1];
            vb2 += w * uj[2];
            e_bar += w * e_t[j];
          }
          for (Index k = 0; k < n; ++k) {
            const S* uj = u_of(t, N, graph.indices(i, k));
            const S d0 = uj[0] - vb0, d1 = uj[1] - vb1, d2 = uj[2] - vb2;
            sq[static_cast<std::size_t>(k)] = d0 * d0 + d1 * d1 + d2 * d2;
          }
          detail::sqrt_array(sq.data(), nrm.data(), n);
          for (Index k = 0; k < n; ++k) {
            const Index j = graph.indices(i, k);
            const S w = graph.weights(i, k) * inv_w[i];
            s_v += w * nrm[static_cast<std::size_t>(k)];
            s_l += w * abs(e_t[j] - e_bar);
          }
          const S d0 = ui[0] - vb0, d1 = ui[1] - vb1, d2 = ui[2] - vb2;
          using std::sqrt;
          const S r_v = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
          const S r_l = abs(e_t[i] - e_bar);
          const S a = r_v / (kappa_m * (s_v + eps));
          const S b = r_l / (kappa_r * (s_l + eps));
          const S a2 = a * a, b2 = b * b;
          if (motion.data()) motion(t, i) = exp(-a2);
          if (rigidity.data()) rigidity(t, i) = exp(-b2);
          if (confidence.data()) {
            // (c^m)^λm (c^r)^λr = exp(−λm a² − λr b²): no pow, exact for λ = 0.
            const S vis = visibility.data() ? S(visibility(t, i) ? 1 : 0) : S(1);
            confidence(t, i) = vis * exp(-(lambda_m * a2 + lambda_r * b2));
          }
        }
      },
      parallel);
}

}  // namespace smg
