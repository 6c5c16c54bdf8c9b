// smg/core/dual_quaternion.hpp — unit dual quaternions for rigid motions, with Jacobians.
//
// A rigid motion x -> R x + t is the unit dual quaternion  d = r + ε s  with r = q (the unit
// rotation quaternion) and s = ½ (0, t) ⊗ r. Dual-quaternion blending (skin/dqb.hpp) forms a
// weighted sum of such 8-vectors, so the Jacobians here are in raw coordinates: the 8-vector
// (r.w, r.x, r.y, r.z, s.w, s.x, s.y, s.z). Rotation inputs are differentiated in the right
// tangent (R <- R Exp(phi)). Derivations: docs/math/core.md, equations (D1)-(D6).
#pragma once

#include "smg/core/config.hpp"

#include <cmath>

#include "smg/core/quaternion.hpp"
#include "smg/core/types.hpp"

namespace smg {

template <class S>
struct DualQuaternion {
  Quaternion<S> real = Quaternion<S>::Identity();                // r
  Quaternion<S> dual = Quaternion<S>(S(0), S(0), S(0), S(0));    // s

  SMG_HOST_DEVICE static DualQuaternion identity() { return DualQuaternion(); }

  // (r.w, r.x, r.y, r.z, s.w, s.x, s.y, s.z).
  SMG_HOST_DEVICE Vector8<S> coeffs_wxyz() const {
    Vector8<S> c;
    c << to_wxyz(real), to_wxyz(dual);
    return c;
  }
  SMG_HOST_DEVICE static DualQuaternion from_coeffs_wxyz(const Vector8<S>& c) {
    DualQuaternion d;
    d.real = from_wxyz(Vector4<S>(c.template head<4>()));
    d.dual = from_wxyz(Vector4<S>(c.template tail<4>()));
    return d;
  }
};

namespace detail {
// Pure quaternion (0, v).
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> pure(const Vector3<S>& v) {
  return Quaternion<S>(S(0), v(0), v(1), v(2));
}
// diag(1, -1, -1, -1): d conj(q) / d q in (w, x, y, z) coordinates.
template <class S>
SMG_HOST_DEVICE inline Matrix4<S> conj_matrix() {
  return Vector4<S>(S(1), S(-1), S(-1), S(-1)).asDiagonal();
}
}  // namespace detail

// The unit dual quaternion of x -> R(q) x + t:  r = q,  s = ½ (0, t) ⊗ q.  (D1)
// q must be unit. J_out_q: 8x3 w.r.t. the right tangent of q; J_out_t: 8x3.
template <class S>
SMG_HOST_DEVICE inline DualQuaternion<S> dual_quaternion_from_rotation_translation(
    const Quaternion<S>& q, const Vector3<S>& t, Matrix83<S>* J_out_q = nullptr,
    Matrix83<S>* J_out_t = nullptr) {
  DualQuaternion<S> d;
  d.real = q;
  const Quaternion<S> tq = detail::pure(t);
  d.dual = Quaternion<S>(Literal<S>(0.5) * (tq * q).coeffs());
  if (J_out_q) {
    const Matrix43<S> Jq = quat_tangent_jacobian(q);
    J_out_q->template topRows<4>() = Jq;
    J_out_q->template bottomRows<4>() = Literal<S>(0.5) * quat_left_matrix(tq) * Jq;
  }
  if (J_out_t) {
    J_out_t->template topRows<4>().setZero();
    J_out_t->template bottomRows<4>() = Literal<S>(0.5) * quat_right_matrix(q).template rightCols<3>();
  }
  return d;
}

// Rotation and translation of a dual quaternion d = r + ε s that need not be unit:
// q = r / |r|,  t = 2 vec(s ⊗ conj(r)) / |r|^2. (The scalar part of s ⊗ conj(r), which is
// nonzero when r and s are not orthogonal, is ignored, as in Kavan et al. 2008.)  (D2)
template <class S>
SMG_HOST_DEVICE inline void dual_quaternion_to_rotation_translation(const DualQuaternion<S>& d,
                                                    Quaternion<S>* q, Vector3<S>* t) {
  using std::sqrt;
  const S n2 = d.real.coeffs().squaredNorm();
  if (q) *q = Quaternion<S>(d.real.coeffs() / sqrt(n2));
  if (t) *t = Literal<S>(2) * (d.dual * d.real.conjugate()).vec() / n2;
}

// Product a ⊗ b = (a.r ⊗ b.r) + ε (a.r ⊗ b.s + a.s ⊗ b.r): the motion "b, then a".  (D3)
// J_out_a, J_out_b: 8x8 in raw coordinates.
template <class S>
SMG_HOST_DEVICE inline DualQuaternion<S> dual_quaternion_product(const DualQuaternion<S>& a,
                                                 const DualQuaternion<S>& b,
                                                 Matrix8<S>* J_out_a = nullptr,
                                                 Matrix8<S>* J_out_b = nullptr) {
  DualQuaternion<S> out;
  out.real = a.real * b.real;
  out.dual = Quaternion<S>((a.real * b.dual).coeffs() + (a.dual * b.real).coeffs());
  if (J_out_a) {
    J_out_a->template topLeftCorner<4, 4>() = quat_right_matrix(b.real);
    J_out_a->template topRightCorner<4, 4>().setZero();
    J_out_a->template bottomLeftCorner<4, 4>() = quat_right_matrix(b.dual);
    J_out_a->template bottomRightCorner<4, 4>() = quat_right_matrix(b.real);
  }
  if (J_out_b) {
    J_out_b->template topLeftCorner<4, 4>() = quat_left_matrix(a.real);
    J_out_b->template topRightCorner<4, 4>().setZero();
    J_out_b->template bottomLeftCorner<4, 4>() = quat_left_matrix(a.dual);
    J_out_b->template bottomRightCorner<4, 4>() = quat_left_matrix(a.real);
  }
  return out;
}

// Quaternion conjugate of both parts, conj(r) + ε conj(s). For a unit dual quaternion this is
// the inverse motion.  J_out_d = diag(1,-1,-1,-1, 1,-1,-1,-1).  (D4)
template <class S>
SMG_HOST_DEVICE inline DualQuaternion<S> dual_quaternion_conjugate(const DualQuaternion<S>& d,
                                                   Matrix8<S>* J_out_d = nullptr) {
  DualQuaternion<S> out;
  out.real = d.real.conjugate();
  out.dual = d.dual.conjugate();
  if (J_out_d) {
    J_out_d->setZero();
    J_out_d->template topLeftCorner<4, 4>() = detail::conj_matrix<S>();
    J_out_d->template bottomRightCorner<4, 4>() = detail::conj_matrix<S>();
  }
  return out;
}

// d / |d.r| (DQB's normalisation: divide by the real part's norm; the dual part is not
// re-orthogonalised, see D2).  J_out_d = I/n - c e_rᵀ / n³ with n = |r|, c the 8 coefficients
// and e_r = (r, 0).  Precondition: |r| > 0.  (D5)
template <class S>
SMG_HOST_DEVICE inline DualQuaternion<S> dual_quaternion_normalized(const DualQuaternion<S>& d,
                                                    Matrix8<S>* J_out_d = nullptr) {
  using std::sqrt;
  const S n = sqrt(d.real.coeffs().squaredNorm());
  DualQuaternion<S> out;
  out.real = Quaternion<S>(d.real.coeffs() / n);
  out.dual = Quaternion<S>(d.dual.coeffs() / n);
  if (J_out_d) {
    const Vector8<S> c = d.coeffs_wxyz();
    Vector8<S> er = Vector8<S>::Zero();
    er.template head<4>() = c.template head<4>();
    *J_out_d = Matrix8<S>::Identity() / n - c * er.transpose() / (n * n * n);
  }
  return out;
}

// Apply the rigid motion of a (not necessarily unit) dual quaternion to a point:
// out = R(r/|r|) p + 2 vec(s ⊗ conj(r)) / |r|^2.  J_out_d: 3x8 raw coordinates; J_out_p = R.
// This is what DQB applies after blending.  (D6)
template <class S>
SMG_HOST_DEVICE inline Vector3<S> dual_quaternion_transform_point(const DualQuaternion<S>& d, const Vector3<S>& p,
                                                  Matrix38<S>* J_out_d = nullptr,
                                                  Matrix3<S>* J_out_p = nullptr) {
  using std::sqrt;
  const Quaternion<S>& r = d.real;
  const Quaternion<S>& s = d.dual;
  const S n2 = r.coeffs().squaredNorm();
  const Quaternion<S> rc = r.conjugate();
  const Quaternion<S> pq = detail::pure(p);
  // f = vec(r ⊗ p ⊗ conj(r)) = |r|^2 R(r̂) p ;  g = 2 vec(s ⊗ conj(r)).
  const Vector3<S> f = (r * pq * rc).vec();
  const Vector3<S> g = Literal<S>(2) * (s * rc).vec();
  const Vector3<S> out = (f + g) / n2;
  if (J_out_d) {
    const Matrix4<S> C = detail::conj_matrix<S>();
    // d(r p r*)/dr = R(p r*) + L(r p) C ;  d(s r*)/dr = L(s) C ;  d(s r*)/ds = R(r*).
    const Matrix4<S> df_dr = quat_right_matrix(Quaternion<S>(pq * rc)) +
                             quat_left_matrix(Quaternion<S>(r * pq)) * C;
    const Matrix4<S> dg_dr = Literal<S>(2) * quat_left_matrix(s) * C;
    const Matrix4<S> dg_ds = Literal<S>(2) * quat_right_matrix(rc);
    const Vector4<S> rw = to_wxyz(r);
    J_out_d->template leftCols<4>() = (df_dr.template bottomRows<3>() +
                                       dg_dr.template bottomRows<3>()) / n2 -
                                      out * (Literal<S>(2) * rw.transpose()) / n2;
    J_out_d->template rightCols<4>() = dg_ds.template bottomRows<3>() / n2;
  }
  if (J_out_p) *J_out_p = Quaternion<S>(r.coeffs() / sqrt(n2)).toRotationMatrix();
  return out;
}

}  // namespace smg
