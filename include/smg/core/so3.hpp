// smg/core/so3.hpp — SO(3) on unit quaternions: hat/vee, Exp/Log, right Jacobians, and the
// group operations with their Jacobians.
//
// Conventions (docs/conventions.md): quaternions are unit Hamilton quaternions; a rotation is
// perturbed on the right, R <- R · Exp(phi), so every rotation Jacobian is a 3-column matrix in
// that right tangent (as manif and Sophus document it). Optional Jacobian outputs follow
// manif's naming J_<output>_<input>; a null pointer means "not computed".
// Derivations: docs/math/core.md, equations (C1)-(C9).
#pragma once

#include "smg/core/config.hpp"

#include <cmath>

#include "smg/core/quaternion.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/types.hpp"

namespace smg::so3 {

// [v]x: the 3x3 skew matrix with hat(v) * u = v x u.  (C1)
template <class Derived>
SMG_HOST_DEVICE inline Matrix3<typename Derived::Scalar> hat(const Eigen::MatrixBase<Derived>& v) {
  EIGEN_STATIC_ASSERT_VECTOR_SPECIFIC_SIZE(Derived, 3);
  using S = typename Derived::Scalar;
  Matrix3<S> m;
  m << S(0), -v(2), v(1),
       v(2), S(0), -v(0),
       -v(1), v(0), S(0);
  return m;
}

// Inverse of hat for a skew-symmetric M: (M21, M02, M10). Only the skew part is read.
template <class Derived>
SMG_HOST_DEVICE inline Vector3<typename Derived::Scalar> vee(const Eigen::MatrixBase<Derived>& M) {
  EIGEN_STATIC_ASSERT_MATRIX_SPECIFIC_SIZE(Derived, 3, 3);
  using S = typename Derived::Scalar;
  using L = Literal<S>;
  return Vector3<S>(L(0.5) * (M(2, 1) - M(1, 2)), L(0.5) * (M(0, 2) - M(2, 0)),
                    L(0.5) * (M(1, 0) - M(0, 1)));
}

namespace detail {
// The coefficients of the right Jacobian and its inverse as functions of theta^2:
//   b = (1 - cos θ)/θ²,  c = (θ - sin θ)/θ³,  d = 1/θ² - (1 + cos θ)/(2 θ sin θ).
// Series through θ^8 below series_threshold (no sqrt, so autodiff is finite at 0); use_series
// says which side of it θ² = t2 lies on.
template <class S>
SMG_HOST_DEVICE inline bool use_series(const S& t2) {
  const auto thr = series_threshold<S>();
  return t2 < thr * thr;
}
template <class S>
SMG_HOST_DEVICE inline S coeff_b(const S& t2) {
  using L = Literal<S>;
  if (use_series(t2))
    return L(1) / 2 - t2 * (L(1) / 24 - t2 * (L(1) / 720 - t2 * (L(1) / 40320 - t2 / L(3628800))));
  using std::sin;
  using std::sqrt;
  const S s = sin(sqrt(t2) / 2);  // half-angle form: no cancellation in 1 - cos
  return L(2) * s * s / t2;
}
template <class S>
SMG_HOST_DEVICE inline S coeff_c(const S& t2) {
  using L = Literal<S>;
  if (use_series(t2))
    return L(1) / 6 -
           t2 * (L(1) / 120 - t2 * (L(1) / 5040 - t2 * (L(1) / 362880 - t2 / L(39916800))));
  using std::sin;
  using std::sqrt;
  const S t = sqrt(t2);
  return (t - sin(t)) / (t2 * t);
}
template <class S>
SMG_HOST_DEVICE inline S coeff_d(const S& t2) {
  using L = Literal<S>;
  if (use_series(t2))
    return L(1) / 12 +
           t2 * (L(1) / 720 + t2 * (L(1) / 30240 + t2 * (L(1) / 1209600 + t2 / L(47900160))));
  using std::cos;
  using std::sin;
  using std::sqrt;
  // cot(θ/2) form: finite at θ = π, singular only at θ = 2π.
  const S t = sqrt(t2);
  return L(1) / t2 - cos(t / 2) / (L(2) * t * sin(t / 2));
}
}  // namespace detail

// Right Jacobian Jr(phi) = I - b [phi]x + c [phi]x^2:  Exp(phi + d) ≈ Exp(phi) Exp(Jr d).  (C3)
template <class Derived>
SMG_HOST_DEVICE
inline Matrix3<typename Derived::Scalar> right_jacobian(const Eigen::MatrixBase<Derived>& phi) {
  using S = typename Derived::Scalar;
  const S t2 = phi.squaredNorm();
  const Matrix3<S> H = hat(phi);
  return Matrix3<S>::Identity() - detail::coeff_b(t2) * H + detail::coeff_c(t2) * (H * H);
}

// Jr(phi)^-1 = I + ½ [phi]x + d [phi]x^2.  Valid for |phi| < 2π (Log returns |phi| <= π).  (C4)
template <class Derived>
SMG_HOST_DEVICE inline Matrix3<typename Derived::Scalar> right_jacobian_inverse(
    const Eigen::MatrixBase<Derived>& phi) {
  using S = typename Derived::Scalar;
  using L = Literal<S>;
  const S t2 = phi.squaredNorm();
  const Matrix3<S> H = hat(phi);
  return Matrix3<S>::Identity() + L(0.5) * H + detail::coeff_d(t2) * (H * H);
}

// Left Jacobian Jl(phi) = Jr(-phi):  Exp(phi + d) ≈ Exp(Jl d) Exp(phi).
template <class Derived>
SMG_HOST_DEVICE
inline Matrix3<typename Derived::Scalar> left_jacobian(const Eigen::MatrixBase<Derived>& phi) {
  return right_jacobian(-phi.eval());
}

// Exp: rotation vector phi (axis * angle, radians) -> unit quaternion
// (cos(θ/2), sin(θ/2) phi/θ).  J_out_phi = Jr(phi).  (C2)
// With the Jacobian, the trigonometric values are shared with Jr (sin θ = 2 sin(θ/2) cos(θ/2)).
template <class Derived>
SMG_HOST_DEVICE inline Quaternion<typename Derived::Scalar> exp(
    const Eigen::MatrixBase<Derived>& phi,
    Matrix3<typename Derived::Scalar>* J_out_phi = nullptr) {
  EIGEN_STATIC_ASSERT_VECTOR_SPECIFIC_SIZE(Derived, 3);
  using S = typename Derived::Scalar;
  using L = Literal<S>;
  using std::cos;
  using std::sin;
  using std::sqrt;
  const S t2 = phi.squaredNorm();
  S w, k;  // w = cos(θ/2), k = sin(θ/2)/θ
  if (detail::use_series(t2)) {
    w = L(1) - t2 * (L(1) / 8 - t2 * (L(1) / 384 - t2 * (L(1) / 46080 - t2 / L(10321920))));
    k = L(1) / 2 - t2 * (L(1) / 48 - t2 * (L(1) / 3840 - t2 * (L(1) / 645120 - t2 / L(185794560))));
    if (J_out_phi) *J_out_phi = right_jacobian(phi);
  } else {
    const S t = sqrt(t2);
    const S sh = sin(t / 2);
    w = cos(t / 2);
    k = sh / t;
    if (J_out_phi) {
      const S b = L(2) * sh * sh / t2;                 // (1 - cos θ)/θ²
      const S c = (t - L(2) * sh * w) / (t2 * t);      // (θ - sin θ)/θ³
      const Matrix3<S> H = hat(phi);
      *J_out_phi = Matrix3<S>::Identity() - b * H + c * (H * H);
    }
  }
  return Quaternion<S>(w, k * phi(0), k * phi(1), k * phi(2));
}

// Log: quaternion -> rotation vector with angle in [0, π], choosing the sign of q with w >= 0
// (q and -q give the same result, except at exactly π where w = 0 and the sign of the vector
// part picks between the two equal answers ±π n). Uses θ = 2 atan2(|v|, w), which is accurate
// near 0 and near π and does not need |q| = 1 (the result depends only on the direction of q).
// J_out_q = Jr(phi)^-1, the Jacobian w.r.t. the right tangent of q.  (C5)
template <class S>
SMG_HOST_DEVICE inline Vector3<S> log(const Quaternion<S>& q, Matrix3<S>* J_out_q = nullptr) {
  using L = Literal<S>;
  using std::atan2;
  using std::sqrt;
  S w = q.w();
  Vector3<S> v = q.vec();
  if (w < S(0)) {
    w = -w;
    v = -v;
  }
  const S n2 = v.squaredNorm();
  S factor;  // θ / |v|
  // atan(x)/x in x = |v|/w has a slowly converging series, so the series branch is only for
  // tiny x (it exists so that autodiff stays finite at the identity); the closed form has no
  // cancellation anywhere else.
  const L x2_limit = L(1e-4);
  if (n2 < x2_limit * w * w) {
    const S x2 = n2 / (w * w);
    factor = L(2) / w * (L(1) - x2 * (L(1) / 3 - x2 * (L(1) / 5 - x2 * (L(1) / 7 - x2 / L(9)))));
    const Vector3<S> phi = factor * v;
    if (J_out_q) *J_out_q = right_jacobian_inverse(phi);
    return phi;
  }
  const S n = sqrt(n2);
  const S theta = L(2) * atan2(n, w);
  factor = theta / n;
  const Vector3<S> phi = factor * v;
  if (J_out_q) {
    // Jr^-1 without trigonometry: cot(θ/2) = w / |v| for any scale of q.
    const Matrix3<S> H = hat(phi);
    const S t2 = theta * theta;
    S d;
    if (detail::use_series(t2))
      d = detail::coeff_d(t2);
    else
      d = L(1) / t2 - w / (L(2) * theta * n);
    *J_out_q = Matrix3<S>::Identity() + L(0.5) * H + d * (H * H);
  }
  return phi;
}

// out = R(q) v.  J_out_q = -R [v]x (right tangent), J_out_v = R.  (C6)
template <class S, class Derived>
SMG_HOST_DEVICE
inline Vector3<S> rotate(const Quaternion<S>& q, const Eigen::MatrixBase<Derived>& v,
                         Matrix3<S>* J_out_q = nullptr, Matrix3<S>* J_out_v = nullptr) {
  const Matrix3<S> R = q.toRotationMatrix();
  const Vector3<S> vv = v;
  if (J_out_q) *J_out_q = -R * hat(vv);
  if (J_out_v) *J_out_v = R;
  return R * vv;
}

// out = R(q)^T v.  J_out_q = [R^T v]x (right tangent), J_out_v = R^T.  (C7)
template <class S, class Derived>
SMG_HOST_DEVICE
inline Vector3<S> inverse_rotate(const Quaternion<S>& q, const Eigen::MatrixBase<Derived>& v,
                                 Matrix3<S>* J_out_q = nullptr, Matrix3<S>* J_out_v = nullptr) {
  const Matrix3<S> Rt = q.toRotationMatrix().transpose();
  const Vector3<S> out = Rt * v;
  if (J_out_q) *J_out_q = hat(out);
  if (J_out_v) *J_out_v = Rt;
  return out;
}

// out = a ⊗ b.  J_out_a = R(b)^T, J_out_b = I (both in right tangents).  (C8)
template <class S>
SMG_HOST_DEVICE
inline Quaternion<S> compose(const Quaternion<S>& a, const Quaternion<S>& b,
                             Matrix3<S>* J_out_a = nullptr, Matrix3<S>* J_out_b = nullptr) {
  if (J_out_a) *J_out_a = b.toRotationMatrix().transpose();
  if (J_out_b) J_out_b->setIdentity();
  return a * b;
}

// out = q^-1 = conj(q) for unit q.  J_out_q = -R(q) (right tangents).  (C9)
template <class S>
SMG_HOST_DEVICE
inline Quaternion<S> inverse(const Quaternion<S>& q, Matrix3<S>* J_out_q = nullptr) {
  if (J_out_q) *J_out_q = -q.toRotationMatrix();
  return q.conjugate();
}

// out = a^-1 ⊗ b, the rotation taking frame a to frame b.  J_out_a = -R(b)^T R(a),
// J_out_b = I.  (Chain of C8 and C9.)
template <class S>
SMG_HOST_DEVICE
inline Quaternion<S> between(const Quaternion<S>& a, const Quaternion<S>& b,
                             Matrix3<S>* J_out_a = nullptr, Matrix3<S>* J_out_b = nullptr) {
  if (J_out_a) *J_out_a = -b.toRotationMatrix().transpose() * a.toRotationMatrix();
  if (J_out_b) J_out_b->setIdentity();
  return a.conjugate() * b;
}

// Geodesic angle between the rotations of a and b, in [0, π], insensitive to the signs of a and
// b; atan2 form, accurate for small angles.
template <class S>
SMG_HOST_DEVICE inline S angular_distance(const Quaternion<S>& a, const Quaternion<S>& b) {
  return log(Quaternion<S>(a.conjugate() * b)).norm();
}

}  // namespace smg::so3
