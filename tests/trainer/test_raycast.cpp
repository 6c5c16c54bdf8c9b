// The analytic ray caster: exact hit distances and normals per primitive, agreement with an
// independent ray-marched signed distance, occlusion order, local hit points that map back to
// the world under the ground-truth motion, depth/id buffers, determinism, co-visibility.
#include <doctest/doctest.h>

#include <cmath>
#include <limits>

#include "fixture.hpp"
#include "support/random.hpp"
#include "trainer/raycast.hpp"

using namespace trainer;
using Eigen::Vector2d;
using Eigen::Vector3d;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

Ray ray(const Vector3d& o, const Vector3d& d) {
  Ray r;
  r.origin = o;
  r.direction = d.normalized();
  return r;
}

struct ShapeHit {
  bool hit = false;
  double t = 0;
  Vector3d n = Vector3d::Zero();
};
ShapeHit cast(const Shape& s, const Ray& r, double t_min = 0.0, double t_max = kInf) {
  ShapeHit h;
  h.hit = intersect_shape(s, r, t_min, t_max, &h.t, &h.n);
  return h;
}

// First root of the SDF along the ray by marching (step 1e-3) and bisection: an independent
// reference for the closed shapes.
ShapeHit march(const Shape& s, const Ray& r, double t_max) {
  ShapeHit h;
  const double step = 1e-3;
  double prev = 0.0;
  if (test::shape_sdf(s, r.at(prev)) <= 0) return h;  // starts inside: not used here
  for (double t = step; t < t_max; t += step) {
    const double f = test::shape_sdf(s, r.at(t));
    if (f <= 0) {
      double lo = prev, hi = t;
      for (int k = 0; k < 60; ++k) {
        const double mid = 0.5 * (lo + hi);
        (test::shape_sdf(s, r.at(mid)) > 0 ? lo : hi) = mid;
      }
      h.hit = true;
      h.t = 0.5 * (lo + hi);
      // Normal: central-difference gradient of the SDF.
      const Vector3d p = r.at(h.t);
      for (int i = 0; i < 3; ++i) {
        Vector3d e = Vector3d::Zero();
        e(i) = 1e-6;
        h.n(i) = (test::shape_sdf(s, p + e) - test::shape_sdf(s, p - e)) / 2e-6;
      }
      h.n.normalize();
      return h;
    }
    prev = t;
  }
  return h;
}

// A hand-made two-body scene (sphere in front of a rectangle) with a pose table.
Scene two_body_scene(const Vector3d& sphere_center) {
  Scene s;
  s.config.frames = 1;
  Body plane;
  plane.id = 0;
  plane.name = "plane";
  plane.shape = {ShapeKind::rectangle, {2, 2, 0}};
  Body ball;
  ball.id = 1;
  ball.name = "ball";
  ball.shape = {ShapeKind::sphere, {0.5, 0, 0}};
  s.bodies = {plane, ball};
  s.poses = {{Pose{}, Pose{Eigen::Matrix3d::Identity(), sphere_center}}};
  return s;
}

}  // namespace

TEST_CASE("sphere: analytic distances and normals, grazing, inside, miss") {
  const Shape s{ShapeKind::sphere, {1.0, 0, 0}};
  ShapeHit h = cast(s, ray({0, 0, -5}, {0, 0, 1}));
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(4.0).epsilon(1e-14));
  CHECK((h.n - Vector3d(0, 0, -1)).norm() < 1e-14);
  for (double a : {0.0, 0.3, 0.7, 0.99}) {
    h = cast(s, ray({a, 0, -5}, {0, 0, 1}));
    REQUIRE(h.hit);
    CHECK(h.t == doctest::Approx(5.0 - std::sqrt(1.0 - a * a)).epsilon(1e-12));
  }
  CHECK_FALSE(cast(s, ray({1.01, 0, -5}, {0, 0, 1})).hit);
  // From the centre: the far side, outward normal along the ray.
  h = cast(s, ray({0, 0, 0}, {0, 1, 0}));
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(1.0));
  CHECK((h.n - Vector3d(0, 1, 0)).norm() < 1e-14);
  // Behind the origin, and beyond t_max: no hit.
  CHECK_FALSE(cast(s, ray({0, 0, 5}, {0, 0, 1})).hit);
  CHECK_FALSE(cast(s, ray({0, 0, -5}, {0, 0, 1}), 0.0, 3.9).hit);
  // t_min past the entry: the exit.
  h = cast(s, ray({0, 0, -5}, {0, 0, 1}), 4.5);
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(6.0));
}

TEST_CASE("box: slab hits on every face, snapped outward normals, inside, miss") {
  const Shape s{ShapeKind::box, {1.0, 2.0, 3.0}};
  for (int axis = 0; axis < 3; ++axis)
    for (double sign : {-1.0, 1.0}) {
      Vector3d o = Vector3d(0.2, -0.3, 0.4);
      o(axis) = sign * 10.0;
      Vector3d d = Vector3d::Zero();
      d(axis) = -sign;
      const ShapeHit h = cast(s, ray(o, d));
      REQUIRE(h.hit);
      CHECK(h.t == doctest::Approx(10.0 - s.size(axis)).epsilon(1e-14));
      Vector3d n = Vector3d::Zero();
      n(axis) = sign;
      CHECK((h.n - n).norm() == 0.0);
    }
  CHECK_FALSE(cast(s, ray({1.001, 0, -10}, {0, 0, 1})).hit);
  const ShapeHit in = cast(s, ray({0, 0, 0}, {0, 0, -1}));
  REQUIRE(in.hit);
  CHECK(in.t == doctest::Approx(3.0));
  CHECK((in.n - Vector3d(0, 0, -1)).norm() == 0.0);
}

TEST_CASE("rectangle: inside and outside its bounds, parallel rays, hit from either side") {
  const Shape s{ShapeKind::rectangle, {1.0, 0.5, 0}};
  ShapeHit h = cast(s, ray({0.9, 0.4, 2}, {0, 0, -1}));
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(2.0));
  CHECK((h.n - Vector3d::UnitZ()).norm() == 0.0);
  h = cast(s, ray({0.9, 0.4, -2}, {0, 0, 1}));  // from below: same face, same normal
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(2.0));
  CHECK_FALSE(cast(s, ray({1.1, 0, 2}, {0, 0, -1})).hit);
  CHECK_FALSE(cast(s, ray({0, 0.6, 2}, {0, 0, -1})).hit);
  CHECK_FALSE(cast(s, ray({0, 0, 1}, {1, 0, 0})).hit);
  h = cast(s, ray({-3, 0, 1}, {3, 0.2, -1}));  // oblique
  REQUIRE(h.hit);
  CHECK(std::abs(ray({-3, 0, 1}, {3, 0.2, -1}).at(h.t).z()) < 1e-14);
}

TEST_CASE("capsule: side, both caps, the rim, rays along the axis") {
  const Shape s{ShapeKind::capsule, {2.0, 0.5, 0}};
  ShapeHit h = cast(s, ray({1, 0, -5}, {0, 0, 1}));
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(4.5));
  CHECK((h.n - Vector3d(0, 0, -1)).norm() < 1e-14);
  h = cast(s, ray({-5, 0, 0}, {1, 0, 0}));
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(4.5));
  CHECK((h.n - Vector3d(-1, 0, 0)).norm() < 1e-14);
  h = cast(s, ray({5, 0, 0}, {-1, 0, 0}));
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(2.5));
  CHECK((h.n - Vector3d(1, 0, 0)).norm() < 1e-14);
  // Over the start cap at x = -0.3: the sphere of radius 0.5 is at height 0.4.
  h = cast(s, ray({-0.3, 0, 5}, {0, 0, -1}));
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(4.6));
  CHECK((h.n - Vector3d(-0.3, 0, 0.4) / 0.5).norm() < 1e-12);
  // At x = 0.2 the cylinder (height 0.5) is above the cap sphere's inner half (0.458): cylinder.
  h = cast(s, ray({0.2, 0, 5}, {0, 0, -1}));
  REQUIRE(h.hit);
  CHECK(h.t == doctest::Approx(4.5));
  CHECK_FALSE(cast(s, ray({-0.51, 0, 5}, {0, 0, -1})).hit);
  CHECK_FALSE(cast(s, ray({2.51, 0, 5}, {0, 0, -1})).hit);
}

TEST_CASE("every closed primitive agrees with a ray-marched signed distance (distance and normal)") {
  SMG_TEST_RNG(rng, 5);
  const Shape shapes[] = {{ShapeKind::sphere, {0.7, 0, 0}},
                          {ShapeKind::box, {0.3, 0.6, 0.45}},
                          {ShapeKind::capsule, {1.2, 0.35, 0}}};
  for (const Shape& s : shapes) {
    int hits = 0, misses = 0;
    for (int k = 0; k < 150; ++k) {
      const Vector3d o = 3.0 * rng.unit3();
      const Vector3d aim = Vector3d(0.6, 0, 0) * (s.kind == ShapeKind::capsule) + rng.vec3(0.9);
      const Ray r = ray(o, aim - o);
      const ShapeHit a = cast(s, r), b = march(s, r, 8.0);
      CAPTURE(k);
      REQUIRE(a.hit == b.hit);
      if (!a.hit) {
        ++misses;
        continue;
      }
      ++hits;
      CHECK(a.t == doctest::Approx(b.t).epsilon(1e-9));
      // Normals agree except on a box edge, where the SDF's gradient is not defined.
      const Vector3d p = r.at(a.t);
      const bool on_box_edge =
          s.kind == ShapeKind::box && ((p.cwiseAbs() - s.size).array().abs() < 1e-4).count() > 1;
      if (!on_box_edge) CHECK((a.n - b.n).norm() < 1e-5);
    }
    CHECK(hits > 20);
    CHECK(misses > 5);
  }
}

TEST_CASE("intersect_scene: nearest body wins, misses report body -1") {
  const Scene front = two_body_scene(Vector3d(0, 0, 1.0));
  Hit hit;
  REQUIRE(intersect_scene(front, 0, ray({0, 0, 5}, {0, 0, -1}), 0.0, kInf, &hit));
  CHECK(hit.body == 1);
  CHECK(hit.distance == doctest::Approx(3.5));
  const Scene behind = two_body_scene(Vector3d(0, 0, -1.0));  // under the plane
  REQUIRE(intersect_scene(behind, 0, ray({0, 0, 5}, {0, 0, -1}), 0.0, kInf, &hit));
  CHECK(hit.body == 0);
  CHECK(hit.distance == doctest::Approx(5.0));
  CHECK(hit.local.z() == 0.0);  // snapped onto the plane
  CHECK_FALSE(intersect_scene(front, 0, ray({0, 0, 5}, {0, 0, 1}), 0.0, kInf, &hit));
  CHECK(hit.body == -1);
}

TEST_CASE("point_visible: occlusion by another body and by the body's own near side") {
  const Scene s = two_body_scene(Vector3d(0, 0, 1.0));
  const Camera cam = look_at(Vector3d(0, 0, 5), Vector3d::Zero(), Vector3d::UnitY(), 64, 64, 1.0);
  CHECK(point_visible(s, 0, cam, Vector3d(0, 0, 1.5)));         // sphere's near pole
  CHECK_FALSE(point_visible(s, 0, cam, Vector3d(0, 0, 0.5)));   // its far pole
  CHECK_FALSE(point_visible(s, 0, cam, Vector3d(0, 0, 0)));     // plane behind the sphere
  CHECK(point_visible(s, 0, cam, Vector3d(1.5, 1.5, 0)));       // plane beside it
  CHECK_FALSE(point_visible(s, 0, cam, Vector3d(0, 0, 6)));     // behind the camera
  CHECK_FALSE(point_visible(s, 0, cam, Vector3d(50, 0, 0)));    // outside the image
}

TEST_CASE("the generated scene: hit points in body frames map back to the world under the motion") {
  const Dataset& d = test::small_dataset();
  const Scene& s = d.truth->scene;
  SMG_TEST_RNG(rng, 11);
  int checked = 0;
  for (int k = 0; k < 400; ++k) {
    const int t = rng.integer(0, s.frames() - 1);
    const Camera& cam = s.train_cameras[static_cast<std::size_t>(t)];
    const Vector2d px(rng.uniform(0, s.width()), rng.uniform(0, s.height()));
    const Ray r = cam.ray(px);
    Hit hit;
    if (!intersect_scene(s, t, r, 0.0, kInf, &hit)) continue;
    ++checked;
    const Vector3d w = world_point(s, hit.body, hit.local, t);
    CHECK((w - r.at(hit.distance)).norm() < 1e-9);
    // Same point under the analytic continuous-time pose.
    CHECK((body_pose(s, hit.body, t).apply(hit.local) - w).norm() < 1e-12);
    // On the surface: |sdf| ~ 0 for closed shapes.
    const Shape& shape = s.bodies[static_cast<std::size_t>(hit.body)].shape;
    if (shape.kind != ShapeKind::rectangle) CHECK(std::abs(test::shape_sdf(shape, hit.local)) < 1e-9);
    CHECK(std::abs(hit.normal_local.norm() - 1.0) < 1e-9);
    // Projects back to the pixel.
    CHECK((cam.project(w) - px).norm() < 1e-7);
    CHECK(point_visible(s, t, cam, w));
  }
  CHECK(checked > 300);
}

TEST_CASE("render: depth and id at pixel centres agree with single rays; exact colours; thread-count independence") {
  const Dataset& d = test::small_dataset();
  const Scene& s = d.truth->scene;
  const int t = 5;
  const RenderOutput& r = d.truth->train[t];
  const Camera& cam = s.train_cameras[t];
  int hits = 0;
  for (int y = 0; y < s.height(); y += 3)
    for (int x = 0; x < s.width(); x += 3) {
      Hit hit;
      const Ray ray_c = cam.ray(Vector2d(x + 0.5, y + 0.5));
      const bool any = intersect_scene(s, t, ray_c, 0.0, kInf, &hit);
      const std::size_t pix = static_cast<std::size_t>(y) * s.width() + x;
      CHECK(r.body[pix] == (any ? hit.body : -1));
      if (!any) {
        CHECK(r.depth[pix] == 0.0f);
        continue;
      }
      ++hits;
      CHECK(r.depth[pix] == doctest::Approx(cam.to_camera(ray_c.at(hit.distance)).z()).epsilon(1e-6));
    }
  CHECK(hits > 500);

  // A uniform, unlit material renders its colour exactly (anti-aliasing averages equal values).
  Scene flat = s;
  for (Body& b : flat.bodies) {
    b.material.color_a = b.material.color_b = Vector3d(0.25, 0.5, 0.75);
    b.material.detail = 0;
  }
  flat.ambient = 1.0;
  flat.diffuse = 0.0;
  flat.background = Vector3d(0.25, 0.5, 0.75);
  RenderOptions ro;
  ro.supersample = 3;
  const RenderOutput fr = render(flat, t, cam, ro);
  double worst = 0;
  for (int y = 0; y < fr.height; ++y)
    for (int x = 0; x < fr.width; ++x)
      for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(fr.rgb.at(x, y, c) - 0.25 * (c + 1)));
  CHECK(worst < 1e-6);

  // The same bits for 1, 2 and 7 threads.
  RenderOptions o1, o2, o7;
  o1.supersample = o2.supersample = o7.supersample = test::small_config().supersample;
  o1.parallel.threads = 1;
  o2.parallel.threads = 2;
  o7.parallel.threads = 7;
  o1.surface_points = o2.surface_points = o7.surface_points = true;
  const RenderOutput a = render(s, t, cam, o1), b = render(s, t, cam, o2), c = render(s, t, cam, o7);
  CHECK(a.rgb.pixels == b.rgb.pixels);
  CHECK(a.rgb.pixels == c.rgb.pixels);
  CHECK(a.depth == c.depth);
  CHECK(a.body == c.body);
  CHECK(a.surface == c.surface);
  CHECK(a.rgb.pixels == r.rgb.pixels);  // and the same as the dataset's
}

TEST_CASE("render: anti-aliasing averages the sub-pixel rays") {
  const Dataset& d = test::small_dataset();
  const Scene& s = d.truth->scene;
  const Camera& cam = s.train_cameras[0];
  for (int k : {1, 2, 3}) {
    CAPTURE(k);
    RenderOptions ro;
    ro.supersample = k;
    const RenderOutput r = render(s, 0, cam, ro);
    // Recompute pixels by hand, on an edge (the arm is near the centre) and off it.
    for (const auto& [x, y] : {std::pair{40, 30}, {33, 28}, {5, 5}}) {
      Vector3d sum = Vector3d::Zero();
      for (int sy = 0; sy < k; ++sy)
        for (int sx = 0; sx < k; ++sx) {
          Hit h;
          if (intersect_scene(s, 0, cam.ray(Vector2d(x + (sx + 0.5) / k, y + (sy + 0.5) / k)), 0.0, kInf, &h))
            sum += surface_color(s, h.body, h.local, h.normal_local);
          else
            sum += s.background;
        }
      for (int c = 0; c < 3; ++c) CHECK(r.rgb.at(x, y, c) == doctest::Approx(sum(c) / (k * k)).epsilon(1e-6));
    }
  }
}

TEST_CASE("covisibility_mask agrees with a direct check, marks empty pixels 0 and covers most of the objects") {
  const Dataset& d = test::small_dataset();
  const Scene& s = d.truth->scene;
  REQUIRE(d.truth->test_covisible.size() == 2);
  const int W = s.width(), H = s.height(), T = s.frames();
  for (int v = 0; v < 2; ++v) {
    const auto& mask = d.truth->test_covisible[static_cast<std::size_t>(v)];
    REQUIRE(mask.size() == static_cast<std::size_t>(T) * W * H);
    long long object_px = 0, object_cov = 0, disagree = 0, checked = 0;
    for (int t = 0; t < T; t += 3)
      for (int y = 0; y < H; y += 2)
        for (int x = 0; x < W; x += 2) {
          const std::size_t pix = static_cast<std::size_t>(y) * W + x;
          const RenderOutput& r = d.truth->test[static_cast<std::size_t>(v)][static_cast<std::size_t>(t)];
          const std::uint8_t m = mask[static_cast<std::size_t>(t) * W * H + pix];
          if (r.body[pix] < 0) {
            CHECK(m == 0);
            continue;
          }
          const Vector3d local(r.surface[pix * 3], r.surface[pix * 3 + 1], r.surface[pix * 3 + 2]);
          bool seen = false;
          for (int tt = 0; tt < T && !seen; ++tt)
            seen = point_visible(s, tt, s.train_cameras[static_cast<std::size_t>(tt)],
                                 world_point(s, r.body[pix], local, tt), 1e-3);
          disagree += seen != (m == 1);
          ++checked;
          if (s.bodies[static_cast<std::size_t>(r.body[pix])].foreground) {
            ++object_px;
            object_cov += m;
          }
        }
    CHECK(disagree == 0);
    CHECK(checked > 1000);
    // Parts of the objects are never seen from the training camera (their backs), most are.
    CHECK(object_cov < object_px);
    CHECK(object_cov > object_px / 2);
  }
}
