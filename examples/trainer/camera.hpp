// examples/trainer/camera.hpp — pinhole cameras in smg's convention (docs/design.md "Camera").
//
// OpenCV axes: x right, y down, z forward. A camera holds its world-to-camera rigid transform
// as a 4x4 matrix [R t; 0 1] (x_cam = R x_world + t) and pixel intrinsics fx, fy, cx, cy.
// Pixel (i, j) (column i, row j) covers [i, i+1) x [j, j+1); its centre is (i + 0.5, j + 0.5).
// A point with camera coordinates (x, y, z), z > 0, lands at u = fx x/z + cx, v = fy y/z + cy;
// "depth" is always z in the camera, not the distance along the ray.
#pragma once

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace trainer {

// A ray o + s d with a unit direction d (s is then a distance).
struct Ray {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d at(double s) const { return origin + s * direction; }
};

struct Camera {
  int width = 0;   // pixels
  int height = 0;  // pixels
  double fx = 1, fy = 1, cx = 0, cy = 0;  // pixels
  Eigen::Matrix4d world_to_camera = Eigen::Matrix4d::Identity();

  Eigen::Matrix3d K() const {
    Eigen::Matrix3d k;
    k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
    return k;
  }
  Eigen::Matrix3d rotation() const { return world_to_camera.topLeftCorner<3, 3>(); }
  Eigen::Vector3d translation() const { return world_to_camera.topRightCorner<3, 1>(); }
  // Camera centre in world coordinates, -R^T t.
  Eigen::Vector3d center() const { return -rotation().transpose() * translation(); }
  Eigen::Vector3d to_camera(const Eigen::Vector3d& world) const {
    return rotation() * world + translation();
  }
  Eigen::Vector3d to_world(const Eigen::Vector3d& cam) const {
    return rotation().transpose() * (cam - translation());
  }

  // Pixel position of a world point and its depth z (written when depth != null). The pixel is
  // meaningless when z <= 0; callers test the depth.
  Eigen::Vector2d project(const Eigen::Vector3d& world, double* depth = nullptr) const {
    const Eigen::Vector3d c = to_camera(world);
    if (depth) *depth = c.z();
    return Eigen::Vector2d(fx * c.x() / c.z() + cx, fy * c.y() / c.z() + cy);
  }
  // The world point at pixel position `pixel` with depth z (inverse of project).
  Eigen::Vector3d unproject(const Eigen::Vector2d& pixel, double depth) const {
    const Eigen::Vector3d c((pixel.x() - cx) / fx * depth, (pixel.y() - cy) / fy * depth, depth);
    return to_world(c);
  }
  // Unit-direction world ray from the camera centre through a pixel position.
  Ray ray(const Eigen::Vector2d& pixel) const {
    const Eigen::Vector3d c((pixel.x() - cx) / fx, (pixel.y() - cy) / fy, 1.0);
    Ray r;
    r.origin = center();
    r.direction = (rotation().transpose() * c).normalized();
    return r;
  }
  // Inside the image rectangle [0, width) x [0, height).
  bool contains(const Eigen::Vector2d& pixel) const {
    return pixel.x() >= 0 && pixel.y() >= 0 && pixel.x() < width && pixel.y() < height;
  }
};

// A camera at `eye` looking at `target`, with the image's up direction as close to `up` as
// possible (y down is then -up projected); principal point at the image centre (W/2, H/2), square
// pixels, vertical field of view fov_y (radians).
inline Camera look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                      const Eigen::Vector3d& up, int width, int height, double fov_y) {
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d x = z.cross(up).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d R;
  R.row(0) = x.transpose();
  R.row(1) = y.transpose();
  R.row(2) = z.transpose();
  Camera cam;
  cam.width = width;
  cam.height = height;
  cam.fy = 0.5 * height / std::tan(0.5 * fov_y);
  cam.fx = cam.fy;
  cam.cx = 0.5 * width;
  cam.cy = 0.5 * height;
  cam.world_to_camera.setIdentity();
  cam.world_to_camera.topLeftCorner<3, 3>() = R;
  cam.world_to_camera.topRightCorner<3, 1>() = -R * eye;
  return cam;
}

}  // namespace trainer
