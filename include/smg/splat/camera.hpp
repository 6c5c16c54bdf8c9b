// smg/splat/camera.hpp — the pinhole camera of the splatter and its validation.
//
// Convention (docs/design.md "Camera"): OpenCV axes (x right, y down, z forward); `viewmat` maps
// world to camera coordinates, p_c = R p + t with viewmat = [R t; 0 0 0 1]; intrinsics in
// pixels; the centre of pixel (i, j) (row i, column j) is at (j + 0.5, i + 0.5). Equations:
// docs/math/splat.md (R1)-(R2).
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <sstream>

#include "smg/core/status.hpp"
#include "smg/core/types.hpp"

namespace smg::splat {

template <class S>
struct Camera {
  Matrix4<S> viewmat = Matrix4<S>::Identity();  // world -> camera, [R t; 0 0 0 1]
  S fx = S(1), fy = S(1);                       // focal lengths, pixels
  S cx = S(0), cy = S(0);                       // principal point, pixels (+0.5 convention)
  int width = 0, height = 0;                    // image size, pixels
  S near_plane = S(0.01);                       // camera-space z below this is culled
  S far_plane = S(1e10);                        // camera-space z above this is culled

  // From a 3x3 intrinsic matrix K = [fx 0 cx; 0 fy cy; 0 0 1] (K(0,1), the skew, is ignored
  // as gsplat ignores it; validate_camera_matrix rejects a nonzero one).
  SMG_HOST_DEVICE
  static Camera from_K(const Matrix4<S>& viewmat, const Matrix3<S>& K, int width, int height) {
    Camera c;
    c.viewmat = viewmat;
    c.fx = K(0, 0);
    c.fy = K(1, 1);
    c.cx = K(0, 2);
    c.cy = K(1, 2);
    c.width = width;
    c.height = height;
    return c;
  }

  SMG_HOST_DEVICE Matrix3<S> rotation() const { return viewmat.template topLeftCorner<3, 3>(); }
  SMG_HOST_DEVICE Vector3<S> translation() const { return viewmat.template topRightCorner<3, 1>(); }
  // Camera centre in world coordinates, -Rᵀ t (R is a rotation, validate_camera checks it).
  SMG_HOST_DEVICE Vector3<S> center() const { return -(rotation().transpose() * translation()); }
};

// Checks what the splatter relies on: image size >= 1, finite positive focal lengths, finite
// principal point, 0 < near < far (both finite except far may be large), a finite viewmat
// whose last row is (0, 0, 0, 1) and whose 3x3 block is a rotation (|RᵀR - I| <= 1e-4 per
// entry, det > 0; views exported in float32 pass).
template <class S>
Status validate_camera(const Camera<S>& c) {
  std::ostringstream m;
  if (c.width < 1 || c.height < 1) {
    m << "camera: image size must be at least 1x1, got " << c.width << "x" << c.height;
    return Status::error(m.str());
  }
  if (!(std::isfinite(c.fx) && std::isfinite(c.fy) && c.fx > S(0) && c.fy > S(0)))
    return Status::error("camera: focal lengths fx, fy must be finite and positive");
  if (!(std::isfinite(c.cx) && std::isfinite(c.cy)))
    return Status::error("camera: principal point cx, cy must be finite");
  if (!(std::isfinite(c.near_plane) && c.near_plane > S(0)))
    return Status::error("camera: near plane must be finite and > 0");
  if (!(c.far_plane > c.near_plane) || std::isnan(c.far_plane))
    return Status::error("camera: far plane must be greater than the near plane");
  for (int r = 0; r < 4; ++r)
    for (int k = 0; k < 4; ++k)
      if (!std::isfinite(c.viewmat(r, k)))
        return Status::error("viewmat: non-finite entry");
  if (c.viewmat(3, 0) != S(0) || c.viewmat(3, 1) != S(0) || c.viewmat(3, 2) != S(0) ||
      c.viewmat(3, 3) != S(1))
    return Status::error("viewmat: last row must be (0, 0, 0, 1)");
  const Matrix3<S> R = c.rotation();
  const S err = (R.transpose() * R - Matrix3<S>::Identity()).cwiseAbs().maxCoeff();
  if (!(err <= S(1e-4)) || !(R.determinant() > S(0))) {
    m << "viewmat: the 3x3 block is not a rotation (max |RᵀR - I| = " << err
      << ", det = " << R.determinant() << ")";
    return Status::error(m.str());
  }
  return Status::ok();
}

// Checks a 3x3 intrinsic matrix before Camera::from_K: finite, K(1,0) = K(2,0) = K(2,1) = 0,
// K(2,2) = 1, zero skew K(0,1).
template <class S>
Status validate_camera_matrix(const Matrix3<S>& K) {
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k)
      if (!std::isfinite(K(r, k))) return Status::error("K: non-finite entry");
  if (K(0, 1) != S(0)) return Status::error("K: nonzero skew K[0,1] is not supported");
  if (K(1, 0) != S(0) || K(2, 0) != S(0) || K(2, 1) != S(0) || K(2, 2) != S(1))
    return Status::error("K: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]");
  return Status::ok();
}

}  // namespace smg::splat
