// smg/skin/blend_point.hpp — one point driven by D nodes: dual-quaternion blending (DQB) and,
// for comparison, linear blend skinning (LBS), with the vector-Jacobian product (backward) and
// the full Jacobians.
//
// A point with reference position p and rotation q_p (both at its reference time t_r) is
// driven by D nodes k. Driver k supplies its pose at t_r (x_ref, q_ref), its pose at the query
// time t (x_t, q_t) and a blend weight w_k >= 0. The node's motion t_r -> t is
//   r_k = q_t ⊗ conj(q_ref),   t_k = x_t − R(r_k) x_ref                           (S6)
// DQB blends the unit dual quaternions of these motions, with signs aligned to the
// largest-weight driver, divides by the real part's norm and applies the result to p and q_p;
// LBS blends the motions' matrices (not re-orthonormalised). docs/math/skin.md derives every
// equation (S6)-(S18) and every Jacobian.
//
// Conventions: quaternions are Hamilton, unit (this per-point layer does not normalise —
// smg::skin_blend normalises on entry), Eigen::Quaternion in memory here; rotation Jacobians
// and gradients are in the right tangent (R <- R Exp(phi)) of the quaternion concerned — of the
// output q' for the output rows, of q_ref, q_t, q_p for the input columns. Sign alignment is a
// discontinuous choice: Jacobians are taken with the chosen signs held fixed (they are exact
// everywhere except on the measure-zero set where a sign or the pivot changes).
#pragma once

#include "smg/core/config.hpp"

#include <cmath>

#include "smg/core/scalar.hpp"
#include "smg/core/types.hpp"

namespace smg {

// How the node motions are blended. Both share the rotation output q' (S12); they differ in
// the position: DQB applies the blended rigid motion (S11), LBS averages the transformed points
// (S13), which shrinks a twisting limb ("candy wrapper"; docs/math/skin.md, "LBS vs DQB").
enum class SkinMethod { dqb, lbs };

inline const char* to_string(SkinMethod m) { return m == SkinMethod::dqb ? "dqb" : "lbs"; }

// One driving node of one point: its pose at the point's reference time and at the query time,
// and its blend weight. Quaternions must be unit; the weight >= 0.
template <class S>
struct SkinDriver {
  Vector3<S> x_ref = Vector3<S>::Zero();
  Quaternion<S> q_ref = Quaternion<S>::Identity();
  Vector3<S> x_t = Vector3<S>::Zero();
  Quaternion<S> q_t = Quaternion<S>::Identity();
  S weight = S(0);
};

// The gradient of a scalar loss with respect to one driver's inputs. Rotations: right tangent
// of q_ref and q_t. (phi_ref = −phi_t always holds, because the node's motion depends on its
// two rotations only through q_t ⊗ conj(q_ref), see (S16); both are given for clarity.)
template <class S>
struct SkinDriverGradient {
  Vector3<S> x_ref, phi_ref, x_t, phi_t;
  S weight;
};

// Jacobian blocks of the outputs (rows 0-2: blended position p', rows 3-5: right tangent of the
// blended rotation q') with respect to one driver (columns 0-2 x_ref, 3-5 phi_ref, 6-8 x_t,
// 9-11 phi_t, 12 weight) and with respect to the point (columns 0-2 p, 3-5 phi_p). Row-major, so
// that a batch of them is a plain [..][6][13] / [..][6][6] array.
template <class S> using SkinDriverJacobian = Eigen::Matrix<S, 6, 13, Eigen::RowMajor>;
template <class S> using SkinPointJacobian = Eigen::Matrix<S, 6, 6, Eigen::RowMajor>;

namespace detail {

// Output pointers are non-deduced (NonDeducedT, smg/core/types.hpp), so that callers may pass
// nullptr for any of them.

template <class S>
SMG_HOST_DEVICE inline Quaternion<S> skin_pure(const Vector3<S>& v) {
  return Quaternion<S>(S(0), v(0), v(1), v(2));
}
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> skin_quat(const Vector4<S>& coeffs_xyzw) {
  return Quaternion<S>(coeffs_xyzw);
}

// +1 if q is the canonical representative of ±q (w > 0, or the first nonzero of (w, x, y, z)
// positive), else −1. Used for the pivot so that outputs do not depend on input signs.
template <class S>
SMG_HOST_DEVICE inline bool skin_is_canonical(const Quaternion<S>& q) {
  const Literal<S> zero(0);
  if (q.w() != zero) return q.w() > zero;
  if (q.x() != zero) return q.x() > zero;
  if (q.y() != zero) return q.y() > zero;
  return q.z() >= zero;
}

// Largest weight, first on ties (docs/design.md "Pinned details: DQB").  (S8)
template <class S>
SMG_HOST_DEVICE inline Index skin_pivot(const SkinDriver<S>* d, Index D) {
  Index pivot = 0;
  for (Index k = 1; k < D; ++k)
    if (d[k].weight > d[pivot].weight) pivot = k;
  return pivot;
}

// r_k = q_t ⊗ conj(q_ref).  (S6)
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> skin_motion_rotation(const SkinDriver<S>& d) {
  return d.q_t * d.q_ref.conjugate();
}

// (0, a) ⊗ q − q ⊗ (0, b) = (q_v·(b − a), q_w (a − b) + (a + b) × q_v): the pattern of the
// motion's dual part (S7) and of its adjoint (S15), in 12 multiplications instead of 32.
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> skin_pure_commutator(const Vector3<S>& a, const Quaternion<S>& q,
                                          const Vector3<S>& b) {
  const Vector3<S> v = q.vec();
  const Vector3<S> vec = q.w() * (a - b) + (a + b).cross(v);
  return Quaternion<S>(v.dot(b - a), vec(0), vec(1), vec(2));
}

// vec(conj(a) ⊗ b) = a_w b_v − b_w a_v − a_v × b_v (the scalar part is not needed).
template <class S>
SMG_HOST_DEVICE inline Vector3<S> skin_vec_conj_product(const Quaternion<S>& a, const Quaternion<S>& b) {
  return a.w() * b.vec() - b.w() * a.vec() - a.vec().cross(b.vec());
}
// vec(b ⊗ conj(a)) = a_w b_v − b_w a_v + a_v × b_v.
template <class S>
SMG_HOST_DEVICE inline Vector3<S> skin_vec_product_conj(const Quaternion<S>& b, const Quaternion<S>& a) {
  return a.w() * b.vec() - b.w() * a.vec() + a.vec().cross(b.vec());
}

// R(q) v and R(q)ᵀ v for unit q (t = 2 q_v × v; v ± q_w t + q_v × t), inlined: the hot loops
// call them once per driver, and Eigen's out-of-line operator* on a conjugated temporary
// measured several times slower there.
template <class S>
SMG_HOST_DEVICE inline Vector3<S> skin_rotate(const Quaternion<S>& q, const Vector3<S>& v) {
  const Vector3<S> t = Literal<S>(2) * q.vec().cross(v);
  return v + q.w() * t + q.vec().cross(t);
}
template <class S>
SMG_HOST_DEVICE inline Vector3<S> skin_inverse_rotate(const Quaternion<S>& q, const Vector3<S>& v) {
  const Vector3<S> t = Literal<S>(2) * q.vec().cross(v);
  return v - q.w() * t + q.vec().cross(t);
}

// Dual part of the motion's unit dual quaternion, s_k = ½ (0, t_k) ⊗ r_k, written without
// forming R(r_k):  s_k = ½ (x̂_t ⊗ r_k − r_k ⊗ x̂_ref).  (S7)
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> skin_motion_dual(const SkinDriver<S>& d, const Quaternion<S>& r) {
  return Quaternion<S>(Literal<S>(0.5) * skin_pure_commutator(d.x_t, r, d.x_ref).coeffs());
}

// The blended, normalised motion of one point (everything the outputs and the backward need
// besides the drivers themselves).
template <class S>
struct SkinBlendState {
  Quaternion<S> r_pivot;      // the pivot's motion rotation, canonical sign
  Quaternion<S> c0, ce;       // b / |b_r|: unit real part and the dual part
  S inv_norm;                 // 1 / |b_r|
  Vector3<S> position;        // p'
  Quaternion<S> rotation;     // q' = c0 ⊗ q_p
};

// Forward pass (S6)-(S13). Preconditions: D >= 1, unit quaternions, weights >= 0 with a
// positive maximum (then |b_r| >= max_k w_k > 0, see (S10)).
template <class S>
SMG_HOST_DEVICE inline void skin_blend_forward(SkinMethod method, const SkinDriver<S>* d, Index D,
                               const Vector3<S>& p, const Quaternion<S>& q_p,
                               SkinBlendState<S>& st) {
  using std::sqrt;
  const Literal<S> zero(0);
  Quaternion<S> rp = skin_motion_rotation(d[skin_pivot(d, D)]);
  if (!skin_is_canonical(rp)) rp.coeffs() = -rp.coeffs();
  st.r_pivot = rp;
  Vector4<S> br = Vector4<S>::Zero(), bs = Vector4<S>::Zero();
  Vector3<S> lbs = Vector3<S>::Zero();
  for (Index k = 0; k < D; ++k) {
    const Quaternion<S> r = skin_motion_rotation(d[k]);
    const S a = r.coeffs().dot(rp.coeffs()) >= zero ? d[k].weight : S(-d[k].weight);
    br += a * r.coeffs();
    if (method == SkinMethod::dqb)
      bs += a * skin_motion_dual(d[k], r).coeffs();
    else
      lbs += d[k].weight * (skin_rotate(r, Vector3<S>(p - d[k].x_ref)) + d[k].x_t);
  }
  st.inv_norm = Literal<S>(1) / sqrt(br.squaredNorm());
  st.c0 = Quaternion<S>(br * st.inv_norm);
  st.ce = Quaternion<S>(bs * st.inv_norm);
  if (method == SkinMethod::dqb) {
    // (S11): R(c0) p + 2 vec(ce ⊗ conj(c0)); the scalar part of ce ⊗ conj(c0), nonzero when the
    // blend is not orthogonal, is ignored (as in Kavan et al. 2008; core D2).
    st.position = skin_rotate(st.c0, p) + Literal<S>(2) * skin_vec_product_conj(st.ce, st.c0);
  } else {
    st.position = lbs;
  }
  st.rotation = st.c0 * q_p;
}

// Backward pass: given g_position = dL/dp' and g_rotation = dL/dθ' (right tangent of q'),
// calls emit(k, SkinDriverGradient) once per driver in order and sets *g_p, *g_phi_p (the
// gradients w.r.t. p and the right tangent of q_p). Equations (S14)-(S18).
template <class S, class Emit>
SMG_HOST_DEVICE inline void skin_blend_backward(SkinMethod method, const SkinDriver<S>* d, Index D,
                                const Vector3<S>& p, const Quaternion<S>& q_p,
                                const SkinBlendState<S>& st, const Vector3<S>& g_position,
                                const Vector3<S>& g_rotation, Emit&& emit, Vector3<S>& g_p,
                                Vector3<S>& g_phi_p) {
  using L = Literal<S>;
  const L zero(0), half(0.5), two(2);
  const Quaternion<S>& c0 = st.c0;
  const Quaternion<S>& ce = st.ce;
  // Output stage (S14): adjoints u_c0, u_ce w.r.t. the normalised blend (c0, ce).
  Vector3<S> psi = skin_rotate(q_p, g_rotation);  // R_p gθ: rotation output through ω = 2 vec(c0* ⊗ δc0)
  Vector4<S> u_ce = Vector4<S>::Zero();
  Vector4<S> u_c0_extra = Vector4<S>::Zero();
  if (method == SkinMethod::dqb) {
    const Vector3<S> R0t_gp = skin_inverse_rotate(c0, g_position);
    psi += p.cross(R0t_gp);
    const Quaternion<S> gp_hat = skin_pure(g_position);
    u_ce = two * (gp_hat * c0).coeffs();
    u_c0_extra = -two * (gp_hat * ce).coeffs();
    g_p = R0t_gp;
  } else {
    g_p.setZero();
  }
  const Vector4<S> u_c0 = (c0 * skin_pure(Vector3<S>(two * psi))).coeffs() + u_c0_extra;
  // Through the normalisation c = b / |b_r|  (S14).
  const S radial = c0.coeffs().dot(u_c0) + ce.coeffs().dot(u_ce);
  const Vector4<S> g_br = (u_c0 - radial * c0.coeffs()) * st.inv_norm;
  const Vector4<S> g_bs = u_ce * st.inv_norm;
  g_phi_p = g_rotation;  // q' = c0 ⊗ q_p: identity in right tangents (core C8)

  const Quaternion<S>& rp = st.r_pivot;
  SkinDriverGradient<S> g;
  for (Index k = 0; k < D; ++k) {
    const SkinDriver<S>& dk = d[k];
    const Quaternion<S> r = skin_motion_rotation(dk);
    const bool positive = r.coeffs().dot(rp.coeffs()) >= zero;
    const S a = positive ? dk.weight : S(-dk.weight);
    const Quaternion<S> g_r(a * g_br);
    Vector3<S> g_rho;
    if (method == SkinMethod::dqb) {
      // (S15): b += a (r, s), s = ½ (x̂_t ⊗ r − r ⊗ x̂_ref).
      const Quaternion<S> s = skin_motion_dual(dk, r);
      const Quaternion<S> g_s(a * g_bs);
      const S dot = r.coeffs().dot(g_br) + s.coeffs().dot(g_bs);
      g.weight = positive ? dot : S(-dot);
      g.x_t = half * skin_vec_product_conj(g_s, r);
      g.x_ref = -half * skin_vec_conj_product(r, g_s);
      const Quaternion<S> g_rt(g_r.coeffs() -
                               half * skin_pure_commutator(dk.x_t, g_s, dk.x_ref).coeffs());
      g_rho = half * skin_vec_conj_product(r, g_rt);
    } else {
      // (S18): p' = Σ w (R(r)(p − x_ref) + x_t); the rotation output as in DQB.
      const Vector3<S> v = p - dk.x_ref;
      const Vector3<S> u = skin_inverse_rotate(r, g_position);  // R(r)ᵀ g_p'
      g.x_t = dk.weight * g_position;
      g.x_ref = -dk.weight * u;
      g_p += dk.weight * u;
      g_rho = dk.weight * v.cross(u) + half * skin_vec_conj_product(r, g_r);
      const S rot = r.coeffs().dot(g_br);
      g.weight = g_position.dot(skin_rotate(r, v) + dk.x_t) + (positive ? rot : S(-rot));
    }
    // (S16): the right tangent of r moves by R(q_ref) (φ_t − φ_ref).
    g.phi_t = skin_inverse_rotate(dk.q_ref, g_rho);
    g.phi_ref = -g.phi_t;
    emit(k, g);
  }
}

// The six rows of the Jacobian of (p', θ') as six vector-Jacobian products with unit output
// gradients: calls on_driver(row, k, SkinDriverGradient) and on_point(row, g_p, g_phi_p).
template <class S, class OnDriver, class OnPoint>
SMG_HOST_DEVICE inline void skin_blend_jacobian_rows(SkinMethod method, const SkinDriver<S>* d, Index D,
                                     const Vector3<S>& p, const Quaternion<S>& q_p,
                                     const SkinBlendState<S>& st, OnDriver&& on_driver,
                                     OnPoint&& on_point) {
  for (int row = 0; row < 6; ++row) {
    Vector3<S> gp = Vector3<S>::Zero(), gr = Vector3<S>::Zero();
    if (row < 3)
      gp(row) = S(1);
    else
      gr(row - 3) = S(1);
    Vector3<S> g_p, g_phi_p;
    skin_blend_backward(
        method, d, D, p, q_p, st, gp, gr,
        [&](Index k, const SkinDriverGradient<S>& g) { on_driver(row, k, g); }, g_p, g_phi_p);
    on_point(row, g_p, g_phi_p);
  }
}

}  // namespace detail

// Blends the motions of D drivers and applies them to a point (p, q_p) at its reference time:
// *p_out = p' and *q_out = q' = c0 ⊗ q_p (equations (S6)-(S13)). Optional Jacobians:
// J_out_drivers[k] (D blocks, 6x13) and J_out_point (6x6), layout as SkinDriverJacobian /
// SkinPointJacobian; the weights are free inputs there (no sum-to-one constraint; chain with
// skinning_weights_point for the weights' own dependence on p, x_ref and sigma).
// Preconditions (checked by the batch validators, not here): D >= 1; unit quaternions;
// weights >= 0 with a positive maximum. LBS assumes weights summing to 1 (it is not scale
// invariant; DQB is).
template <class S>
SMG_HOST_DEVICE inline void skin_point(SkinMethod method, const SkinDriver<S>* drivers, Index D,
                       const detail::NonDeducedT<Vector3<S>>& p,
                       const detail::NonDeducedT<Quaternion<S>>& q_p,
                       detail::NonDeducedT<Vector3<S>>* p_out, detail::NonDeducedT<Quaternion<S>>* q_out,
                       detail::NonDeducedT<SkinDriverJacobian<S>>* J_out_drivers = nullptr,
                       detail::NonDeducedT<SkinPointJacobian<S>>* J_out_point = nullptr) {
  detail::SkinBlendState<S> st;
  detail::skin_blend_forward(method, drivers, D, p, q_p, st);
  if (p_out) *p_out = st.position;
  if (q_out) *q_out = st.rotation;
  if (!J_out_drivers && !J_out_point) return;
  detail::skin_blend_jacobian_rows(
      method, drivers, D, p, q_p, st,
      [&](int row, Index k, const SkinDriverGradient<S>& g) {
        if (!J_out_drivers) return;
        auto J = J_out_drivers[k].row(row);
        J.template segment<3>(0) = g.x_ref.transpose();
        J.template segment<3>(3) = g.phi_ref.transpose();
        J.template segment<3>(6) = g.x_t.transpose();
        J.template segment<3>(9) = g.phi_t.transpose();
        J(12) = g.weight;
      },
      [&](int row, const Vector3<S>& g_p, const Vector3<S>& g_phi_p) {
        if (!J_out_point) return;
        J_out_point->row(row).template head<3>() = g_p.transpose();
        J_out_point->row(row).template tail<3>() = g_phi_p.transpose();
      });
}

// Vector-Jacobian product of skin_point: given g_position = dL/dp' and g_rotation = dL/dθ'
// (right tangent of q'), writes g_drivers[k] (D entries, overwritten), *g_p = dL/dp and
// *g_phi_p = dL/dφ_p (right tangent of q_p). Any output pointer may be null. Returns nothing
// about the forward; call skin_point for the values. Same preconditions as skin_point.
template <class S>
SMG_HOST_DEVICE inline void skin_point_vjp(SkinMethod method, const SkinDriver<S>* drivers, Index D,
                           const detail::NonDeducedT<Vector3<S>>& p,
                           const detail::NonDeducedT<Quaternion<S>>& q_p,
                           const detail::NonDeducedT<Vector3<S>>& g_position,
                           const detail::NonDeducedT<Vector3<S>>& g_rotation,
                           detail::NonDeducedT<SkinDriverGradient<S>>* g_drivers,
                           detail::NonDeducedT<Vector3<S>>* g_p, detail::NonDeducedT<Vector3<S>>* g_phi_p) {
  detail::SkinBlendState<S> st;
  detail::skin_blend_forward(method, drivers, D, p, q_p, st);
  Vector3<S> gp, gphi;
  detail::skin_blend_backward(
      method, drivers, D, p, q_p, st, g_position, g_rotation,
      [&](Index k, const SkinDriverGradient<S>& g) {
        if (g_drivers) g_drivers[k] = g;
      },
      gp, gphi);
  if (g_p) *g_p = gp;
  if (g_phi_p) *g_phi_p = gphi;
}

}  // namespace smg
