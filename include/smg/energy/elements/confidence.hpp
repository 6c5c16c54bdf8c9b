// smg/energy/elements/confidence.hpp — the per-node maths of the node confidences (E1)-(E6),
// written once for the CPU loops (confidence.hpp) and the CUDA kernels (cuda/confidence.cuh):
// host/device functions of one node and frame, with the option values as a plain struct.
// Equations and conventions: confidence.hpp and docs/math/energy.md.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>

#include "smg/core/scalar.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

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

// 1 / Σ_k w_ik, the factor of ŵ_ij = w_ij / Σ_k w_ik, or 0 for a row without weight (then every
// sum over the row is empty: e = 0, v̄ = 0, pinned).
template <class S, class I>
SMG_HOST_DEVICE inline S inverse_row_weight(const NeighborsView<S, I>& g, Index i) {
  const S W = detail::row_weight(g, i);
  return W > S(0) ? S(Literal<S>(1) / W) : S(0);
}

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

}  // namespace smg
