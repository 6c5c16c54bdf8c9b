// smg/energy/elements/lrm.hpp — one LRM neighbourhood term (E11)-(E13) and its exact gradient (E15),
// written once for every place that evaluates it: the SIMD CPU kernel (lrm.hpp, W frames at
// once in Lanes), the residual form (lrm_residuals.hpp, plain scalars and AutoDiffScalar) and
// the CUDA kernel (cuda/lrm.cuh, one thread per node and frame). Host/device functions of a
// neighbourhood's gathered values: no views, threads or allocation. The loops around them, the
// normalisation and the frame blocking are the callers'.
// (tests/energy/reference_energies.hpp re-derives the same equations independently, by design:
// a reference must not share code with what it checks.)
#pragma once

#include "smg/core/config.hpp"

#include <Eigen/Core>

#include "smg/core/scalar.hpp"
#include "smg/core/types.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/options.hpp"

namespace smg {

// μ / trace(A) of the LRM 3x3 solve (docs/design.md pinned: 1e-10 in double, 1e-5 in float): just
// above the rounding level of the solve in each precision, so the regulariser decides a
// degenerate direction instead of rounding noise, while biasing ordinary neighbourhoods by
// less than 1e-6 (double).  (E13)
template <class S>
SMG_HOST_DEVICE inline Literal<S> lrm_mu_factor() {
  using L = Literal<S>;
  return Eigen::NumTraits<L>::epsilon() > L(1e-10) ? L(1e-5) : L(1e-10);
}

namespace detail {

// LDLᵀ of a symmetric positive definite 3x3 matrix (no pivoting, no square root: stable for
// SPD, and AutoDiffScalar-friendly).
template <class V>
struct Ldlt3 {
  V d0, d1, d2, l10, l20, l21;
  SMG_HOST_DEVICE Ldlt3(const V& m00, const V& m01, const V& m02, const V& m11, const V& m12, const V& m22)
      : d0(m00) {
    l10 = m01 / d0;
    l20 = m02 / d0;
    d1 = m11 - l10 * l10 * d0;
    l21 = (m12 - l20 * l10 * d0) / d1;
    d2 = m22 - l20 * l20 * d0 - l21 * l21 * d1;
  }
  SMG_HOST_DEVICE void solve(const V& b0, const V& b1, const V& b2, V& x0, V& x1, V& x2) const {
    const V y1 = b1 - l10 * b0, y2 = b2 - l20 * b0 - l21 * y1;
    x2 = y2 / d2;
    x1 = y1 / d1 - l21 * x2;
    x0 = b0 / d0 - l10 * x1 - l20 * x2;
  }
};

template <class S>
struct LrmParams {
  Literal<S> huber_delta;
  Literal<S> mu_factor;  // c_μ
  bool detach_omega = false;
  bool gradient = false;
};

// The constants of (E12)-(E13) from the options, in the computation's literal type; `gradient`:
// whether lrm_neighborhood computes ∂L/∂x and ∂L/∂u too.
template <class S>
inline LrmParams<S> lrm_params(const LrmOptions& options, bool gradient) {
  using L = Literal<S>;
  LrmParams<S> p;
  p.huber_delta = L(options.huber_delta);
  p.mu_factor = lrm_mu_factor<S>();
  p.detach_omega = options.detach_omega;
  p.gradient = gradient;
  return p;
}

// Scratch lanes per neighbourhood of K entries.
inline Index lrm_scratch_size(Index K) { return 11 * K; }

// One neighbourhood (or W of them, lane-wise) over K entries: energy L_{t,i} (E11)-(E13) and,
// with p.gradient, ∂L/∂x_k into gx[3K] and ∂L/∂u_k into gu[3K] (E15). Inputs, [component][k]:
// positions x[3K], velocities u[3K], raw weights a[K] (entries with a = 0, e.g. padding, add
// nothing). scratch: lrm_scratch_size(K) lanes. omega (3 lanes, optional) receives ω.
template <class V, class S>
SMG_HOST_DEVICE V lrm_neighborhood(Index K, const V* x, const V* u, const V* a, const LrmParams<S>& p,
                   V* scratch, V* gx, V* gu, V* omega = nullptr) {
  using L = Literal<S>;
  const V zero = lane_constant<V>(L(0)), one = lane_constant<V>(L(1));
  V* w = scratch;
  V* xt = w + K;
  V* ut = xt + 3 * K;
  V* psi = ut + 3 * K;
  V* r = psi + K;  // 3K: residuals, then q = ŵ ψ r

  // Normalised weights; an empty neighbourhood gets ŵ = 0 and so contributes 0 throughout.
  V W = zero;
  for (Index k = 0; k < K; ++k) W += a[k];
  const auto active = lane_greater(W, zero);
  const V inv_w = lane_select(active, V(one / lane_select(active, W, one)), zero);
  for (Index k = 0; k < K; ++k) w[k] = a[k] * inv_w;
  // Centring (E11).
  for (int c = 0; c < 3; ++c) {
    V gs = zero, vs = zero;
    for (Index k = 0; k < K; ++k) {
      gs += w[k] * x[c * K + k];
      vs += w[k] * u[c * K + k];
    }
    for (Index k = 0; k < K; ++k) {
      xt[c * K + k] = x[c * K + k] - gs;
      ut[c * K + k] = u[c * K + k] - vs;
    }
  }
  // Normal equations (E12): S = Σ ŵ x̃ x̃ᵀ, A = trace(S) I − S, b = Σ ŵ x̃ × ũ.
  const V *X = xt, *Y = xt + K, *Z = xt + 2 * K, *U0 = ut, *U1 = ut + K, *U2 = ut + 2 * K;
  V sxx = zero, sxy = zero, sxz = zero, syy = zero, syz = zero, szz = zero;
  V b0 = zero, b1 = zero, b2 = zero;
  for (Index k = 0; k < K; ++k) {
    const V wx = w[k] * X[k], wy = w[k] * Y[k], wz = w[k] * Z[k];
    sxx += wx * X[k];
    sxy += wx * Y[k];
    sxz += wx * Z[k];
    syy += wy * Y[k];
    syz += wy * Z[k];
    szz += wz * Z[k];
    b0 += wy * U2[k] - wz * U1[k];
    b1 += wz * U0[k] - wx * U2[k];
    b2 += wx * U1[k] - wy * U0[k];
  }
  const V tr = sxx + syy + szz;  // trace(A) = 2 tr
  const auto solved = lane_greater(tr, zero);
  const V mu = (L(2) * p.mu_factor) * tr;
  // Unsolved lanes (trace 0) factor I instead and are then masked to ω = 0.
  const V diag = mu + lane_select(solved, zero, one);
  const Ldlt3<V> M(tr - sxx + diag, -sxy, -sxz, tr - syy + diag, -syz, tr - szz + diag);
  V o0, o1, o2;
  M.solve(b0, b1, b2, o0, o1, o2);
  o0 = lane_select(solved, o0, zero);
  o1 = lane_select(solved, o1, zero);
  o2 = lane_select(solved, o2, zero);
  if (omega) {
    omega[0] = o0;
    omega[1] = o1;
    omega[2] = o2;
  }
  // Residuals and Huber (E13).
  const L delta = p.huber_delta, delta2 = p.huber_delta * p.huber_delta;
  V energy = zero;
  for (Index k = 0; k < K; ++k) {
    const V x0 = X[k], x1 = Y[k], x2 = Z[k];
    const V r0 = U0[k] - (o1 * x2 - o2 * x1);
    const V r1 = U1[k] - (o2 * x0 - o0 * x2);
    const V r2 = U2[k] - (o0 * x1 - o1 * x0);
    r[k] = r0;
    r[K + k] = r1;
    r[2 * K + k] = r2;
    const V n2 = r0 * r0 + r1 * r1 + r2 * r2;
    const auto linear = lane_greater(n2, lane_constant<V>(delta2));
    const V nr = lane_sqrt(lane_select(linear, n2, lane_constant<V>(delta2)));
    const V rho = lane_select(linear, V(delta * (nr - L(0.5) * delta)), V(L(0.5) * n2));
    psi[k] = lane_select(linear, V(delta / nr), one);  // ρ'(r)/r
    energy += w[k] * rho;
  }
  if (!p.gradient) return energy;

  // q = ŵ ψ r = ∂L/∂r; Q = Σ q; z = ∂L/∂ω = Σ q × x̃.
  V Q0 = zero, Q1 = zero, Q2 = zero, z0 = zero, z1 = zero, z2 = zero;
  for (Index k = 0; k < K; ++k) {
    const V s = w[k] * psi[k];
    const V q0 = s * r[k], q1 = s * r[K + k], q2 = s * r[2 * K + k];
    r[k] = q0;
    r[K + k] = q1;
    r[2 * K + k] = q2;
    Q0 += q0;
    Q1 += q1;
    Q2 += q2;
    z0 += q1 * Z[k] - q2 * Y[k];
    z1 += q2 * X[k] - q0 * Z[k];
    z2 += q0 * Y[k] - q1 * X[k];
  }
  // Adjoint of ω = (A + μI)⁻¹ b: λ = (A + μI)⁻¹ z (0 when ω is held constant or not solved).
  // ∂L/∂x̃ gains ŵ [ũ × λ + (λωᵀ + ωλᵀ − (2 + 4c_μ)(λ·ω) I) x̃] and ∂L/∂ũ gains ŵ λ × x̃ (E15).
  V l0 = zero, l1 = zero, l2 = zero;
  if (!p.detach_omega) {
    M.solve(z0, z1, z2, l0, l1, l2);
    l0 = lane_select(solved, l0, zero);
    l1 = lane_select(solved, l1, zero);
    l2 = lane_select(solved, l2, zero);
  }
  const V kappa = (L(2) + L(4) * p.mu_factor) * (l0 * o0 + l1 * o1 + l2 * o2);
  const V m00 = L(2) * l0 * o0 - kappa, m11 = L(2) * l1 * o1 - kappa,
          m22 = L(2) * l2 * o2 - kappa;
  const V m01 = l0 * o1 + o0 * l1, m02 = l0 * o2 + o0 * l2, m12 = l1 * o2 + o1 * l2;
  // Centring back (E15): ∂/∂x_k = ∂/∂x̃_k − ŵ_k Σ_m ∂/∂x̃_m, where the ŵ-linear parts sum to 0
  // (Σ ŵ x̃ = Σ ŵ ũ = 0), leaving ŵ_k Q and ŵ_k ω × Q.
  for (Index k = 0; k < K; ++k) {
    const V wk = w[k];
    const V p0 = r[k] - wk * Q0, p1 = r[K + k] - wk * Q1, p2 = r[2 * K + k] - wk * Q2;
    const V x0 = X[k], x1 = Y[k], x2 = Z[k];
    const V u0 = U0[k], u1 = U1[k], u2 = U2[k];
    gu[k] = p0 + wk * (l1 * x2 - l2 * x1);
    gu[K + k] = p1 + wk * (l2 * x0 - l0 * x2);
    gu[2 * K + k] = p2 + wk * (l0 * x1 - l1 * x0);
    gx[k] = (o1 * p2 - o2 * p1) + wk * (m00 * x0 + m01 * x1 + m02 * x2 + (u1 * l2 - u2 * l1));
    gx[K + k] =
        (o2 * p0 - o0 * p2) + wk * (m01 * x0 + m11 * x1 + m12 * x2 + (u2 * l0 - u0 * l2));
    gx[2 * K + k] =
        (o0 * p1 - o1 * p0) + wk * (m02 * x0 + m12 * x1 + m22 * x2 + (u0 * l1 - u1 * l0));
  }
  return energy;
}

}  // namespace detail

}  // namespace smg
