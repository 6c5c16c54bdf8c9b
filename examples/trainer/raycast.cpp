// examples/trainer/raycast.cpp — analytic intersections and the per-pixel ray caster.
#include "trainer/raycast.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <stdexcept>

namespace trainer {

namespace {

constexpr double kTiny = 1e-12;

// Smallest root of a t^2 + 2 b t + c = 0 in (t_min, t_max) for which accept(t) holds.
template <class Accept>
bool first_root(double a, double b, double c, double t_min, double t_max, Accept accept, double* t) {
  if (std::abs(a) < kTiny) return false;
  const double disc = b * b - a * c;
  if (disc < 0) return false;
  const double s = std::sqrt(disc);
  // Numerically stable pair: q = -(b + sign(b) s); roots q / a and c / q.
  const double q = -(b + (b >= 0 ? s : -s));
  double r0 = q / a, r1 = (std::abs(q) > kTiny) ? c / q : r0;
  if (r0 > r1) std::swap(r0, r1);
  for (double r : {r0, r1})
    if (r > t_min && r < t_max && accept(r)) {
      *t = r;
      return true;
    }
  return false;
}

bool hit_sphere(const Eigen::Vector3d& center, double radius, const Ray& ray, double t_min,
                double t_max, double* t, Eigen::Vector3d* n) {
  const Eigen::Vector3d oc = ray.origin - center;
  double r;
  if (!first_root(1.0, oc.dot(ray.direction), oc.squaredNorm() - radius * radius, t_min, t_max,
                  [](double) { return true; }, &r))
    return false;
  *t = r;
  *n = (ray.at(r) - center) / radius;
  return true;
}

}  // namespace

bool intersect_shape(const Shape& shape, const Ray& ray, double t_min, double t_max,
                     double* distance, Eigen::Vector3d* normal) {
  const Eigen::Vector3d& o = ray.origin;
  const Eigen::Vector3d& d = ray.direction;
  switch (shape.kind) {
    case ShapeKind::rectangle: {
      if (std::abs(d.z()) < kTiny) return false;
      const double t = -o.z() / d.z();
      if (!(t > t_min && t < t_max)) return false;
      const Eigen::Vector3d p = ray.at(t);
      if (std::abs(p.x()) > shape.size.x() || std::abs(p.y()) > shape.size.y()) return false;
      *distance = t;
      *normal = Eigen::Vector3d::UnitZ();
      return true;
    }
    case ShapeKind::sphere:
      return hit_sphere(Eigen::Vector3d::Zero(), shape.size.x(), ray, t_min, t_max, distance, normal);
    case ShapeKind::box: {
      // Slabs: entry = max of the near planes, exit = min of the far planes.
      double t_near = -std::numeric_limits<double>::infinity(), t_far = std::numeric_limits<double>::infinity();
      int near_axis = -1, far_axis = -1;
      for (int i = 0; i < 3; ++i) {
        const double h = shape.size(i);
        if (std::abs(d(i)) < kTiny) {
          if (std::abs(o(i)) > h) return false;
          continue;
        }
        double a = (-h - o(i)) / d(i), b = (h - o(i)) / d(i);
        if (a > b) std::swap(a, b);
        if (a > t_near) { t_near = a; near_axis = i; }
        if (b < t_far) { t_far = b; far_axis = i; }
      }
      if (t_near > t_far) return false;
      if (t_near > t_min && t_near < t_max && near_axis >= 0) {
        *distance = t_near;
        *normal = Eigen::Vector3d::Zero();
        (*normal)(near_axis) = d(near_axis) > 0 ? -1.0 : 1.0;  // facing the ray
        return true;
      }
      if (t_far > t_min && t_far < t_max && far_axis >= 0) {  // origin inside: the far side
        *distance = t_far;
        *normal = Eigen::Vector3d::Zero();
        (*normal)(far_axis) = d(far_axis) > 0 ? 1.0 : -1.0;
        return true;
      }
      return false;
    }
    case ShapeKind::capsule: {
      // Union of the side of the infinite cylinder (axis x, 0 <= x <= L) and two end spheres;
      // the nearest valid hit of the three is the capsule's.
      const double L = shape.size.x(), r = shape.size.y();
      double best = t_max;
      bool found = false;
      Eigen::Vector3d n_best;
      double t;
      const double a = d.y() * d.y() + d.z() * d.z();
      const double b = o.y() * d.y() + o.z() * d.z();
      const double c = o.y() * o.y() + o.z() * o.z() - r * r;
      if (first_root(a, b, c, t_min, best,
                     [&](double s) {
                       const double x = o.x() + s * d.x();
                       return x >= 0 && x <= L;
                     },
                     &t)) {
        best = t;
        found = true;
        const Eigen::Vector3d p = ray.at(t);
        n_best = Eigen::Vector3d(0, p.y(), p.z()) / r;
      }
      for (int end = 0; end < 2; ++end) {
        const Eigen::Vector3d center(end == 0 ? 0.0 : L, 0, 0);
        // Only the outer hemisphere of each end belongs to the capsule's surface; testing both
        // roots lets a ray that first meets the inner half still find the outer one.
        const Eigen::Vector3d oc = o - center;
        double s;
        if (first_root(1.0, oc.dot(d), oc.squaredNorm() - r * r, t_min, best,
                       [&](double q) {
                         const double x = o.x() + q * d.x();
                         return end == 0 ? x <= 0 : x >= L;
                       },
                       &s)) {
          best = s;
          found = true;
          n_best = (ray.at(s) - center) / r;
        }
      }
      if (!found) return false;
      *distance = best;
      *normal = n_best;
      return true;
    }
  }
  return false;
}

namespace {
// Bounding sphere of a closed shape in its own frame (centre, radius); radius < 0: none.
std::pair<Eigen::Vector3d, double> bounding_sphere(const Shape& s) {
  switch (s.kind) {
    case ShapeKind::sphere: return {Eigen::Vector3d::Zero(), s.size.x()};
    case ShapeKind::box: return {Eigen::Vector3d::Zero(), s.size.norm()};
    case ShapeKind::capsule: return {Eigen::Vector3d(0.5 * s.size.x(), 0, 0), 0.5 * s.size.x() + s.size.y()};
    case ShapeKind::rectangle: break;
  }
  return {Eigen::Vector3d::Zero(), -1.0};
}
}  // namespace

bool intersect_scene(const Scene& scene, int t, const Ray& ray, double t_min, double t_max, Hit* hit) {
  const auto& poses = scene.poses[static_cast<std::size_t>(t)];
  bool found = false;
  double best = t_max;
  for (const Body& b : scene.bodies) {
    const Pose& P = poses[static_cast<std::size_t>(b.id)];
    // Cheap rejection: rays passing a small body's bounding sphere (most of them) skip it.
    if (const auto [c, r] = bounding_sphere(b.shape); r > 0) {
      const Eigen::Vector3d oc = P.apply(c) - ray.origin;
      const double along = oc.dot(ray.direction);
      if (oc.squaredNorm() - along * along > r * r) continue;
    }
    Ray local;
    local.origin = P.apply_inverse(ray.origin);
    local.direction = P.R.transpose() * ray.direction;  // still unit: distances are shared
    double s;
    Eigen::Vector3d n;
    if (intersect_shape(b.shape, local, t_min, best, &s, &n)) {
      best = s;
      found = true;
      hit->distance = s;
      hit->body = b.id;
      hit->local = local.at(s);
      hit->normal_local = n;
    }
  }
  if (found) {
    // Snap points onto flat faces: a texture cell boundary at z = 0 must not flicker with
    // the rounding of o.z + s d.z.
    const Body& b = scene.bodies[static_cast<std::size_t>(hit->body)];
    if (b.shape.kind == ShapeKind::rectangle) hit->local.z() = 0.0;
    if (b.shape.kind == ShapeKind::box)
      for (int i = 0; i < 3; ++i)
        if (hit->normal_local(i) != 0.0) hit->local(i) = hit->normal_local(i) * b.shape.size(i);
  } else {
    hit->body = -1;
  }
  return found;
}

bool point_visible(const Scene& scene, int t, const Camera& camera, const Eigen::Vector3d& world,
                   double rel_tolerance) {
  double z;
  const Eigen::Vector2d px = camera.project(world, &z);
  if (!(z > 1e-6) || !camera.contains(px)) return false;
  Ray ray;
  ray.origin = camera.center();
  const Eigen::Vector3d to = world - ray.origin;
  const double dist = to.norm();
  ray.direction = to / dist;
  Hit hit;
  return !intersect_scene(scene, t, ray, 0.0, dist * (1.0 - rel_tolerance), &hit);
}

RenderOutput render(const Scene& scene, int t, const Camera& camera, const RenderOptions& options) {
  if (options.supersample < 1 || options.supersample > 8)
    throw std::invalid_argument("render: supersample must be in [1, 8]");
  const int W = camera.width, H = camera.height, k = options.supersample;
  RenderOutput out;
  out.width = W;
  out.height = H;
  out.rgb = Image(W, H, 3);
  out.depth.assign(static_cast<std::size_t>(W) * H, 0.0f);
  out.body.assign(static_cast<std::size_t>(W) * H, -1);
  if (options.surface_points) out.surface.assign(static_cast<std::size_t>(W) * H * 3, 0.0f);
  const Eigen::Vector3d optical_axis = camera.rotation().row(2).transpose();
  const double inf = std::numeric_limits<double>::infinity();

  smg::parallel_for_chunks(
      H,
      [&](smg::Index, smg::Index row_begin, smg::Index row_end) {
        for (smg::Index yy = row_begin; yy < row_end; ++yy) {
          const int y = static_cast<int>(yy);
          for (int x = 0; x < W; ++x) {
            const std::size_t pix = static_cast<std::size_t>(y) * W + x;
            Hit hit;
            // Centre ray: depth, id and surface point.
            const Ray centre = camera.ray(Eigen::Vector2d(x + 0.5, y + 0.5));
            if (intersect_scene(scene, t, centre, 0.0, inf, &hit)) {
              out.depth[pix] = static_cast<float>(hit.distance * centre.direction.dot(optical_axis));
              out.body[pix] = hit.body;
              if (options.surface_points)
                for (int c = 0; c < 3; ++c) out.surface[pix * 3 + c] = static_cast<float>(hit.local(c));
            }
            // Colour: k x k stratified sub-pixel rays. For odd k the middle one is the centre ray
            // (bit for bit: (k/2 + 0.5)/k == 0.5), so its hit is reused.
            Eigen::Vector3d sum = Eigen::Vector3d::Zero();
            for (int sy = 0; sy < k; ++sy)
              for (int sx = 0; sx < k; ++sx) {
                Hit h;
                bool any;
                if (k % 2 == 1 && sx == k / 2 && sy == k / 2) {
                  h = hit;
                  any = hit.body >= 0;
                } else {
                  any = intersect_scene(scene, t, camera.ray(Eigen::Vector2d(x + (sx + 0.5) / k, y + (sy + 0.5) / k)),
                                        0.0, inf, &h);
                }
                sum += any ? surface_color(scene, h.body, h.local, h.normal_local) : scene.background;
              }
            sum /= static_cast<double>(k * k);
            for (int c = 0; c < 3; ++c) out.rgb.at(x, y, c) = static_cast<float>(sum(c));
          }
        }
      },
      options.parallel);
  return out;
}

std::vector<RenderOutput> render_training_view(const Scene& scene, const RenderOptions& options) {
  std::vector<RenderOutput> out;
  out.reserve(static_cast<std::size_t>(scene.frames()));
  for (int t = 0; t < scene.frames(); ++t)
    out.push_back(render(scene, t, scene.train_cameras[static_cast<std::size_t>(t)], options));
  return out;
}

std::vector<RenderOutput> render_test_view(const Scene& scene, int view, const RenderOptions& options) {
  if (view < 0 || view >= static_cast<int>(scene.test_cameras.size()))
    throw std::invalid_argument("render_test_view: no test view " + std::to_string(view));
  std::vector<RenderOutput> out;
  out.reserve(static_cast<std::size_t>(scene.frames()));
  for (int t = 0; t < scene.frames(); ++t)
    out.push_back(render(scene, t, scene.test_cameras[static_cast<std::size_t>(view)], options));
  return out;
}

std::vector<std::uint8_t> covisibility_mask(const Scene& scene, const std::vector<RenderOutput>& test,
                                            int min_frames, smg::ParallelOptions parallel) {
  const int T = scene.frames();
  if (static_cast<int>(test.size()) != T)
    throw std::invalid_argument("covisibility_mask: expected one test render per frame");
  if (T == 0) return {};
  const int W = test[0].width, H = test[0].height;
  for (const RenderOutput& r : test)
    if (r.surface.size() != static_cast<std::size_t>(W) * H * 3)
      throw std::invalid_argument("covisibility_mask: test renders need surface points");
  const std::size_t plane = static_cast<std::size_t>(W) * H;
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(T) * plane, 0);
  // Work item = one (frame, row); each writes only its own row.
  smg::parallel_for_chunks(
      static_cast<smg::Index>(T) * H,
      [&](smg::Index, smg::Index begin, smg::Index end) {
        for (smg::Index item = begin; item < end; ++item) {
          const int t = static_cast<int>(item / H), y = static_cast<int>(item % H);
          const RenderOutput& r = test[static_cast<std::size_t>(t)];
          for (int x = 0; x < W; ++x) {
            const std::size_t pix = static_cast<std::size_t>(y) * W + x;
            const int b = r.body[pix];
            if (b < 0) continue;
            const Eigen::Vector3d local(r.surface[pix * 3], r.surface[pix * 3 + 1], r.surface[pix * 3 + 2]);
            int seen = 0;
            // Nearest training frames first: most points are seen there and the loop stops early.
            for (int k = 0; k < 2 * T && seen < min_frames; ++k) {
              const int tt = (k % 2 == 0) ? t + k / 2 : t - (k + 1) / 2;
              if (tt < 0 || tt >= T) continue;
              const Eigen::Vector3d w = world_point(scene, b, local, tt);
              if (point_visible(scene, tt, scene.train_cameras[static_cast<std::size_t>(tt)], w, 1e-3))
                ++seen;
            }
            mask[static_cast<std::size_t>(t) * plane + pix] = seen >= min_frames ? 1 : 0;
          }
        }
      },
      parallel);
  return mask;
}

}  // namespace trainer
