// examples/trainer/scene.hpp — the example's procedurally generated dynamic scene.
//
// A small room seen by one moving training camera and two fixed test cameras (docs/trainer.md):
//
//   floor, back wall   textured rectangles (static background)
//   arm                two capsules (upper arm, forearm) with a shoulder and an elbow joint;
//                      it swings past the static box, never touching it, and from the training
//                      camera it sometimes hides the box
//   box                a small static textured box on the floor
//   ball               a textured sphere rolling on its own path
//
// A second layout, SceneLayout::occluder (the harder scene of docs/trainer.md), keeps the bodies
// and classes but rearranges them for long unobserved stretches:
//
//   box                a tall static pillar (26 x 10 x 52 cm) between the training camera and the
//                      arm's sweep, config.box_gap in front of the arm at its closest
//   arm                swings about the shoulder from behind the pillar (hidden) through pointing
//                      at the wall to pointing left, where the forearm ("hand") leaves the
//                      training camera's view
//   ball               as before, right of the pillar
//
// and make_priors' depth is noisier on moving bodies there (apply_scene_layout in dataset.hpp).
//
// A third layout, SceneLayout::bending, is the standard scene with a flexible arm: the two links
// become a tube of ArmMotion::links short capsules (radii tapering from the shoulder), each joint
// bending about its link's z axis by the same curl split evenly, plus a wave travelling along the
// tube. Every link is class "arm", so motion inside that one semantic class is not rigid: the
// distance between two points of the arm changes over time (the case C-ARAP's confidence is meant
// for). Each link is still a rigid part, so true trajectories and visibility stay exact.
//
// World frame: z up, metres; the floor is z = 0 and the wall is the plane y = wall_y, facing -y.
// Every body is a rigid part with its own local frame; a surface point given in that frame is at
// pose(t) * p in the world at frame t (see world_point). Poses are analytic functions of the
// continuous frame time (body_pose) and are tabulated at integer frames (Scene::poses).
//
// Appearance is view independent (it depends on the surface point only), so a splatter with one
// colour per Gaussian can represent it exactly: albedo from a procedural texture in the body
// frame, times a Lambertian factor that is baked in the body frame (the light direction is fixed
// to the body at frame 0). Static bodies are therefore lit by a fixed world light; moving bodies
// carry their frame-0 shading with them.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "smg/core/status.hpp"
#include "trainer/camera.hpp"

namespace trainer {

// Rigid transform from a body frame to the world: x_world = R x_local + t.
struct Pose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  Eigen::Vector3d apply(const Eigen::Vector3d& p) const { return R * p + t; }
  Eigen::Vector3d apply_inverse(const Eigen::Vector3d& p) const { return R.transpose() * (p - t); }
  Pose inverse() const { return {R.transpose(), -(R.transpose() * t)}; }
  Pose operator*(const Pose& o) const { return {R * o.R, R * o.t + t}; }
  // Rotation as a unit quaternion in smg's memory order (w, x, y, z), w >= 0.
  Eigen::Vector4d quaternion_wxyz() const;
};

// Primitive shapes, each in its own local frame.
enum class ShapeKind {
  rectangle,  // z = 0, |x| <= size.x, |y| <= size.y; normal +z (hit from either side)
  sphere,     // centred at the origin, radius size.x
  box,        // axis aligned, half extents size
  capsule,    // segment from (0,0,0) to (size.x,0,0), radius size.y
};
struct Shape {
  ShapeKind kind = ShapeKind::sphere;
  Eigen::Vector3d size = Eigen::Vector3d::Ones();
};

// Procedural texture patterns, evaluated in the body frame (they move with the body).
enum class Pattern {
  checker,  // 3D checker of period 2*scale (hard edges; the ray caster anti-aliases them)
  stripes,  // smooth sinusoidal stripes of period scale along stripe_axis
  noise,    // value-noise fBm with feature size scale
};
struct Material {
  Pattern pattern = Pattern::checker;
  Eigen::Vector3d color_a = Eigen::Vector3d::Constant(0.2);
  Eigen::Vector3d color_b = Eigen::Vector3d::Constant(0.8);
  double scale = 0.1;                                  // metres
  Eigen::Vector3d stripe_axis = Eigen::Vector3d::UnitX();
  double detail = 0.15;  // amplitude of a fine value-noise modulation (feature size 0.3 scale), [0, 1)
  std::uint64_t seed = 0;
};

// How a body moves (the parameters live in Scene::arm and Scene::ball).
enum class Motion { fixed, upper_arm, forearm, ball, arm_link };

// Semantic classes (Scene::class_names gives their names).
namespace classes {
constexpr int floor = 0, wall = 1, arm = 2, box = 3, ball = 4;
constexpr int count = 5;
}  // namespace classes

struct Body {
  int id = 0;                 // index in Scene::bodies
  std::string name;
  int semantic_class = 0;     // classes::*
  bool foreground = false;    // an object (arm, box, ball), not floor or wall
  bool moves = false;
  Motion motion = Motion::fixed;
  int link = 0;               // Motion::arm_link: position along the bending arm, 0 at the shoulder
  Pose rest;                  // the pose of a fixed body
  Shape shape;
  Material material;
  Eigen::Vector3d light_local = Eigen::Vector3d::UnitZ();  // baked light direction, body frame
};

// Two-link arm. Angles in radians, functions of the phase w = 2 pi cycles u + phase with
// u = frame / (T - 1) in [0, 1]:
//   yaw   = yaw_mean + yaw_amplitude sin(w)                  (about world z, at the shoulder)
//   pitch = pitch_mean + pitch_amplitude sin(w + pi/2)       (raises the upper arm)
//   elbow = elbow_mean + elbow_amplitude sin(w - elbow_lag)  (about the upper arm's z axis)
// Upper arm: R1 = Rz(yaw) Ry(-pitch), origin at the shoulder. Forearm: R2 = R1 Rz(elbow), origin at
// the elbow S + R1 (upper_length, 0, 0). Each link is a capsule along its local +x; the forearm
// is thinner, so its start cap lies inside the upper arm's elbow cap and no surface belongs to
// both links (a shared surface would make a track's body, hence its motion, ambiguous).
struct ArmMotion {
  Eigen::Vector3d shoulder = Eigen::Vector3d::Zero();
  double upper_length = 0.3, fore_length = 0.3;
  double upper_radius = 0.05, fore_radius = 0.042;
  double yaw_mean = 0, yaw_amplitude = 0;
  double pitch_mean = 0, pitch_amplitude = 0;
  double elbow_mean = 0, elbow_amplitude = 0;
  double cycles = 1.5, phase = 0, elbow_lag = 0;
  // SceneLayout::bending: `links` capsules of link_length each; link k (k >= 1) starts at link
  // k-1's end, turned about its z axis by
  //   bend_k = (elbow_mean + elbow_amplitude sin(w - elbow_lag - wave (k - 1))) / (links - 1),
  // so the whole tube curls by about the elbow's angle and the curl travels along it.
  // Link 0 has the upper arm's pose. 0 links: the two-link arm above.
  int links = 0;
  double link_length = 0.1, wave = 0;
};

// Ball rolling on the floor around an ellipse: angle a = phase + direction 2 pi laps u,
// centre = center + (radius_x cos a, radius_y sin a, 0) (center.z = radius, resting on the floor),
// rotation Rz(a) Rx(-direction * rolled) with rolled = mean ellipse radius * (a - phase) / radius,
// which is rolling without slipping on a circle and close to it on the ellipse.
struct BallMotion {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double radius_x = 0.2, radius_y = 0.15, radius = 0.1;
  double laps = 1.0, phase = 0, direction = 1;
};

// A camera orbiting `target` at `distance`: yaw 0 looks along +y (from the -y side), positive yaw
// moves the camera towards +x; elevation is the angle above the horizontal.
//   yaw(u) = yaw_mean + yaw_amplitude sin(2 pi cycles u + phase)
//   elevation(u) = elevation_mean + elevation_amplitude sin(2 pi cycles u + phase + pi/3)
struct OrbitPath {
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  double distance = 2.0;
  double yaw_mean = 0, yaw_amplitude = 0;
  double elevation_mean = 0.5, elevation_amplitude = 0;
  double cycles = 1.0, phase = 0;
  Eigen::Vector3d eye(double u) const;
};

// Arrangement of the bodies (see the top of this file).
enum class SceneLayout { standard, occluder, bending };

inline const std::vector<std::string>& scene_layout_names() {
  static const std::vector<std::string> names = {"standard", "occluder", "bending"};
  return names;
}
inline std::string to_string(SceneLayout layout) { return scene_layout_names()[static_cast<std::size_t>(layout)]; }
// The layout by name; false if the name is unknown.
inline bool parse_scene_layout(const std::string& name, SceneLayout* out) {
  const auto& names = scene_layout_names();
  for (std::size_t k = 0; k < names.size(); ++k)
    if (names[k] == name) {
      *out = static_cast<SceneLayout>(k);
      return true;
    }
  return false;
}

struct SceneConfig {
  SceneLayout layout = SceneLayout::standard;
  std::uint64_t seed = 0;   // varies textures, arm swing, ball path, camera phase
  int frames = 32;          // T
  int width = 160;          // pixels, every camera
  int height = 120;
  double fov_y_deg = 50.0;  // vertical field of view of every camera
  double clearance = 0.03;  // minimum gap (metres) between moving bodies and anything else, [0.005, 0.05]
  double box_gap = 0.06;    // closest approach (metres) of the arm to the static box, [clearance, 0.3]
};

// The two test views: yaw and elevation (radians) of the fixed test cameras on the orbit.
struct TestView {
  std::string name;
  double yaw = 0, elevation = 0;
};

struct Scene {
  SceneConfig config;
  std::vector<Body> bodies;
  std::vector<std::string> class_names;  // [classes::count]
  ArmMotion arm;
  BallMotion ball;
  OrbitPath train_path;
  std::vector<TestView> test_views;

  std::vector<std::vector<Pose>> poses;  // [T][bodies], body_pose at integer frames
  std::vector<Camera> train_cameras;     // [T], the moving training camera
  std::vector<Camera> test_cameras;      // [test views], fixed over time

  Eigen::Vector3d background = Eigen::Vector3d::Zero();  // colour where a ray hits nothing
  Eigen::Vector3d light_world = Eigen::Vector3d(0.3, -0.5, 0.8).normalized();
  double ambient = 0.45, diffuse = 0.55;

  // Axis-aligned bounds of the foreground objects (arm, box, ball) over all frames, and its
  // diagonal: the "scene extent" that scales the 3D tracking thresholds (5% and 10%).
  Eigen::AlignedBox3d object_bounds;
  double extent = 0;
  // The smallest gap between a moving body and any other body over the sequence (a certified
  // lower bound in space, see min_gap; 400 samples in time), >= config.clearance.
  double min_gap = 0;

  int frames() const { return config.frames; }
  int width() const { return config.width; }
  int height() const { return config.height; }
  int body_count() const { return static_cast<int>(bodies.size()); }
  int find_body(const std::string& name) const;  // -1 if none
};

// Checks sizes and ranges ("scene: frames must be >= 2, got 1").
smg::Status validate_scene_config(const SceneConfig& config);

// Builds the scene for a seed: bodies, motions, cameras, pose table, extent. The arm and ball
// amplitudes are shrunk (deterministically) until every moving body keeps config.clearance from
// everything else at every time. Throws std::invalid_argument with validate_scene_config's
// message on a bad config.
Scene make_scene(const SceneConfig& config);

// Analytic pose of `body` at continuous frame time `frame` (0 .. T-1).
Pose body_pose(const Scene& scene, int body, double frame);

// World position at integer frame t of the point p given in the body's frame.
inline Eigen::Vector3d world_point(const Scene& scene, int body, const Eigen::Vector3d& p, int t) {
  return scene.poses[static_cast<std::size_t>(t)][static_cast<std::size_t>(body)].apply(p);
}

// Albedo of a material at a body-frame point, in [0, 1]^3.
Eigen::Vector3d albedo(const Material& material, const Eigen::Vector3d& local);

// Colour of body `body` at a body-frame surface point with body-frame outward normal: albedo times
// (ambient + diffuse max(0, n . light_local)). Independent of view and time.
Eigen::Vector3d surface_color(const Scene& scene, int body, const Eigen::Vector3d& local,
                              const Eigen::Vector3d& normal_local);

// Lower bound on the gap between the surfaces of bodies a and b at continuous time `frame`
// (0 when they touch or overlap). One of them must be a sphere or a capsule. Capsule axes are
// sampled every `step` metres and half a step is subtracted, so the bound is certified (the
// distance to a set is 1-Lipschitz).
double min_gap(const Scene& scene, int a, int b, double frame, double step = 0.005);

}  // namespace trainer
