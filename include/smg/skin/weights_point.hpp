// smg/skin/weights_point.hpp — distance-aware skinning weights of one point, with Jacobians.
//
// A point p attached to anchor node a at reference time t_r is driven by D nodes (a and its
// graph neighbours) at positions x_k = x_k(t_r), each with a length scale sigma_k > 0:
//   l_k = −‖p − x_k‖² / (2 σ_k²),   w_k = exp(l_k − m) / Σ_j exp(l_j − m),  m = max_j l_j
// (S2)-(S3): the normalised exp(l_k), computed as a softmax so that it never underflows to
// 0/0: when every exp(l_k) underflows (a point far from all its drivers, or tiny sigmas) the
// result is still the correct normalised value, which tends to uniform weight over the
// drivers of largest l_k. Defined fallback (S4): if every l_k is −inf (‖p − x_k‖/σ_k overflows
// for every driver), the weights are (1, 0, ..., 0) — all on the first driver, the anchor — and
// their derivatives are 0. Derivations: docs/math/skin.md.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <limits>

#include "smg/core/scalar.hpp"
#include "smg/core/types.hpp"

namespace smg {

// Weights of one point over D drivers (S2)-(S4). x[k]: driver positions at the point's reference
// time; sigma[k] > 0 (length units). Writes w[0..D). Returns true when the fallback (S4) was
// used. Optional Jacobians (null = not computed), row-major over the D weights:
//   J_w_p[j]            = dw_j / dp                  (D entries, each a 1x3 row as a 3-vector)
//   J_w_x[j * D + k]    = dw_j / dx_k                (D*D entries, 1x3 rows)
//   J_w_sigma[j * D + k] = dw_j / dσ_k               (D*D scalars)
// (S5): dw_j/dl_k = w_j (δ_jk − w_k), dl_k/dp = −(p − x_k)/σ_k², dl_k/dx_k = (p − x_k)/σ_k²,
// dl_k/dσ_k = ‖p − x_k‖²/σ_k³.  Precondition: D >= 1.
template <class S>
SMG_HOST_DEVICE inline bool skinning_weights_point(const detail::NonDeducedT<Vector3<S>>& p, Index D, const Vector3<S>* x,
                                   const S* sigma, S* w,
                                   detail::NonDeducedT<Vector3<S>>* J_w_p = nullptr,
                                   detail::NonDeducedT<Vector3<S>>* J_w_x = nullptr,
                                   detail::NonDeducedT<S>* J_w_sigma = nullptr) {
  using std::exp;
  using L = Literal<S>;
  const L neg_inf = -std::numeric_limits<L>::infinity();
  // Logits, via the scaled difference u = (p − x)/σ so that ‖u‖² overflows only when the
  // scaled distance itself does (then l = −inf, weight exactly 0).
  S m = S(neg_inf);
  for (Index k = 0; k < D; ++k) {
    const Vector3<S> u = (p - x[k]) / sigma[k];
    S l = -L(0.5) * u.squaredNorm();
    if (!(l > neg_inf)) l = S(neg_inf);  // NaN from inf/inf never happens for finite inputs
    w[k] = l;
    if (l > m) m = l;
  }
  const bool fallback = !(m > neg_inf);
  if (fallback) {
    for (Index k = 0; k < D; ++k) w[k] = S(k == 0 ? 1 : 0);
  } else {
    S z = S(0);
    for (Index k = 0; k < D; ++k) {
      w[k] = w[k] > neg_inf ? S(exp(w[k] - m)) : S(0);
      z += w[k];
    }
    for (Index k = 0; k < D; ++k) w[k] /= z;  // z >= 1 (the maximum contributes exp(0))
  }
  if (!J_w_p && !J_w_x && !J_w_sigma) return fallback;
  // a_k = dl_k/dp; ā = Σ w_k a_k.
  Vector3<S> abar = Vector3<S>::Zero();
  for (Index k = 0; k < D; ++k)
    if (w[k] > L(0)) abar -= w[k] * (p - x[k]) / (sigma[k] * sigma[k]);
  for (Index j = 0; j < D; ++j) {
    const bool live = w[j] > L(0) && !fallback;
    if (J_w_p) {
      if (live)
        J_w_p[j] = w[j] * (Vector3<S>(-(p - x[j]) / (sigma[j] * sigma[j])) - abar);
      else
        J_w_p[j].setZero();
    }
    for (Index k = 0; k < D; ++k) {
      // dw_j/dl_k = w_j (δ_jk − w_k); zero unless both weights are positive.
      const bool pair = live && w[k] > L(0);
      const S dwdl = pair ? S(w[j] * ((j == k ? L(1) : L(0)) - w[k])) : S(0);
      if (J_w_x) {
        if (pair)
          J_w_x[j * D + k] = dwdl * (p - x[k]) / (sigma[k] * sigma[k]);
        else
          J_w_x[j * D + k].setZero();
      }
      if (J_w_sigma)
        J_w_sigma[j * D + k] =
            pair ? S(dwdl * (p - x[k]).squaredNorm() / (sigma[k] * sigma[k] * sigma[k])) : S(0);
    }
  }
  return fallback;
}

// Vector-Jacobian product of skinning_weights_point at its output w (pass the w it wrote):
// given g_w[k] = dL/dw_k, adds dL/dp to *g_p and writes g_x[k] = dL/dx_k, g_sigma[k] = dL/dσ_k
// (any of the three may be null). (S19): g_l_k = w_k (g_w_k − Σ_j w_j g_w_j). A driver with
// weight 0 receives 0; after the fallback every gradient is 0.
template <class S>
SMG_HOST_DEVICE inline void skinning_weights_point_vjp(const detail::NonDeducedT<Vector3<S>>& p, Index D, const Vector3<S>* x,
                                       const S* sigma, const S* w, const S* g_w,
                                       detail::NonDeducedT<Vector3<S>>* g_p,
                                       detail::NonDeducedT<Vector3<S>>* g_x,
                                       detail::NonDeducedT<S>* g_sigma) {
  using L = Literal<S>;
  S wbar = S(0);
  for (Index k = 0; k < D; ++k) wbar += w[k] * g_w[k];
  for (Index k = 0; k < D; ++k) {
    const S gl = w[k] * (g_w[k] - wbar);
    if (!(w[k] > L(0)) || gl == L(0)) {  // also covers the fallback: g_l = 0 for one-hot w
      if (g_x) g_x[k].setZero();
      if (g_sigma) g_sigma[k] = S(0);
      continue;
    }
    const S inv_s = L(1) / sigma[k];
    const Vector3<S> u = (p - x[k]) * inv_s;  // finite whenever w_k > 0
    const Vector3<S> gx = (gl * inv_s) * u;   // g_l (p − x)/σ²
    if (g_p) *g_p -= gx;
    if (g_x) g_x[k] = gx;
    if (g_sigma) g_sigma[k] = gl * u.squaredNorm() * inv_s;
  }
}

}  // namespace smg
