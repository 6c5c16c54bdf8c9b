// smg/core/quaternion.hpp — quaternion storage conversion and raw-coefficient Jacobians.
//
// Memory convention: (w, x, y, z). Eigen::Quaternion stores (x, y, z, w); convert only at the
// boundary with from_wxyz / to_wxyz. Products are Hamilton products, q ⊗ p, as Eigen's
// operator*. Rotation Jacobians elsewhere in smg use the right tangent (R <- R Exp(phi)); this
// header also supplies the bridges between that tangent and raw 4-vectors (what gsplat and
// PyTorch optimise). Derivations: docs/math/core.md, section "Quaternions".
#pragma once

#include "smg/core/config.hpp"

#include <cmath>

#include "smg/core/scalar.hpp"
#include "smg/core/types.hpp"

namespace smg {

// q from 4 scalars in (w, x, y, z) order. No normalisation.
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> from_wxyz(const S* wxyz) {
  return Quaternion<S>(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
}
template <class Derived>
SMG_HOST_DEVICE
inline Quaternion<typename Derived::Scalar> from_wxyz(const Eigen::MatrixBase<Derived>& wxyz) {
  EIGEN_STATIC_ASSERT_VECTOR_SPECIFIC_SIZE(Derived, 4);
  return Quaternion<typename Derived::Scalar>(wxyz(0), wxyz(1), wxyz(2), wxyz(3));
}
// The 4 coefficients of q in (w, x, y, z) order.
template <class S>
SMG_HOST_DEVICE inline Vector4<S> to_wxyz(const Quaternion<S>& q) {
  return Vector4<S>(q.w(), q.x(), q.y(), q.z());
}
template <class S>
SMG_HOST_DEVICE inline void to_wxyz(const Quaternion<S>& q, S* out) {
  out[0] = q.w();
  out[1] = q.x();
  out[2] = q.y();
  out[3] = q.z();
}

// Left-product matrix, (w, x, y, z) coordinates: to_wxyz(p ⊗ q) = quat_left_matrix(p) * to_wxyz(q).
template <class S>
SMG_HOST_DEVICE inline Matrix4<S> quat_left_matrix(const Quaternion<S>& p) {
  Matrix4<S> L;
  L << p.w(), -p.x(), -p.y(), -p.z(),
       p.x(),  p.w(), -p.z(),  p.y(),
       p.y(),  p.z(),  p.w(), -p.x(),
       p.z(), -p.y(),  p.x(),  p.w();
  return L;
}
// Right-product matrix: to_wxyz(p ⊗ q) = quat_right_matrix(q) * to_wxyz(p).
template <class S>
SMG_HOST_DEVICE inline Matrix4<S> quat_right_matrix(const Quaternion<S>& q) {
  Matrix4<S> R;
  R << q.w(), -q.x(), -q.y(), -q.z(),
       q.x(),  q.w(),  q.z(), -q.y(),
       q.y(), -q.z(),  q.w(),  q.x(),
       q.z(),  q.y(), -q.x(),  q.w();
  return R;
}

// d to_wxyz(q ⊗ Exp(phi)) / d phi at phi = 0, a 4x3 matrix: ½ quat_left_matrix(q) restricted to
// the vector columns. Maps a right-tangent direction to a raw-coefficient direction; its
// transpose maps a raw 4-vector gradient g to the right-tangent gradient J^T g (for unit q).
template <class S>
SMG_HOST_DEVICE inline Matrix43<S> quat_tangent_jacobian(const Quaternion<S>& q) {
  return Literal<S>(0.5) * quat_left_matrix(q).template rightCols<3>();
}

// q / |q| with, optionally, its 4x4 Jacobian in (w, x, y, z) coordinates,
// d(q/|q|)/dq = (I - q̂ q̂ᵀ) / |q|. Precondition: |q| > 0 (validate_quaternions rejects zero).
template <class S>
SMG_HOST_DEVICE
inline Quaternion<S> normalized(const Quaternion<S>& q, Matrix4<S>* J_out_q = nullptr) {
  using std::sqrt;
  const S n = sqrt(q.coeffs().squaredNorm());
  const Quaternion<S> out(q.coeffs() / n);
  if (J_out_q) {
    const Vector4<S> u = to_wxyz(out);
    *J_out_q = (Matrix4<S>::Identity() - u * u.transpose()) / n;
  }
  return out;
}

// The representative of ±q with w >= 0 (the one whose log has angle <= pi).
template <class S>
SMG_HOST_DEVICE inline Quaternion<S> canonical(const Quaternion<S>& q) {
  return q.w() < S(0) ? Quaternion<S>(-q.coeffs()) : q;
}

namespace detail {

// Row-major 3x3 rotation matrix R of q / |q| from the 4 raw coefficients q = (w, x, y, z),
// without a square root (the kernels of C-ARAP, CPU and CUDA, and the residual form call it).
template <class S>
SMG_HOST_DEVICE inline void rotation_from_wxyz(const S* q, S* R) {
  using L = Literal<S>;
  const S w = q[0], x = q[1], y = q[2], z = q[3];
  const S s = L(2) / (w * w + x * x + y * y + z * z);
  R[0] = L(1) - s * (y * y + z * z);
  R[1] = s * (x * y - w * z);
  R[2] = s * (x * z + w * y);
  R[3] = s * (x * y + w * z);
  R[4] = L(1) - s * (x * x + z * z);
  R[5] = s * (y * z - w * x);
  R[6] = s * (x * z - w * y);
  R[7] = s * (y * z + w * x);
  R[8] = L(1) - s * (x * x + y * y);
}

}  // namespace detail

}  // namespace smg
