// smg/core/quaternion_manifold.hpp — unit quaternions (w, x, y, z) as a manifold with smg's
// *right*, full-angle perturbation: the maths of a Ceres Manifold for smg's convention.
//
// Ceres's own QuaternionManifold (and EigenQuaternionManifold) perturb on the left with a
// half-angle tangent: Plus(q, δ) = [cos|δ|, sin|δ| δ/|δ|] ⊗ q. smg's rotation gradients and
// Jacobians are in the right tangent R <- R Exp(φ) (φ the rotation vector), so a Ceres user
// mixing them must use this manifold instead; docs/math/energy.md shows the ~15-line
// ceres::Manifold subclass built on these functions (Ceres is not a dependency of smg).
//
//   plus(q, δ)     = q ⊗ Exp(δ)                                   ambient 4, tangent 3
//   minus(y, x)    = Log(x⁻¹ ⊗ y)                                 minus(plus(x, δ), x) = δ
//   plus_jacobian  = ∂ plus(q, δ)/∂δ at δ = 0 = ½ [q]_L[:, 1:4]    4x3
//   minus_jacobian = ∂ minus(y, x)/∂y at y = x = 2 [x]_L[:, 1:4]ᵀ  3x4
// with [q]_L the left-product matrix (quat_left_matrix). For unit q,
// minus_jacobian · plus_jacobian = I₃, and a cost Jacobian G (m x 3) in the right tangent lifts
// to the ambient 4-vector as G · minus_jacobian (then Ceres's chain G·Jm·Jp gives back G).
// Functions are templated on the scalar (Ceres Jets work: AutoDiffManifold).
#pragma once

#include "smg/core/config.hpp"

#include "smg/core/quaternion.hpp"
#include "smg/core/so3.hpp"

namespace smg::quaternion_manifold {

// out = q ⊗ Exp(delta), all (w, x, y, z) / rotation-vector arrays.
template <class S>
SMG_HOST_DEVICE inline void plus(const S* q, const S* delta, S* out) {
  const Quaternion<S> r = from_wxyz(q) * so3::exp(Vector3<S>(delta[0], delta[1], delta[2]));
  to_wxyz(r, out);
}

// out = Log(x⁻¹ ⊗ y), the right-tangent difference (angle in [0, π]).
template <class S>
SMG_HOST_DEVICE inline void minus(const S* y, const S* x, S* out) {
  const Vector3<S> d = so3::log(Quaternion<S>(from_wxyz(x).conjugate() * from_wxyz(y)));
  out[0] = d(0);
  out[1] = d(1);
  out[2] = d(2);
}

// ∂ plus(q, δ)/∂δ at δ = 0, 4x3.
template <class S>
SMG_HOST_DEVICE inline Matrix43<S> plus_jacobian(const Quaternion<S>& q) {
  return quat_tangent_jacobian(q);
}
// ∂ minus(y, x)/∂y at y = x, 3x4 (for unit x).
template <class S>
SMG_HOST_DEVICE inline Matrix34<S> minus_jacobian(const Quaternion<S>& x) {
  return Literal<S>(2) * quat_left_matrix(x).template rightCols<3>().transpose();
}

// Row-major raw-array versions (Ceres's layout).
template <class S>
SMG_HOST_DEVICE inline void plus_jacobian(const S* q, S* J_row_major_4x3) {
  Eigen::Map<Eigen::Matrix<S, 4, 3, Eigen::RowMajor>> J(J_row_major_4x3);
  J = plus_jacobian(from_wxyz(q));
}
template <class S>
SMG_HOST_DEVICE inline void minus_jacobian(const S* x, S* J_row_major_3x4) {
  Eigen::Map<Eigen::Matrix<S, 3, 4, Eigen::RowMajor>> J(J_row_major_3x4);
  J = minus_jacobian(from_wxyz(x));
}

// A cost Jacobian G (rows x 3) in the right tangent of q as an ambient (rows x 4) Jacobian
// for a solver that chains it with plus_jacobian: G · minus_jacobian(q).
template <class Derived>
SMG_HOST_DEVICE
inline Eigen::Matrix<typename Derived::Scalar, Derived::RowsAtCompileTime, 4> ambient_jacobian(
    const Eigen::MatrixBase<Derived>& G, const Quaternion<typename Derived::Scalar>& q) {
  return G * minus_jacobian(q);
}

}  // namespace smg::quaternion_manifold
