// The procedural scene: determinism for a seed, analytic motion (joints, rotations), the arm
// never touching the box yet hiding it from the training camera at times, wide test baselines,
// extent, config validation.
#include <doctest/doctest.h>

#include <cmath>
#include <stdexcept>

#include "fixture.hpp"
#include "support/random.hpp"
#include "trainer/raycast.hpp"
#include "trainer/scene.hpp"

using namespace trainer;
using Eigen::Vector3d;

namespace {

SceneConfig config(std::uint64_t seed, int frames = 16, SceneLayout layout = SceneLayout::standard) {
  SceneConfig c;
  c.layout = layout;
  c.seed = seed;
  c.frames = frames;
  c.width = 96;
  c.height = 72;
  return c;
}

// Fraction of the box's surface samples visible from `cam` at frame t, relative to the same
// samples with the arm removed (i.e. the share the arm leaves visible).
double box_visible_share(const Scene& s, const Scene& no_arm, int t, const Camera& cam) {
  const int box = s.find_body("box");
  const Vector3d h = s.bodies[static_cast<std::size_t>(box)].shape.size;
  int with = 0, without = 0;
  for (int face = 0; face < 6; ++face)
    for (int i = 0; i < 7; ++i)
      for (int j = 0; j < 7; ++j) {
        Vector3d q;
        const int axis = face / 2;
        q(axis) = (face % 2 ? 1.0 : -1.0) * h(axis);
        q((axis + 1) % 3) = ((i + 0.5) / 7 * 2 - 1) * h((axis + 1) % 3);
        q((axis + 2) % 3) = ((j + 0.5) / 7 * 2 - 1) * h((axis + 2) % 3);
        const Vector3d w = world_point(s, box, q, t);
        if (point_visible(no_arm, t, cam, w)) {
          ++without;
          with += point_visible(s, t, cam, w);
        }
      }
  return without > 0 ? static_cast<double>(with) / without : 1.0;
}

Scene without_arm(const Scene& s) {
  Scene n = s;
  for (auto& frame : n.poses)
    for (const Body& b : n.bodies)
      if (b.semantic_class == classes::arm) frame[static_cast<std::size_t>(b.id)].t = Vector3d(100, 100, 100);
  return n;
}

}  // namespace

TEST_CASE("make_scene is deterministic for a seed and varies with it") {
  const Scene a = make_scene(config(7)), b = make_scene(config(7)), c = make_scene(config(8));
  REQUIRE(a.body_count() == b.body_count());
  bool same = true, differs = false;
  for (int t = 0; t < a.frames(); ++t)
    for (int i = 0; i < a.body_count(); ++i) {
      const Pose &pa = a.poses[t][i], &pb = b.poses[t][i], &pc = c.poses[t][i];
      same = same && pa.R == pb.R && pa.t == pb.t;
      differs = differs || !(pa.R == pc.R && pa.t == pc.t);
    }
  CHECK(same);
  CHECK(differs);
  for (int t = 0; t < a.frames(); ++t) CHECK(a.train_cameras[t].world_to_camera == b.train_cameras[t].world_to_camera);
  for (int i = 0; i < a.body_count(); ++i) {
    CHECK(a.bodies[i].material.color_a == b.bodies[i].material.color_a);
    CHECK(a.bodies[i].material.seed == b.bodies[i].material.seed);
  }
  RenderOptions ro;
  ro.supersample = 1;
  CHECK(render(a, 3, a.train_cameras[3], ro).rgb.pixels == render(b, 3, b.train_cameras[3], ro).rgb.pixels);
  CHECK(render(a, 3, a.train_cameras[3], ro).rgb.pixels != render(c, 3, c.train_cameras[3], ro).rgb.pixels);
}

TEST_CASE("the scene's bodies: names, classes, foreground and motion flags") {
  const Scene s = make_scene(config(0));
  REQUIRE(s.body_count() == 6);
  const char* names[] = {"floor", "wall", "upper_arm", "forearm", "box", "ball"};
  const int cls[] = {classes::floor, classes::wall, classes::arm, classes::arm, classes::box, classes::ball};
  const bool moves[] = {false, false, true, true, false, true};
  for (int i = 0; i < 6; ++i) {
    CHECK(s.bodies[i].name == names[i]);
    CHECK(s.bodies[i].id == i);
    CHECK(s.find_body(names[i]) == i);
    CHECK(s.bodies[i].semantic_class == cls[i]);
    CHECK(s.bodies[i].moves == moves[i]);
    CHECK(s.bodies[i].foreground == (i >= 2));
  }
  CHECK(s.find_body("nothing") == -1);
  CHECK(s.class_names.size() == static_cast<std::size_t>(classes::count));
  CHECK(s.test_cameras.size() == 2);
  CHECK(s.train_cameras.size() == 16);
}

TEST_CASE("analytic motion: rotations are proper, the elbow joint holds, the table matches body_pose") {
  const Scene s = make_scene(config(2));
  const int up = s.find_body("upper_arm"), fore = s.find_body("forearm"), ball = s.find_body("ball");
  for (double f = 0; f <= s.frames() - 1; f += 0.37) {
    for (int b = 0; b < s.body_count(); ++b) {
      const Pose p = body_pose(s, b, f);
      CHECK((p.R * p.R.transpose() - Eigen::Matrix3d::Identity()).norm() < 1e-12);
      CHECK(p.R.determinant() == doctest::Approx(1.0).epsilon(1e-12));
      const Eigen::Vector4d q = p.quaternion_wxyz();
      CHECK(q(0) >= 0);
      CHECK((Eigen::Quaterniond(q(0), q(1), q(2), q(3)).toRotationMatrix() - p.R).norm() < 1e-12);
    }
    // The forearm starts where the upper arm ends; the shoulder stays put.
    const Pose pu = body_pose(s, up, f), pf = body_pose(s, fore, f);
    CHECK((pu.apply(Vector3d(s.arm.upper_length, 0, 0)) - pf.t).norm() < 1e-12);
    CHECK((pu.t - s.arm.shoulder).norm() == 0.0);
    // The ball rests on the floor.
    CHECK(body_pose(s, ball, f).t.z() == doctest::Approx(s.ball.radius));
  }
  for (int t = 0; t < s.frames(); ++t)
    for (int b = 0; b < s.body_count(); ++b) {
      const Pose p = body_pose(s, b, t);
      CHECK(p.R == s.poses[t][b].R);
      CHECK(p.t == s.poses[t][b].t);
    }
  // The arm and the ball really move.
  CHECK((s.poses[0][fore].t - s.poses[s.frames() / 3][fore].t).norm() > 0.05);
  CHECK((s.poses[0][ball].t - s.poses[s.frames() / 3][ball].t).norm() > 0.05);
}

TEST_CASE("the bending layout: six arm links of one class, joints hold, the arm bends (not rigid)") {
  for (std::uint64_t seed : {0u, 3u}) {
    CAPTURE(seed);
    const Scene s = make_scene(config(seed, 24, SceneLayout::bending));
    std::vector<int> links;
    for (const Body& b : s.bodies)
      if (b.semantic_class == classes::arm) {
        CHECK(b.motion == Motion::arm_link);
        CHECK(b.moves);
        CHECK(b.link == static_cast<int>(links.size()));
        links.push_back(b.id);
      }
    REQUIRE(links.size() == 6);
    CHECK(s.find_body("upper_arm") == -1);
    double r_prev = 1e9;
    for (int b : links) {  // tapering: each start cap inside the previous end cap
      CHECK(s.bodies[b].shape.size.y() < r_prev);
      r_prev = s.bodies[b].shape.size.y();
    }
    const auto tip = [&](double f) {
      return body_pose(s, links.back(), f).apply(Vector3d(s.arm.link_length, 0, 0));
    };
    double dmin = 1e9, dmax = 0, curl_min = 1e9, curl_max = -1e9;
    for (double f = 0; f <= s.frames() - 1; f += 0.25) {
      for (std::size_t k = 1; k < links.size(); ++k) {
        // Link k starts where link k-1 ends.
        const Pose a = body_pose(s, links[k - 1], f), b = body_pose(s, links[k], f);
        CHECK((a.apply(Vector3d(s.arm.link_length, 0, 0)) - b.t).norm() < 1e-12);
      }
      CHECK((body_pose(s, links[0], f).t - s.arm.shoulder).norm() == 0.0);
      // Shoulder-to-tip distance and the angle between the first and last link's axes: a rigid
      // arm would keep both constant.
      const double d = (tip(f) - s.arm.shoulder).norm();
      dmin = std::min(dmin, d);
      dmax = std::max(dmax, d);
      const Vector3d x0 = body_pose(s, links.front(), f).R.col(0), x5 = body_pose(s, links.back(), f).R.col(0);
      const double curl = std::atan2(x0.cross(x5).norm(), x0.dot(x5));
      curl_min = std::min(curl_min, curl);
      curl_max = std::max(curl_max, curl);
    }
    CHECK(dmax - dmin > 0.05);            // the tube's chord changes by more than 5 cm
    CHECK(curl_max - curl_min > 0.5);     // and its curl by more than 0.5 rad
    CHECK(dmax <= 6 * s.arm.link_length + 1e-12);
  }
}

TEST_CASE("the arm never touches the box or the floor, the ball never touches the box (independent SDF check)") {
  for (const SceneLayout layout : {SceneLayout::standard, SceneLayout::occluder, SceneLayout::bending})
  for (std::uint64_t seed : {0u, 1u, 5u}) {
    CAPTURE(to_string(layout));
    CAPTURE(seed);
    const Scene s = make_scene(config(seed, 24, layout));
    CHECK(s.min_gap >= s.config.clearance);
    const int box = s.find_body("box"), ball = s.find_body("ball");
    const Shape& box_shape = s.bodies[box].shape;
    double arm_box = 1e9, arm_floor = 1e9, ball_box = 1e9;
    // Capsule = segment (+) ball of radius r, so its distance to the box is the smallest box SDF
    // along the axis minus r; sampled every millimetre, 10 times a frame.
    for (double f = 0; f <= s.frames() - 1; f += 0.1) {
      const Pose box_pose = body_pose(s, box, f);
      for (const Body& link : s.bodies) {
        if (link.semantic_class != classes::arm) continue;
        const int b = link.id;
        const Pose p = body_pose(s, b, f);
        const double L = s.bodies[b].shape.size.x(), r = s.bodies[b].shape.size.y();
        const int n = static_cast<int>(L / 0.001);
        for (int i = 0; i <= n; ++i) {
          const Vector3d w = p.apply(Vector3d(L * i / n, 0, 0));
          arm_box = std::min(arm_box, test::shape_sdf(box_shape, box_pose.apply_inverse(w)) - r);
          arm_floor = std::min(arm_floor, w.z() - r);
        }
      }
      const Pose pb = body_pose(s, ball, f);
      ball_box = std::min(ball_box, test::shape_sdf(box_shape, box_pose.apply_inverse(pb.t)) - s.ball.radius);
    }
    CHECK(arm_box >= s.config.clearance);
    // ... and passes close to it (the scene is about an arm near a static object).
    CHECK(arm_box < s.config.box_gap + 0.02);
    CHECK(arm_floor >= s.config.clearance);
    CHECK(ball_box >= s.config.clearance);
  }
}

TEST_CASE("the arm hides the box from the training camera at times; the test cameras see it") {
  for (std::uint64_t seed : {0u, 9u}) {
    CAPTURE(seed);
    const Scene s = make_scene(config(seed, 24));
    const Scene n = without_arm(s);
    double lo = 1, hi = 0, test_lo = 1;
    for (int t = 0; t < s.frames(); ++t) {
      const double share = box_visible_share(s, n, t, s.train_cameras[t]);
      lo = std::min(lo, share);
      hi = std::max(hi, share);
      for (const Camera& c : s.test_cameras) test_lo = std::min(test_lo, box_visible_share(s, n, t, c));
    }
    CHECK(lo < 0.7);   // a good part of the box is hidden in some frames
    CHECK(hi > 0.99);  // and it is in full view in others
    CHECK(test_lo > 0.9);
  }
}

TEST_CASE("test cameras are fixed at wide baselines from the moving training camera") {
  const Scene s = make_scene(config(4));
  for (const Camera& tc : s.test_cameras)
    for (const Camera& c : s.train_cameras) {
      const double cosang = c.rotation().row(2).dot(tc.rotation().row(2));
      const double deg = std::acos(cosang) * 180.0 / M_PI;
      CHECK(deg > 45.0);
      CHECK(deg < 90.0);
    }
  // The training camera moves smoothly: consecutive centres a few centimetres apart.
  for (int t = 1; t < s.frames(); ++t) {
    const double step = (s.train_cameras[t].center() - s.train_cameras[t - 1].center()).norm();
    CHECK(step > 0.001);
    CHECK(step < 0.15);
  }
}

TEST_CASE("every object is in view: most frames of the training camera and of both test cameras") {
  const Dataset& d = test::small_dataset();
  const Scene& s = d.truth->scene;
  for (int b = 0; b < s.body_count(); ++b) {
    CAPTURE(s.bodies[b].name);
    auto frames_seen = [&](const std::vector<RenderOutput>& view) {
      int n = 0;
      for (const RenderOutput& r : view) {
        int px = 0;
        for (int id : r.body) px += id == b;
        n += px >= 20;
      }
      return n;
    };
    CHECK(frames_seen(d.truth->train) >= s.frames() * 3 / 4);
    CHECK(frames_seen(d.truth->test[0]) >= s.frames() * 3 / 4);
    CHECK(frames_seen(d.truth->test[1]) >= s.frames() * 3 / 4);
  }
}

TEST_CASE("scene extent bounds the objects over all frames") {
  const Scene s = make_scene(config(1));
  CHECK(s.extent == doctest::Approx(s.object_bounds.diagonal().norm()));
  CHECK(s.extent > 1.0);
  CHECK(s.extent < 3.0);
  for (int t = 0; t < s.frames(); ++t)
    for (const Body& b : s.bodies) {
      if (!b.foreground) continue;
      // Points on the surface are inside the bounds.
      for (int k = 0; k < 20; ++k) {
        Vector3d q;
        const double a = 0.3 * k;
        switch (b.shape.kind) {
          case ShapeKind::sphere: q = b.shape.size.x() * Vector3d(std::cos(a), std::sin(a), 0); break;
          case ShapeKind::capsule: q = Vector3d(b.shape.size.x() * k / 19.0, b.shape.size.y() * std::cos(a), b.shape.size.y() * std::sin(a)); break;
          default: q = b.shape.size.cwiseProduct(Vector3d(k % 2 ? 1 : -1, k % 3 ? 1 : -1, k % 5 ? 1 : -1)); break;
        }
        CHECK(s.object_bounds.exteriorDistance(world_point(s, b.id, q, t)) < 1e-12);
      }
    }
}

TEST_CASE("appearance: view independent, in range, textured") {
  const Scene s = make_scene(config(6));
  smg::test::Rng rng(3);
  for (const Body& b : s.bodies) {
    double lo = 1, hi = 0;
    for (int k = 0; k < 400; ++k) {
      const Vector3d p = rng.vec3(0.2);
      const Vector3d c = albedo(b.material, p);
      CHECK(c.minCoeff() >= 0.0);
      CHECK(c.maxCoeff() <= 1.0);
      CHECK(albedo(b.material, p) == c);  // a pure function of the point
      lo = std::min(lo, c.mean());
      hi = std::max(hi, c.mean());
    }
    CHECK(hi - lo > 0.1);  // enough texture to fit photometrically
  }
}

TEST_CASE("extreme valid configurations build") {
  SceneConfig c = config(11, 2);
  c.clearance = 0.05;
  c.box_gap = 0.3;
  const Scene a = make_scene(c);
  CHECK(a.min_gap >= 0.05);
  CHECK(a.bodies[a.find_body("box")].rest.t.y() < 1.2 - 0.15);  // still in front of the wall
  c = config(12, 300);
  c.clearance = 0.005;
  c.box_gap = 0.005;
  const Scene b = make_scene(c);
  CHECK(b.min_gap >= 0.005);
  CHECK(b.train_cameras.size() == 300);
}

TEST_CASE("validate_scene_config names the bad field; make_scene throws its message") {
  SceneConfig c;
  c.frames = 1;
  CHECK(validate_scene_config(c).message() == "scene: frames must be in [2, 100000], got 1");
  CHECK_THROWS_AS(make_scene(c), std::invalid_argument);
  c = SceneConfig();
  c.width = 8;
  CHECK(validate_scene_config(c).message().find("image size") != std::string::npos);
  c = SceneConfig();
  c.fov_y_deg = 200;
  CHECK(validate_scene_config(c).message().find("fov_y_deg") != std::string::npos);
  c = SceneConfig();
  c.clearance = 0;
  CHECK(validate_scene_config(c).message().find("clearance") != std::string::npos);
  c = SceneConfig();
  c.box_gap = c.clearance / 2;
  CHECK(validate_scene_config(c).message().find("box_gap") != std::string::npos);
  CHECK(validate_scene_config(SceneConfig()).is_ok());
}

namespace {

// Per frame, whether a point on the forearm's tip (its end cap, facing up) is seen by the training
// camera, hidden by another body, or outside the image.
struct TipFrames {
  int seen = 0, occluded = 0, outside = 0, longest_unseen = 0;
};
TipFrames forearm_tip(const Scene& s) {
  const int fore = s.find_body("forearm");
  const Vector3d tip(s.arm.fore_length, 0, s.arm.fore_radius);
  TipFrames r;
  int run = 0;
  for (int t = 0; t < s.frames(); ++t) {
    const Camera& cam = s.train_cameras[static_cast<std::size_t>(t)];
    const Vector3d w = world_point(s, fore, tip, t);
    const bool inside = cam.contains(cam.project(w));
    const bool seen = point_visible(s, t, cam, w);
    r.seen += seen;
    r.outside += !inside;
    r.occluded += inside && !seen;
    run = seen ? 0 : run + 1;
    r.longest_unseen = std::max(r.longest_unseen, run);
  }
  return r;
}

// Share of the arm's axis-top samples (both links, 10 each) hidden by the static box in frame t.
double arm_hidden_by_box(const Scene& s, const Scene& no_box, int t) {
  const Camera& cam = s.train_cameras[static_cast<std::size_t>(t)];
  int behind = 0, total = 0;
  for (const char* link : {"upper_arm", "forearm"}) {
    const int b = s.find_body(link);
    const Body& body = s.bodies[static_cast<std::size_t>(b)];
    for (int i = 0; i < 10; ++i) {
      const Vector3d w = world_point(s, b, Vector3d(body.shape.size.x() * (i + 0.5) / 10, 0, body.shape.size.y()), t);
      if (!point_visible(no_box, t, cam, w)) continue;
      ++total;
      behind += !point_visible(s, t, cam, w);
    }
  }
  return total > 0 ? static_cast<double>(behind) / total : 0.0;
}

}  // namespace

TEST_CASE("occluder layout: the arm passes behind the pillar and the hand leaves the view, for long stretches") {
  for (std::uint64_t seed : {0u, 1u, 2u, 3u, 4u}) {
    CAPTURE(seed);
    const Scene s = make_scene(config(seed, 32, SceneLayout::occluder));
    const Scene standard = make_scene(config(seed, 32));
    // The pillar: taller than it is wide, in front of the shoulder (between the arm and the
    // training camera, whose centre is at negative y).
    const Body& box = s.bodies[static_cast<std::size_t>(s.find_body("box"))];
    CHECK(box.shape.size.z() > 1.5 * box.shape.size.x());
    CHECK(box.rest.t.y() < s.arm.shoulder.y());
    CHECK(s.train_cameras[0].center().y() < box.rest.t.y());
    // The box hides a good part of the arm in some frames (and none in the standard layout,
    // where the arm is in front of the box).
    Scene no_box = s;
    for (auto& frame : no_box.poses) frame[static_cast<std::size_t>(box.id)].t = Vector3d(100, 100, 100);
    double most = 0;
    for (int t = 0; t < s.frames(); ++t) most = std::max(most, arm_hidden_by_box(s, no_box, t));
    CHECK(most > 0.3);
    // The forearm's tip: out of the image in some frames, behind the pillar in others, and unseen
    // for at least a quarter of the sequence in one stretch, longer than in the standard layout.
    const TipFrames occ = forearm_tip(s), std_tip = forearm_tip(standard);
    MESSAGE("seed " << seed << ": arm hidden by the pillar up to " << most << "; tip seen " << occ.seen << ", outside "
                    << occ.outside << ", occluded " << occ.occluded << ", longest unseen " << occ.longest_unseen
                    << " (standard layout " << std_tip.longest_unseen << ")");
    CHECK(occ.outside >= 3);
    CHECK(occ.occluded >= 2);
    CHECK(occ.seen >= 4);
    CHECK(occ.longest_unseen >= s.frames() / 4);
    CHECK(occ.longest_unseen > std_tip.longest_unseen);
  }
}

TEST_CASE("occluder layout: the same random draws as the standard layout, and the standard layout is unchanged") {
  // Textures and the ball come from the same draws in both layouts.
  const Scene a = make_scene(config(7, 16)), b = make_scene(config(7, 16, SceneLayout::occluder));
  REQUIRE(a.body_count() == b.body_count());
  for (int k = 0; k < a.body_count(); ++k) {
    CHECK(a.bodies[k].name == b.bodies[k].name);
    CHECK(a.bodies[k].material.seed == b.bodies[k].material.seed);
  }
  CHECK(a.ball.radius_x == b.ball.radius_x);
  CHECK(a.ball.phase == b.ball.phase);
  CHECK(a.arm.phase == b.arm.phase);
  CHECK(a.arm.shoulder.y() != b.arm.shoulder.y());
  // The default config is the standard layout.
  CHECK(SceneConfig{}.layout == SceneLayout::standard);
  SceneLayout parsed = SceneLayout::standard;
  CHECK(parse_scene_layout("occluder", &parsed));
  CHECK(parsed == SceneLayout::occluder);
  CHECK_FALSE(parse_scene_layout("occluded", &parsed));
  CHECK(to_string(SceneLayout::standard) == "standard");
}
