// Cameras: OpenCV axes, pixel centres at +0.5, project/unproject/ray round trips.
#include <doctest/doctest.h>

#include <cmath>

#include "support/random.hpp"
#include "trainer/camera.hpp"

using trainer::Camera;
using Eigen::Vector2d;
using Eigen::Vector3d;

TEST_CASE("look_at: OpenCV axes, the target at the principal point, a proper rotation") {
  const Vector3d eye(0.3, -2.0, 1.1), target(-0.1, 0.2, 0.3);
  const Camera cam = trainer::look_at(eye, target, Vector3d::UnitZ(), 160, 120, 0.9);
  const Eigen::Matrix3d R = cam.rotation();
  CHECK((R * R.transpose() - Eigen::Matrix3d::Identity()).norm() < 1e-12);
  CHECK(R.determinant() == doctest::Approx(1.0).epsilon(1e-12));
  CHECK((cam.center() - eye).norm() < 1e-12);
  double z;
  const Vector2d c = cam.project(target, &z);
  CHECK(c.x() == doctest::Approx(80.0).epsilon(1e-12));
  CHECK(c.y() == doctest::Approx(60.0).epsilon(1e-12));
  CHECK(z == doctest::Approx((target - eye).norm()).epsilon(1e-12));
  // y points down: a point above the target lands higher in the image (smaller v); x points
  // right: with z up and the camera looking along roughly +y, world +x is to the right.
  CHECK(cam.project(target + Vector3d(0, 0, 0.1)).y() < 60.0);
  CHECK(cam.project(target + Vector3d(0.1, 0, 0)).x() > 80.0);
  // Vertical field of view: the top image edge is at fov/2 above the axis.
  CHECK(cam.fy == doctest::Approx(60.0 / std::tan(0.45)).epsilon(1e-12));
  CHECK(cam.fx == cam.fy);
}

TEST_CASE("pixel centres are at +0.5: the centre ray of pixel (i, j) goes through (i + 0.5, j + 0.5)") {
  const Camera cam = trainer::look_at(Vector3d(0, -1, 0), Vector3d::Zero(), Vector3d::UnitZ(), 4, 2, 1.0);
  // With W = 4, H = 2 the principal point (2, 1) is the corner shared by the four central pixels.
  const trainer::Ray r = cam.ray(Vector2d(0 + 0.5, 0 + 0.5));
  const Vector3d c = cam.rotation() * r.direction;
  CHECK(c.x() / c.z() == doctest::Approx((0.5 - 2.0) / cam.fx).epsilon(1e-12));
  CHECK(c.y() / c.z() == doctest::Approx((0.5 - 1.0) / cam.fy).epsilon(1e-12));
  CHECK(cam.contains(Vector2d(0, 0)));
  CHECK(cam.contains(Vector2d(3.999, 1.999)));
  CHECK_FALSE(cam.contains(Vector2d(4.0, 1.0)));
  CHECK_FALSE(cam.contains(Vector2d(-1e-9, 1.0)));
}

TEST_CASE("project/unproject and the pixel ray round-trip for random cameras and points") {
  SMG_TEST_RNG(rng, 71);
  for (int k = 0; k < 200; ++k) {
    const Vector3d eye = rng.vec3(3.0), target = rng.vec3(0.5);
    const Camera cam = trainer::look_at(eye, target, Vector3d::UnitZ(), 160, 120, rng.uniform(0.4, 1.5));
    const Vector3d p = target + rng.vec3(0.4);
    double z;
    const Vector2d uv = cam.project(p, &z);
    if (z < 0.05) continue;
    CHECK((cam.unproject(uv, z) - p).norm() < 1e-10 * (1 + p.norm()));
    // The ray through uv passes through p at distance |p - centre|.
    const trainer::Ray r = cam.ray(uv);
    CHECK(std::abs(r.direction.norm() - 1.0) < 1e-12);
    CHECK((r.at((p - cam.center()).norm()) - p).norm() < 1e-10 * (1 + p.norm()));
    // Depth is z in the camera, not the distance along the ray.
    CHECK(cam.to_camera(p).z() == doctest::Approx(z).epsilon(1e-12));
    CHECK((cam.to_world(cam.to_camera(p)) - p).norm() < 1e-12 * (1 + p.norm()));
  }
}

TEST_CASE("K and world_to_camera hold the pinhole model x_img ~ K [R t] X") {
  const Camera cam = trainer::look_at(Vector3d(1, -2, 1), Vector3d(0, 0, 0.2), Vector3d::UnitZ(), 160, 120, 0.8);
  const Vector3d p(0.1, 0.3, -0.2);
  const Eigen::Vector4d ph(p.x(), p.y(), p.z(), 1.0);
  const Vector3d h = cam.K() * (cam.world_to_camera * ph).head<3>();
  const Vector2d uv = cam.project(p);
  CHECK(h.x() / h.z() == doctest::Approx(uv.x()).epsilon(1e-12));
  CHECK(h.y() / h.z() == doctest::Approx(uv.y()).epsilon(1e-12));
  CHECK(cam.world_to_camera.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1)));
}
