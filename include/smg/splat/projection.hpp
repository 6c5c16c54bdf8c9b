// smg/splat/projection.hpp — EWA projection of one 3D Gaussian to the image, and its
// vector-Jacobian product.
//
// gsplat's pinhole projection (fully_fused_projection, persp_proj): world -> camera, 3D
// covariance R S Sᵀ Rᵀ, local affine approximation J of the perspective map with gsplat's
// clamp of x/z and y/z to 1.3x the field of view, 2D covariance J Σ_c Jᵀ + eps2d I, its
// inverse (the conic), and the radius ceil(k sqrt(lambda_max)). Equations (R1)-(R8) in
// docs/math/splat.md; the backward (R20)-(R26). Both are written once over a shared
// intermediate struct, so the backward differentiates exactly what the forward computed.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <limits>

#include "smg/core/quaternion.hpp"
#include "smg/core/types.hpp"
#include "smg/splat/camera.hpp"

namespace smg::splat {

// Why a Gaussian is not drawn. Culled Gaussians get zero gradients.
enum class Cull {
  none = 0,     // visible
  depth,        // camera-space z < near, z > far, or not finite (behind / on the camera plane)
  singular,     // 2D covariance not positive definite within rounding: det <= 16 eps a c (R6)
  outside,      // its radius box does not reach the image
  transparent,  // opacity < 1/255: no pixel can pass the alpha test (decided by the renderer)
};

SMG_HOST_DEVICE inline const char* cull_name(Cull c) {
  switch (c) {
    case Cull::none: return "visible";
    case Cull::depth: return "depth";
    case Cull::singular: return "singular";
    case Cull::outside: return "outside";
    case Cull::transparent: return "transparent";
  }
  return "?";
}

template <class S>
struct ProjectedGaussian {
  Vector2<S> mean2d = Vector2<S>::Zero();  // pixels, (R3)
  Vector3<S> conic = Vector3<S>::Zero();   // (a, b, c) = entries of Σ2D⁻¹: (xx, xy, yy), (R6)
  Vector3<S> cov2d = Vector3<S>::Zero();   // dilated 2D covariance (xx, xy, yy), pixels², (R5)
  S depth = S(0);                          // camera-space z
  S radius = S(0);                         // pixels, ceil(k sqrt(lambda_max)), (R7)
};

// Unit quaternion (w, x, y, z) -> rotation matrix, the polynomial form gsplat uses. (R2)
template <class S>
SMG_HOST_DEVICE inline Matrix3<S> rotmat_from_unit_wxyz(const Vector4<S>& q) {
  const S w = q(0), x = q(1), y = q(2), z = q(3);
  Matrix3<S> R;
  R << S(1) - S(2) * (y * y + z * z), S(2) * (x * y - w * z), S(2) * (x * z + w * y),
       S(2) * (x * y + w * z), S(1) - S(2) * (x * x + z * z), S(2) * (y * z - w * x),
       S(2) * (x * z - w * y), S(2) * (y * z + w * x), S(1) - S(2) * (x * x + y * y);
  return R;
}

// dL/dq of L(rotmat_from_unit_wxyz(q)) given v_R = dL/dR (the polynomial's gradient). (R24)
template <class S>
SMG_HOST_DEVICE
inline Vector4<S> rotmat_from_unit_wxyz_vjp(const Vector4<S>& q, const Matrix3<S>& v) {
  const S w = q(0), x = q(1), y = q(2), z = q(3);
  Vector4<S> g;
  g(0) = S(2) * (-z * v(0, 1) + y * v(0, 2) + z * v(1, 0) - x * v(1, 2) - y * v(2, 0) + x * v(2, 1));
  g(1) = S(2) * (y * v(0, 1) + z * v(0, 2) + y * v(1, 0) - S(2) * x * v(1, 1) - w * v(1, 2) +
                 z * v(2, 0) + w * v(2, 1) - S(2) * x * v(2, 2));
  g(2) = S(2) * (-S(2) * y * v(0, 0) + x * v(0, 1) + w * v(0, 2) + x * v(1, 0) + z * v(1, 2) -
                 w * v(2, 0) + z * v(2, 1) - S(2) * y * v(2, 2));
  g(3) = S(2) * (-S(2) * z * v(0, 0) - w * v(0, 1) + x * v(0, 2) + w * v(1, 0) -
                 S(2) * z * v(1, 1) + y * v(1, 2) + x * v(2, 0) + y * v(2, 1));
  return g;
}

namespace detail {

// Everything the forward computes on the way, kept for the backward.
template <class S>
struct ProjectionState {
  Vector4<S> qhat;      // normalised quaternion
  S qnorm;              // |q|
  Matrix3<S> Rq;        // rotation of the Gaussian
  Vector3<S> scale;     // exp(log_scale)
  Matrix3<S> Sigma_c;   // camera-space covariance W Σ Wᵀ
  Vector3<S> p_c;       // camera-space mean
  S j00, j02, j11, j12; // nonzero entries of J (R4)
  S u, v;               // x/z, y/z after gsplat's field-of-view clamp
  bool u_free, v_free;  // the clamp is inactive (gradient flows through x/z, y/z)
  S a, b, c;            // dilated 2D covariance
  S det;
};

// gsplat's clamp of x/z, y/z for the Jacobian: 0.3 * tan(fov/2) beyond the image edges.
template <class S>
SMG_HOST_DEVICE
inline void fov_limits(const Camera<S>& cam, S* lim_x_pos, S* lim_x_neg, S* lim_y_pos, S* lim_y_neg) {
  const S tan_fovx = S(0.5) * S(cam.width) / cam.fx;
  const S tan_fovy = S(0.5) * S(cam.height) / cam.fy;
  *lim_x_pos = (S(cam.width) - cam.cx) / cam.fx + S(0.3) * tan_fovx;
  *lim_x_neg = cam.cx / cam.fx + S(0.3) * tan_fovx;
  *lim_y_pos = (S(cam.height) - cam.cy) / cam.fy + S(0.3) * tan_fovy;
  *lim_y_neg = cam.cy / cam.fy + S(0.3) * tan_fovy;
}

// Depth test, covariances and J. Returns Cull::depth when z is outside [near, far].
template <class S>
SMG_HOST_DEVICE
inline Cull projection_state(const Camera<S>& cam, const Vector3<S>& mean, const Vector4<S>& quat,
                             const Vector3<S>& log_scale, S eps2d, ProjectionState<S>* st) {
  const Matrix3<S> W = cam.rotation();
  st->p_c = W * mean + cam.translation();
  const S x = st->p_c.x(), y = st->p_c.y(), z = st->p_c.z();
  if (!(z >= cam.near_plane && z <= cam.far_plane)) return Cull::depth;  // NaN-safe

  st->qnorm = quat.norm();
  st->qhat = quat / st->qnorm;
  st->Rq = rotmat_from_unit_wxyz(st->qhat);
  st->scale = log_scale.array().exp().matrix();
  // Σ_c = (W R diag(s)) (W R diag(s))ᵀ  (R2)
  const Matrix3<S> A = (W * st->Rq) * st->scale.asDiagonal();
  st->Sigma_c.noalias() = A * A.transpose();

  S lxp, lxn, lyp, lyn;
  fov_limits(cam, &lxp, &lxn, &lyp, &lyn);
  const S rz = S(1) / z;
  const S xz = x * rz, yz = y * rz;
  st->u_free = xz <= lxp && xz >= -lxn;
  st->v_free = yz <= lyp && yz >= -lyn;
  st->u = std::min(lxp, std::max(-lxn, xz));
  st->v = std::min(lyp, std::max(-lyn, yz));
  st->j00 = cam.fx * rz;
  st->j11 = cam.fy * rz;
  st->j02 = -cam.fx * st->u * rz;
  st->j12 = -cam.fy * st->v * rz;

  // Σ2D = J Σ_c Jᵀ + eps2d I with J = [j00 0 j02; 0 j11 j12]  (R5)
  const Matrix3<S>& P = st->Sigma_c;
  const S j00 = st->j00, j02 = st->j02, j11 = st->j11, j12 = st->j12;
  st->a = j00 * j00 * P(0, 0) + S(2) * j00 * j02 * P(0, 2) + j02 * j02 * P(2, 2) + eps2d;
  st->b = j00 * j11 * P(0, 1) + j00 * j12 * P(0, 2) + j02 * j11 * P(1, 2) + j02 * j12 * P(2, 2);
  st->c = j11 * j11 * P(1, 1) + S(2) * j11 * j12 * P(1, 2) + j12 * j12 * P(2, 2) + eps2d;
  st->det = st->a * st->c - st->b * st->b;
  return Cull::none;
}

}  // namespace detail

// Projects one Gaussian (mean [3], quaternion (w,x,y,z) of any nonzero norm, log-scales [3])
// with the camera. Returns Cull::none and fills *out when visible; otherwise the reason
// (out is then unspecified). radius_sigmas: k in (R7), 3 for gsplat.  (R1)-(R8)
template <class S>
SMG_HOST_DEVICE
inline Cull project_gaussian(const Camera<S>& cam, const Vector3<S>& mean, const Vector4<S>& quat,
                             const Vector3<S>& log_scale, S eps2d, S radius_sigmas,
                             ProjectedGaussian<S>* out) {
  detail::ProjectionState<S> st;
  if (Cull c = detail::projection_state(cam, mean, quat, log_scale, eps2d, &st); c != Cull::none)
    return c;
  // Near-singular: the determinant is below the rounding error of its own computation (also
  // rejects NaN/Inf from overflowing scales).  (R6)
  const S eps = std::numeric_limits<S>::epsilon();
  if (!(st.det > S(16) * eps * st.a * st.c) || !std::isfinite(st.det)) return Cull::singular;

  const S inv_det = S(1) / st.det;
  out->conic = Vector3<S>(st.c * inv_det, -st.b * inv_det, st.a * inv_det);
  out->cov2d = Vector3<S>(st.a, st.b, st.c);
  const S half_trace = S(0.5) * (st.a + st.c);
  const S lambda_max =
      half_trace + std::sqrt(std::max(half_trace * half_trace - st.det, S(0.01)));  // (R7)
  out->radius = std::ceil(radius_sigmas * std::sqrt(lambda_max));
  const S rz = S(1) / st.p_c.z();
  out->mean2d = Vector2<S>(cam.fx * st.p_c.x() * rz + cam.cx, cam.fy * st.p_c.y() * rz + cam.cy);
  out->depth = st.p_c.z();
  const S r = out->radius;
  // (R8): the radius box must overlap the image.
  if (!(out->mean2d.x() + r > S(0) && out->mean2d.x() - r < S(cam.width) &&
        out->mean2d.y() + r > S(0) && out->mean2d.y() - r < S(cam.height)))
    return Cull::outside;
  return Cull::none;
}

// Gradients of one visible Gaussian's projection. Inputs: the forward's arguments and its
// conic, v_mean2d = dL/d mean2d, v_conic = dL/d (a, b, c) of the conic, v_depth = dL/dz.
// Outputs (each optional, overwritten): v_mean [3], v_quat raw 4-vector (through q/|q|),
// v_quat_tangent right-tangent 3-vector (d/dφ at q̂ ⊗ Exp(φ)), v_log_scale [3].  (R20)-(R26)
// Must only be called for a Gaussian that project_gaussian reported visible.
template <class S>
SMG_HOST_DEVICE
inline void project_gaussian_vjp(const Camera<S>& cam, const Vector3<S>& mean,
                                 const Vector4<S>& quat, const Vector3<S>& log_scale, S eps2d,
                                 const Vector3<S>& conic, const Vector2<S>& v_mean2d,
                                 const Vector3<S>& v_conic, S v_depth, Vector3<S>* v_mean,
                                 Vector4<S>* v_quat, Vector3<S>* v_quat_tangent,
                                 Vector3<S>* v_log_scale) {
  detail::ProjectionState<S> st;
  detail::projection_state(cam, mean, quat, log_scale, eps2d, &st);
  const S x = st.p_c.x(), y = st.p_c.y(), z = st.p_c.z();
  const S rz = S(1) / z, rz2 = rz * rz, rz3 = rz2 * rz;

  // Conic = Σ2D⁻¹: dL/dΣ2D = -Q V Q with V the symmetric gradient w.r.t. Q.  (R21)
  Matrix2<S> Q, V;
  Q << conic(0), conic(1), conic(1), conic(2);
  V << v_conic(0), S(0.5) * v_conic(1), S(0.5) * v_conic(1), v_conic(2);
  const Matrix2<S> G = -(Q * V * Q);

  // Σ2D = J Σ_c Jᵀ: dL/dΣ_c = Jᵀ G J, dL/dJ = 2 G J Σ_c.  (R22)
  Eigen::Matrix<S, 2, 3> J;
  J << st.j00, S(0), st.j02, S(0), st.j11, st.j12;
  const Matrix3<S> v_Sigma_c = J.transpose() * G * J;
  const Eigen::Matrix<S, 2, 3> v_J = S(2) * G * J * st.Sigma_c;

  // Through J's dependence on the camera-space mean and the projected mean.  (R23)
  Vector3<S> v_pc(cam.fx * rz * v_mean2d(0), cam.fy * rz * v_mean2d(1),
                  -(cam.fx * x * v_mean2d(0) + cam.fy * y * v_mean2d(1)) * rz2 + v_depth);
  v_pc.z() += -cam.fx * rz2 * v_J(0, 0) - cam.fy * rz2 * v_J(1, 1);
  if (st.u_free) {  // j02 = -fx x / z²
    v_pc.x() += -cam.fx * rz2 * v_J(0, 2);
    v_pc.z() += S(2) * cam.fx * x * rz3 * v_J(0, 2);
  } else {          // j02 = -fx u / z with u a constant
    v_pc.z() += cam.fx * st.u * rz2 * v_J(0, 2);
  }
  if (st.v_free) {
    v_pc.y() += -cam.fy * rz2 * v_J(1, 2);
    v_pc.z() += S(2) * cam.fy * y * rz3 * v_J(1, 2);
  } else {
    v_pc.z() += cam.fy * st.v * rz2 * v_J(1, 2);
  }

  const Matrix3<S> W = cam.rotation();
  if (v_mean) *v_mean = W.transpose() * v_pc;
  if (!v_quat && !v_quat_tangent && !v_log_scale) return;

  // Σ_c = W M Mᵀ Wᵀ, M = R diag(s): dL/dM = 2 Wᵀ (dL/dΣ_c) W M.  (R24)
  const Matrix3<S> v_Sigma = W.transpose() * v_Sigma_c * W;
  const Matrix3<S> M = st.Rq * st.scale.asDiagonal();
  const Matrix3<S> v_M = S(2) * v_Sigma * M;
  if (v_log_scale) {  // (R25): dL/dlog s_j = s_j Σ_i v_M(i,j) R(i,j)
    for (int j = 0; j < 3; ++j) (*v_log_scale)(j) = st.scale(j) * v_M.col(j).dot(st.Rq.col(j));
  }
  const Matrix3<S> v_R = v_M * st.scale.asDiagonal();
  const Vector4<S> v_qhat = rotmat_from_unit_wxyz_vjp(st.qhat, v_R);
  if (v_quat)  // (R26): through q̂ = q/|q|
    *v_quat = (v_qhat - st.qhat * st.qhat.dot(v_qhat)) / st.qnorm;
  if (v_quat_tangent) {
    const Quaternion<S> qh(st.qhat(0), st.qhat(1), st.qhat(2), st.qhat(3));
    *v_quat_tangent = quat_tangent_jacobian(qh).transpose() * v_qhat;
  }
}

}  // namespace smg::splat
