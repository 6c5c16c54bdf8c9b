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
SMG_HOST_DEVICE inline S row_weight(const NeighborsView<S, I>& g, Index i) {
  S W(0);
  for (Index k = 0; k < g.k(); ++k) {
    if (g.indices(i, k) < 0) break;
    W += g.weights(i, k);
  }
  return W;
}
}  // namespace detail

// The constants of (E3)-(E6) in the computation's literal type, converted once per call from
// ConfidenceOptions (a plain value: GPU kernels take it by value).
template <class S>
struct ConfidenceConstants {
  Literal<S> kappa_m, kappa_r, lambda_m, lambda_r, eps;
  explicit ConfidenceConstants(const ConfidenceOptions& o)
      : kappa_m(o.kappa_m), kappa_r(o.kappa_r), lambda_m(o.lambda_m), lambda_r(o.lambda_r),
        eps(o.eps) {}
};

// e_i^t (E4): the ŵ-weighted mean change |ℓ_ij^{t'} − ℓ_ij^t| of node i's edge lengths between
// the two frames of its velocity (E1). inv_w = 1 / Σ_k w_ik (0 for an empty row: e = 0).
// One per-element function for the CPU loop and the CUDA kernel (include/smg/cuda/).
template <class S, class I>
SMG_HOST_DEVICE inline S confidence_edge_change(PositionsView<const S> positions,
                                                const NeighborsView<S, I>& graph, S inv_w,
                                                Index t, Index i) {
  using std::abs;
  using std::sqrt;
  const VelocityFrames f = velocity_frames(t, positions.frames());
  const Index n = graph.degree(i);
  if (!f.moving || !(inv_w > S(0)) || n == 0) return S(0);
  const S* pi = positions.ptr(f.plus, i);
  const S* mi = positions.ptr(f.minus, i);
  S e(0);
  for (Index k = 0; k < n; ++k) {
    const Index j = graph.indices(i, k);
    const S* pj = positions.ptr(f.plus, j);
    const S* mj = positions.ptr(f.minus, j);
    // ℓ⁺ − ℓ⁻ = (‖a‖² − ‖b‖²) / (‖a‖ + ‖b‖) with ‖a‖² − ‖b‖² = (a − b)·(a + b): the same value
    // as sqrt(‖a‖²) − sqrt(‖b‖²) without its cancellation (edges change little between frames,
    // so the plain difference of two lengths loses most of float's digits).
    S aa(0), bb(0), ab(0);
    for (int c = 0; c < 3; ++c) {
      const S ac = pj[c] - pi[c], bc = mj[c] - mi[c];
      aa += ac * ac;
      bb += bc * bc;
      ab += (ac - bc) * (ac + bc);
    }
    const S sum = sqrt(aa) + sqrt(bb);
    e += graph.weights(i, k) * (sum > S(0) ? S(abs(ab) / sum) : S(0));
  }
  return e * inv_w;
}

// The factors of node i at frame t from the velocities u [T][N][3] (E1) and the edge changes
// e [T][N] (E4): c^m (E2, E3) into *motion and c^r (E4, E5) into *rigidity (exponents not
// applied), and returns exp(−λm a² − λr b²) = (c^m)^λm (c^r)^λr, the confidence before the
// visibility factor of (E6). inv_w = 1 / Σ_k w_ik (0: no neighbours, empty sums = 0).
template <class S, class I>
SMG_HOST_DEVICE inline S confidence_node(const S* velocity, const S* edge_change,
                                         const NeighborsView<S, I>& graph, S inv_w, Index t,
                                         Index i, const ConfidenceConstants<S>& p, S* motion,
                                         S* rigidity) {
  using std::abs;
  using std::exp;
  using std::sqrt;
  const Index N = graph.nodes();
  const S* e_t = edge_change + t * N;
  const S* ui = velocity + (t * N + i) * 3;
  S vb0(0), vb1(0), vb2(0), s_v(0), e_bar(0), s_l(0);
  const Index n = inv_w > S(0) ? graph.degree(i) : 0;
  for (Index k = 0; k < n; ++k) {
    const Index j = graph.indices(i, k);
    const S w = graph.weights(i, k) * inv_w;
    const S* uj = velocity + (t * N + j) * 3;
    vb0 += w * uj[0];
    vb1 += w * uj[1];
    vb2 += w * uj[2];
    e_bar += w * e_t[j];
  }
  for (Index k = 0; k < n; ++k) {
    const Index j = graph.indices(i, k);
    const S w = graph.weights(i, k) * inv_w;
    const S* uj = velocity + (t * N + j) * 3;
    const S d0 = uj[0] - vb0, d1 = uj[1] - vb1, d2 = uj[2] - vb2;
    s_v += w * sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    s_l += w * abs(e_t[j] - e_bar);
  }
  const S d0 = ui[0] - vb0, d1 = ui[1] - vb1, d2 = ui[2] - vb2;
  const S r_v = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
  const S r_l = abs(e_t[i] - e_bar);
  const S a = r_v / (p.kappa_m * (s_v + p.eps));
  const S b = r_l / (p.kappa_r * (s_l + p.eps));
  const S a2 = a * a, b2 = b * b;
  if (motion) *motion = exp(-a2);
  if (rigidity) *rigidity = exp(-b2);
  // (c^m)^λm (c^r)^λr = exp(−λm a² − λr b²): no pow, exact for λ = 0.
  return exp(-(p.lambda_m * a2 + p.lambda_r * b2));
}

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
  for (Index i = 0; i < N; ++i) {
    const S W = detail::row_weight(graph, i);
    inv_w[i] = W > S(0) ? S(L(1) / W) : S(0);
  }
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
