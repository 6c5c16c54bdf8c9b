// examples/trainer/scene.cpp — scene layout, analytic motion and appearance (scene.hpp).
#include "trainer/scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "smg/core/quaternion.hpp"
#include "trainer/random.hpp"
#include "trainer/util.hpp"

namespace trainer {

namespace {

// Random streams of the scene generator (random.hpp: derive_seed).
enum : std::uint64_t { kStreamLayout = 1, kStreamTextures = 2 };

Eigen::Matrix3d rot_x(double a) {
  return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitX()).toRotationMatrix();
}
Eigen::Matrix3d rot_y(double a) {
  return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()).toRotationMatrix();
}
Eigen::Matrix3d rot_z(double a) {
  return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

double phase_u(const Scene& s, double frame) {
  return s.config.frames > 1 ? frame / static_cast<double>(s.config.frames - 1) : 0.0;
}

// ---- procedural noise ------------------------------------------------------------------
// Lattice values: a light multiply-xorshift hash (texture quality needs no more; it is the
// ray caster's inner loop).
double lattice(std::int64_t x, std::int64_t y, std::int64_t z, std::uint64_t seed) {
  std::uint64_t h = static_cast<std::uint64_t>(x) * 0x8CB92BA72F3D8DD7ull ^
                    static_cast<std::uint64_t>(y) * 0xABC98388FB8FAC03ull ^
                    static_cast<std::uint64_t>(z) * 0x9E3779B97F4A7C15ull ^ seed;
  h ^= h >> 32;
  h *= 0xD6E8FEB86659FD93ull;
  h ^= h >> 32;
  return unit_from_bits(h);
}
double fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }

// Value noise in [0, 1], C2 (quintic interpolation of a hashed lattice).
double value_noise(const Eigen::Vector3d& p, std::uint64_t seed) {
  const double fx = std::floor(p.x()), fy = std::floor(p.y()), fz = std::floor(p.z());
  const auto ix = static_cast<std::int64_t>(fx), iy = static_cast<std::int64_t>(fy),
             iz = static_cast<std::int64_t>(fz);
  const double tx = fade(p.x() - fx), ty = fade(p.y() - fy), tz = fade(p.z() - fz);
  double c[2][2][2];
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      for (int d = 0; d < 2; ++d) c[a][b][d] = lattice(ix + a, iy + b, iz + d, seed);
  auto lerp = [](double u, double v, double t) { return u + (v - u) * t; };
  const double x00 = lerp(c[0][0][0], c[1][0][0], tx), x10 = lerp(c[0][1][0], c[1][1][0], tx);
  const double x01 = lerp(c[0][0][1], c[1][0][1], tx), x11 = lerp(c[0][1][1], c[1][1][1], tx);
  return lerp(lerp(x00, x10, ty), lerp(x01, x11, ty), tz);
}
// Three octaves, weights summing to 1, so the result stays in [0, 1].
double fbm(const Eigen::Vector3d& p, std::uint64_t seed) {
  return 0.5 * value_noise(p, seed) + 0.3 * value_noise(2.03 * p, seed + 1) +
         0.2 * value_noise(4.01 * p, seed + 2);
}

Eigen::Vector3d clamp01(const Eigen::Vector3d& c) { return c.cwiseMax(0.0).cwiseMin(1.0); }

// ---- distances for the clearance check -------------------------------------------------
// A body's "core" (point, segment, box or rectangle) and the radius its surface adds.
struct Core {
  ShapeKind kind;
  Pose pose;
  Eigen::Vector3d size;
  double radius;
};
Core core_of(const Scene& s, int b, double frame) {
  const Body& body = s.bodies[static_cast<std::size_t>(b)];
  Core c{body.shape.kind, body_pose(s, b, frame), body.shape.size, 0.0};
  if (c.kind == ShapeKind::sphere) c.radius = body.shape.size.x();
  if (c.kind == ShapeKind::capsule) c.radius = body.shape.size.y();
  return c;
}
// Exact distance from a world point to a core (0 inside a box).
double point_to_core(const Core& c, const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = c.pose.apply_inverse(p);
  switch (c.kind) {
    case ShapeKind::sphere:
      return q.norm();
    case ShapeKind::capsule: {
      const double x = std::clamp(q.x(), 0.0, c.size.x());
      return (q - Eigen::Vector3d(x, 0, 0)).norm();
    }
    case ShapeKind::box:
      return (q.cwiseAbs() - c.size).cwiseMax(0.0).norm();
    case ShapeKind::rectangle: {
      const Eigen::Vector3d r(std::clamp(q.x(), -c.size.x(), c.size.x()),
                              std::clamp(q.y(), -c.size.y(), c.size.y()), 0.0);
      return (q - r).norm();
    }
  }
  return 0.0;
}

// Points along a round core (a sphere's centre, or a capsule's axis every `step` metres) and the
// slack to subtract for a certified bound: the distance to any set is 1-Lipschitz, so the true
// minimum over the axis is at most half a spacing below the sampled one.
double round_core_points(const Core& c, double step, std::vector<Eigen::Vector3d>* pts) {
  if (c.kind == ShapeKind::sphere) {
    pts->push_back(c.pose.t);
    return 0.0;
  }
  const double L = c.size.x();
  const int n = std::max(1, static_cast<int>(std::ceil(L / step)));
  for (int k = 0; k <= n; ++k) pts->push_back(c.pose.apply(Eigen::Vector3d(L * k / n, 0, 0)));
  return 0.5 * L / n;
}

void extend_bounds(const Scene& s, int b, int t, Eigen::AlignedBox3d* box) {
  const Body& body = s.bodies[static_cast<std::size_t>(b)];
  const Pose& P = s.poses[static_cast<std::size_t>(t)][static_cast<std::size_t>(b)];
  const Eigen::Vector3d one = Eigen::Vector3d::Ones();
  switch (body.shape.kind) {
    case ShapeKind::sphere:
      box->extend(P.t + body.shape.size.x() * one);
      box->extend(P.t - body.shape.size.x() * one);
      break;
    case ShapeKind::capsule: {
      const double r = body.shape.size.y();
      for (const Eigen::Vector3d& e : {P.t, P.apply(Eigen::Vector3d(body.shape.size.x(), 0, 0))}) {
        box->extend(e + r * one);
        box->extend(e - r * one);
      }
      break;
    }
    case ShapeKind::box:
      for (int k = 0; k < 8; ++k) {
        const Eigen::Vector3d corner((k & 1) ? 1 : -1, (k & 2) ? 1 : -1, (k & 4) ? 1 : -1);
        box->extend(P.apply(corner.cwiseProduct(body.shape.size)));
      }
      break;
    case ShapeKind::rectangle:
      for (int k = 0; k < 4; ++k) {
        const Eigen::Vector3d corner((k & 1) ? 1 : -1, (k & 2) ? 1 : -1, 0);
        box->extend(P.apply(corner.cwiseProduct(body.shape.size)));
      }
      break;
  }
}

Eigen::Vector3d jitter_color(Random& rng, const Eigen::Vector3d& c, double amount) {
  return clamp01(c + Eigen::Vector3d(rng.uniform(-amount, amount), rng.uniform(-amount, amount),
                                     rng.uniform(-amount, amount)));
}

// A body's material: colours a and b, each jittered by up to its amount, a scale uniform in
// [scale_lo, scale_hi] and a texture seed, drawn from tex in that order.
Material draw_material(Random& tex, Pattern pattern, const Eigen::Vector3d& a, double jitter_a,
                       const Eigen::Vector3d& b, double jitter_b, double scale_lo, double scale_hi, double detail) {
  Material m;
  m.pattern = pattern;
  m.color_a = jitter_color(tex, a, jitter_a);
  m.color_b = jitter_color(tex, b, jitter_b);
  m.scale = tex.uniform(scale_lo, scale_hi);
  m.detail = detail;
  m.seed = tex.next();
  return m;
}

// Times at which gaps are checked: motions are functions of u = frame / (T - 1), so a fixed
// number of samples in u resolves them equally for any T (at T = 32, 13 per frame).
int gap_samples(const Scene&) { return 400; }
double gap_time(const Scene& s, int k) { return (s.config.frames - 1) * static_cast<double>(k) / gap_samples(s); }

// The smallest certified gap between bodies a and b over the sequence.
double pair_min_gap(const Scene& s, int a, int b) {
  double best = std::numeric_limits<double>::infinity();
  for (int k = 0; k <= gap_samples(s); ++k) best = std::min(best, min_gap(s, a, b, gap_time(s, k)));
  return best;
}

// The smallest certified gap between a moving body and the bodies it must not touch, over the
// whole sequence. Writes the worst pair.
double sequence_min_gap(const Scene& s, int* worst_a, int* worst_b) {
  double best = std::numeric_limits<double>::infinity();
  const int n = s.body_count();
  for (int a = 0; a < n; ++a) {
    if (!s.bodies[static_cast<std::size_t>(a)].moves) continue;
    for (int b = 0; b < n; ++b) {
      if (b == a) continue;
      const Body& A = s.bodies[static_cast<std::size_t>(a)];
      const Body& B = s.bodies[static_cast<std::size_t>(b)];
      if (B.moves && b < a) continue;  // each moving pair once
      // The two arm links share the elbow joint; the ball rolls on the floor.
      if (A.semantic_class == classes::arm && B.semantic_class == classes::arm) continue;
      if ((A.semantic_class == classes::ball && B.semantic_class == classes::floor) ||
          (B.semantic_class == classes::ball && A.semantic_class == classes::floor))
        continue;
      const double g = pair_min_gap(s, a, b);
      if (g < best) {
        best = g;
        *worst_a = a;
        *worst_b = b;
      }
    }
  }
  return best;
}

}  // namespace

Eigen::Vector4d Pose::quaternion_wxyz() const {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  return smg::to_wxyz(q);
}

Eigen::Vector3d OrbitPath::eye(double u) const {
  const double w = 2 * kPi * cycles * u + phase;
  const double yaw = yaw_mean + yaw_amplitude * std::sin(w);
  const double el = elevation_mean + elevation_amplitude * std::sin(w + kPi / 3);
  return target + distance * Eigen::Vector3d(std::sin(yaw) * std::cos(el),
                                             -std::cos(yaw) * std::cos(el), std::sin(el));
}

int Scene::find_body(const std::string& name) const {
  for (const Body& b : bodies)
    if (b.name == name) return b.id;
  return -1;
}

smg::Status validate_scene_config(const SceneConfig& c) {
  auto err = [](const std::string& m) { return smg::Status::error("scene: " + m); };
  if (c.frames < 2 || c.frames > 100000)
    return err("frames must be in [2, 100000], got " + std::to_string(c.frames));
  if (c.width < 16 || c.height < 16 || c.width > 8192 || c.height > 8192)
    return err("image size must be in [16, 8192] x [16, 8192], got " + std::to_string(c.width) +
               "x" + std::to_string(c.height));
  if (!(c.fov_y_deg >= 10 && c.fov_y_deg <= 120))
    return err("fov_y_deg must be in [10, 120], got " + std::to_string(c.fov_y_deg));
  if (!(c.clearance >= 0.005 && c.clearance <= 0.05))
    return err("clearance must be in [0.005, 0.05] metres, got " + std::to_string(c.clearance));
  if (!(c.box_gap >= c.clearance && c.box_gap <= 0.3))
    return err("box_gap must be in [clearance, 0.3] metres, got " + std::to_string(c.box_gap));
  return smg::Status::ok();
}

Pose body_pose(const Scene& s, int b, double frame) {
  const Body& body = s.bodies[static_cast<std::size_t>(b)];
  const double u = phase_u(s, frame);
  switch (body.motion) {
    case Motion::fixed:
      return body.rest;
    case Motion::upper_arm:
    case Motion::forearm:
    case Motion::arm_link: {
      const ArmMotion& a = s.arm;
      const double w = 2 * kPi * a.cycles * u + a.phase;
      const double yaw = a.yaw_mean + a.yaw_amplitude * std::sin(w);
      const double pitch = a.pitch_mean + a.pitch_amplitude * std::sin(w + kPi / 2);
      const Pose upper{rot_z(yaw) * rot_y(-pitch), a.shoulder};
      if (body.motion == Motion::upper_arm) return upper;
      if (body.motion == Motion::arm_link) {
        Pose p = upper;
        for (int k = 1; k <= body.link; ++k) {
          const double bend =
              (a.elbow_mean + a.elbow_amplitude * std::sin(w - a.elbow_lag - a.wave * (k - 1))) / (a.links - 1);
          p = {p.R * rot_z(bend), p.apply(Eigen::Vector3d(a.link_length, 0, 0))};
        }
        return p;
      }
      const double elbow = a.elbow_mean + a.elbow_amplitude * std::sin(w - a.elbow_lag);
      return {upper.R * rot_z(elbow), upper.apply(Eigen::Vector3d(a.upper_length, 0, 0))};
    }
    case Motion::ball: {
      const BallMotion& m = s.ball;
      const double a = m.phase + m.direction * 2 * kPi * m.laps * u;
      const double mean_r = 0.5 * (m.radius_x + m.radius_y);
      const double rolled = mean_r * (a - m.phase) / m.radius;
      return {rot_z(a) * rot_x(-m.direction * rolled),
              m.center + Eigen::Vector3d(m.radius_x * std::cos(a), m.radius_y * std::sin(a), 0)};
    }
  }
  return body.rest;
}

Eigen::Vector3d albedo(const Material& m, const Eigen::Vector3d& p) {
  double mix = 0.0;
  switch (m.pattern) {
    case Pattern::checker: {
      // Offset so that cell boundaries never coincide with faces at round coordinates.
      const Eigen::Vector3d q = p / m.scale + Eigen::Vector3d(0.37, 0.21, 0.13);
      const auto c = static_cast<std::int64_t>(std::floor(q.x()) + std::floor(q.y()) + std::floor(q.z()));
      mix = (c % 2 == 0) ? 0.0 : 1.0;
      break;
    }
    case Pattern::stripes:
      mix = 0.5 + 0.5 * std::sin(2 * kPi * p.dot(m.stripe_axis) / m.scale);
      break;
    case Pattern::noise:
      mix = std::clamp(0.5 + 2.5 * (fbm(p / m.scale, m.seed) - 0.5), 0.0, 1.0);
      break;
  }
  const double fine = value_noise(p / (0.3 * m.scale), m.seed + 17);
  const Eigen::Vector3d c = (1 - mix) * m.color_a + mix * m.color_b;
  return clamp01(c * (1.0 + m.detail * (2.0 * fine - 1.0)));
}

Eigen::Vector3d surface_color(const Scene& s, int b, const Eigen::Vector3d& local,
                              const Eigen::Vector3d& normal_local) {
  const Body& body = s.bodies[static_cast<std::size_t>(b)];
  const double lambert = std::max(0.0, normal_local.dot(body.light_local));
  return clamp01(albedo(body.material, local) * (s.ambient + s.diffuse * lambert));
}

double min_gap(const Scene& s, int a, int b, double frame, double step) {
  Core ca = core_of(s, a, frame), cb = core_of(s, b, frame);
  const auto is_round = [](const Core& c) {
    return c.kind == ShapeKind::sphere || c.kind == ShapeKind::capsule;
  };
  if (!is_round(ca)) std::swap(ca, cb);
  if (!is_round(ca)) throw std::invalid_argument("min_gap: one body must be a sphere or a capsule");
  std::vector<Eigen::Vector3d> pts;
  const double slack = round_core_points(ca, step, &pts);
  double d = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3d& p : pts) d = std::min(d, point_to_core(cb, p));
  return std::max(0.0, d - slack - ca.radius - cb.radius);
}

Scene make_scene(const SceneConfig& config) {
  if (smg::Status st = validate_scene_config(config); !st) throw std::invalid_argument(st.message());
  Scene s;
  s.config = config;
  s.class_names = {"floor", "wall", "arm", "box", "ball"};
  Random rng(derive_seed(config.seed, kStreamLayout));
  Random tex(derive_seed(config.seed, kStreamTextures));

  auto add = [&](const std::string& name, int cls, bool foreground, Motion motion, Shape shape,
                 Material material, Pose rest) {
    Body b;
    b.id = static_cast<int>(s.bodies.size());
    b.name = name;
    b.semantic_class = cls;
    b.foreground = foreground;
    b.moves = motion != Motion::fixed;
    b.motion = motion;
    b.rest = std::move(rest);
    b.shape = std::move(shape);
    b.material = std::move(material);
    s.bodies.push_back(b);
  };

  // Floor (z = 0) and back wall (y = 1.2, facing -y), large enough that the test cameras see
  // little beyond them. The wall's local x is world x and its local y is world z, so its local +z
  // normal points to -y.
  {
    const Material m = draw_material(tex, Pattern::checker, {0.78, 0.74, 0.66}, 0.06, {0.42, 0.40, 0.38}, 0.06,
                                     0.12, 0.15, 0.18);
    add("floor", classes::floor, false, Motion::fixed, {ShapeKind::rectangle, {3.5, 3.0, 0}}, m,
        {Eigen::Matrix3d::Identity(), {0.0, -1.8, 0.0}});
  }
  {
    const Material m = draw_material(tex, Pattern::noise, {0.30, 0.45, 0.55}, 0.06, {0.75, 0.80, 0.70}, 0.06,
                                     0.10, 0.13, 0.12);
    Eigen::Matrix3d R;
    R.col(0) = Eigen::Vector3d::UnitX();
    R.col(1) = Eigen::Vector3d::UnitZ();
    R.col(2) = -Eigen::Vector3d::UnitY();
    add("wall", classes::wall, false, Motion::fixed, {ShapeKind::rectangle, {3.5, 1.2, 0}}, m,
        {R, {0.0, 1.2, 1.2}});
  }

  // Arm: two capsules from a shoulder left of the box. It swings from pointing towards the
  // training camera (the box in full view) to reaching in front of the box (hiding it).
  // Occluder layout: the shoulder sits behind the pillar's left edge and the arm sweeps about
  // 150 degrees, from pointing right (behind the pillar) through pointing at the wall to pointing
  // left, where the forearm leaves the training view; fewer cycles, so each stretch is long.
  // Both layouts draw the same random numbers in the same order.
  const bool occluder = config.layout == SceneLayout::occluder;
  const bool bending = config.layout == SceneLayout::bending;  // otherwise standard's arrangement
  s.arm.shoulder = occluder ? Eigen::Vector3d(-0.42 + rng.uniform(-0.02, 0.02), 0.32, 0.30)
                            : Eigen::Vector3d(-0.55 + rng.uniform(-0.02, 0.02), -0.02, 0.25);
  s.arm.upper_length = 0.30;
  s.arm.fore_length = 0.30;
  s.arm.upper_radius = 0.05;
  s.arm.fore_radius = 0.042;
  const double amp = rng.uniform(0.9, 1.1);
  s.arm.yaw_mean = (occluder ? kPi / 2 : -0.25) + rng.uniform(-0.03, 0.03);
  s.arm.yaw_amplitude = (occluder ? 1.3 : 0.42) * amp;
  s.arm.pitch_mean = 0.0;
  s.arm.pitch_amplitude = (occluder ? 0.06 : 0.08) * amp;
  s.arm.elbow_mean = occluder ? 0.3 : bending ? 0.6 : 0.25;
  s.arm.elbow_amplitude = (bending ? 0.9 : 0.3) * amp;
  s.arm.elbow_lag = rng.uniform(0.5, 0.9);
  const double cycles = rng.uniform(1.3, 1.7);
  s.arm.cycles = occluder ? 1.0 + 0.625 * (cycles - 1.3) : cycles;  // occluder: [1, 1.25]
  s.arm.phase = rng.uniform(0, 2 * kPi);
  {
    Material m = draw_material(tex, Pattern::stripes, {0.90, 0.55, 0.25}, 0.05, {0.55, 0.20, 0.12}, 0.05,
                               0.06, 0.08, 0.15);
    m.stripe_axis = Eigen::Vector3d(1.0, 0.35, 0.0).normalized();
    if (bending) {
      // Six links of 10 cm (the two-link arm's 60 cm), radii tapering from the upper arm's 5 cm
      // by 3 mm a link: each link's start cap lies inside the previous link's end cap, so no
      // surface belongs to two links. The wave puts about a quarter turn of phase along the tube.
      s.arm.links = 6;
      s.arm.link_length = 0.1;
      s.arm.wave = 0.45;
      for (int k = 0; k < s.arm.links; ++k) {
        if (k > 0) m.seed = tex.next();
        m.stripe_axis = Eigen::Vector3d(1.0, k % 2 ? -0.35 : 0.35, 0.0).normalized();
        add("arm_link" + std::to_string(k), classes::arm, true, Motion::arm_link,
            {ShapeKind::capsule, {s.arm.link_length, s.arm.upper_radius - 0.003 * k, 0}}, m, {});
        s.bodies.back().link = k;
      }
    } else {
      add("upper_arm", classes::arm, true, Motion::upper_arm,
          {ShapeKind::capsule, {s.arm.upper_length, s.arm.upper_radius, 0}}, m, {});
      m.seed = tex.next();
      m.stripe_axis = Eigen::Vector3d(1.0, -0.35, 0.0).normalized();
      add("forearm", classes::arm, true, Motion::forearm,
          {ShapeKind::capsule, {s.arm.fore_length, s.arm.fore_radius, 0}}, m, {});
    }
  }

  // Static box on the floor behind the arm's sweep, pushed back until the arm's closest
  // approach is config.box_gap: near enough to tempt a geometric graph, never touching.
  // Occluder layout: a tall pillar in front of the sweep (between it and the training camera),
  // pulled back towards the arm until its closest approach is config.box_gap.
  {
    const Material m = draw_material(tex, Pattern::checker, {0.15, 0.30, 0.75}, 0.05, {0.90, 0.92, 0.95}, 0.04,
                                     0.04, 0.05, 0.12);
    const double turn = rng.uniform(-0.15, 0.15);
    const double dx = rng.uniform(-0.02, 0.02);
    const Eigen::Vector3d half = occluder ? Eigen::Vector3d(0.13, 0.05, 0.26) : Eigen::Vector3d(0.1, 0.1, 0.1);
    add("box", classes::box, true, Motion::fixed, {ShapeKind::box, half}, m,
        {rot_z(occluder ? 0.5 * turn : 0.35 + turn), {0.02 + dx, occluder ? -0.3 : 0.1, half.z()}});
    // The arm's axis samples at every checked time, computed once (same samples and slack as
    // min_gap, so the result equals pair_min_gap's); then a coarse and a fine scan in y.
    Body& box = s.bodies.back();
    std::vector<Eigen::Vector3d> pts;
    std::vector<double> reach;  // radius + slack per point
    for (int k = 0; k <= gap_samples(s); ++k)
      for (const Body& link : s.bodies) {
        if (link.semantic_class != classes::arm) continue;
        const Core c = core_of(s, link.id, gap_time(s, k));
        const double slack = round_core_points(c, 0.005, &pts);
        reach.resize(pts.size(), c.radius + slack);
      }
    const auto gap_at = [&](double y) {
      Core c = core_of(s, box.id, 0.0);
      c.pose.t.y() = y;
      double g = std::numeric_limits<double>::infinity();
      for (std::size_t i = 0; i < pts.size(); ++i) g = std::min(g, point_to_core(c, pts[i]) - reach[i]);
      return std::max(0.0, g);
    };
    double y = box.rest.t.y();
    if (occluder) {
      while (y < 1.0 && gap_at(y + 0.02) >= config.box_gap) y += 0.02;
      while (y < 1.0 && gap_at(y + 0.005) >= config.box_gap) y += 0.005;
    } else {
      while (gap_at(y) < config.box_gap && y < 1.0) y += 0.02;
      for (double fine = std::max(box.rest.t.y(), y - 0.02); fine <= y; fine += 0.005)
        if (gap_at(fine) >= config.box_gap) {
          y = fine;
          break;
        }
    }
    box.rest.t.y() = y;
  }

  // Ball rolling on its own ellipse, right of the box and in front of it.
  s.ball.radius = 0.09;
  s.ball.center = Eigen::Vector3d(0.47 + rng.uniform(-0.02, 0.02), -0.15, s.ball.radius);
  s.ball.radius_x = rng.uniform(0.13, 0.16);
  s.ball.radius_y = rng.uniform(0.10, 0.13);
  s.ball.laps = rng.uniform(0.7, 1.0);
  s.ball.phase = rng.uniform(0, 2 * kPi);
  s.ball.direction = rng.uniform() < 0.5 ? -1.0 : 1.0;
  {
    const Material m = draw_material(tex, Pattern::checker, {0.85, 0.15, 0.15}, 0.05, {0.95, 0.85, 0.30}, 0.05,
                                     0.045, 0.055, 0.10);
    add("ball", classes::ball, true, Motion::ball, {ShapeKind::sphere, {s.ball.radius, 0, 0}}, m, {});
  }

  // Safety net: keep every moving body config.clearance away from everything else by shrinking
  // the offending motion. The layout above is designed to pass untouched; shrinking by more than
  // a third would change the scene's character, so that is an error.
  for (int attempt = 0;; ++attempt) {
    int a = -1, b = -1;
    s.min_gap = sequence_min_gap(s, &a, &b);
    if (s.min_gap >= config.clearance) break;
    if (attempt >= 4)
      throw std::logic_error("make_scene: " + s.bodies[static_cast<std::size_t>(a)].name + " and " +
                             s.bodies[static_cast<std::size_t>(b)].name + " come closer than the clearance");
    const auto involves = [&](int cls) {
      return s.bodies[static_cast<std::size_t>(a)].semantic_class == cls ||
             s.bodies[static_cast<std::size_t>(b)].semantic_class == cls;
    };
    if (involves(classes::arm)) {
      s.arm.yaw_amplitude *= 0.9;
      s.arm.elbow_amplitude *= 0.9;
      s.arm.pitch_amplitude *= 0.9;
    }
    if (involves(classes::ball)) {
      s.ball.radius_x *= 0.9;
      s.ball.radius_y *= 0.9;
    }
  }

  // Baked lighting: the world light expressed in each body's frame at frame 0.
  for (Body& b : s.bodies) b.light_local = body_pose(s, b.id, 0.0).R.transpose() * s.light_world;

  // Cameras: a training camera orbiting in front of the scene, two fixed test cameras far to the
  // sides (wide baselines: about 65-70 degrees of yaw from the training camera's mean direction).
  const double fov = config.fov_y_deg * kPi / 180.0;
  // Occluder layout: aimed right of the shoulder, so that the arm pointing left leaves the view.
  s.train_path.target = occluder ? Eigen::Vector3d(0.2, 0.15, 0.2) : Eigen::Vector3d(-0.04, 0.1, 0.14);
  s.train_path.distance = 1.4;
  s.train_path.yaw_mean = rng.uniform(-0.05, 0.05);
  s.train_path.yaw_amplitude = 0.26;
  s.train_path.elevation_mean = 0.5;
  s.train_path.elevation_amplitude = 0.06;
  s.train_path.cycles = 1.0;
  s.train_path.phase = rng.uniform(0, 2 * kPi);
  s.test_views = {{"test_right", 1.3, 0.62}, {"test_left", -1.35, 0.5}};

  const int T = config.frames;
  s.poses.assign(static_cast<std::size_t>(T), std::vector<Pose>(s.bodies.size()));
  s.train_cameras.resize(static_cast<std::size_t>(T));
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  for (int t = 0; t < T; ++t) {
    for (const Body& b : s.bodies)
      s.poses[static_cast<std::size_t>(t)][static_cast<std::size_t>(b.id)] = body_pose(s, b.id, t);
    s.train_cameras[static_cast<std::size_t>(t)] =
        look_at(s.train_path.eye(phase_u(s, t)), s.train_path.target, up, config.width,
                config.height, fov);
  }
  for (const TestView& v : s.test_views) {
    OrbitPath p = s.train_path;
    p.distance = 1.6;  // a little farther than the training camera: the whole scene in view
    if (occluder) {    // the whole sweep in view, the left camera well clear of the arm
      p.target = Eigen::Vector3d(-0.1, 0.15, 0.2);
      p.distance = 2.0;
    }
    p.yaw_mean = v.yaw;
    p.yaw_amplitude = 0;
    p.elevation_mean = v.elevation;
    p.elevation_amplitude = 0;
    s.test_cameras.push_back(look_at(p.eye(0.0), p.target, up, config.width, config.height, fov));
  }

  s.object_bounds.setEmpty();
  for (int t = 0; t < T; ++t)
    for (const Body& b : s.bodies)
      if (b.foreground) extend_bounds(s, b.id, t, &s.object_bounds);
  s.extent = s.object_bounds.diagonal().norm();
  return s;
}

}  // namespace trainer
