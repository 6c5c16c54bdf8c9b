// Priors: track statistics as configured (jitter, outliers, drops, occluded-but-reported),
// visibility that matches the ground-truth occlusion, depth noise and holes, semantic features,
// lifting to smg's view layouts, determinism for any thread count.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "fixture.hpp"
#include "smg/core/validate.hpp"
#include "trainer/priors.hpp"

using namespace trainer;
using Eigen::Vector2d;
using Eigen::Vector3d;

namespace {

// Priors with every random effect off: what a perfect tracker/depth sensor would give.
PriorConfig clean_config(int tracks = 400) {
  PriorConfig c;
  c.tracks = tracks;
  c.jitter_px = 0;
  c.outlier_rate = 0;
  c.drop_rate = 0;
  c.lost_track_rate = 0;
  c.occluded_reported_rate = 0;
  c.depth_noise = 0;
  c.depth_scale_jitter = 0;
  c.depth_hole_rate = 0;
  c.depth_edge_outlier_rate = 0;
  c.depth_edge_hole_rate = 0;
  c.feature_noise = 0;
  return c;
}

// The binomial count k of n draws at rate p lies within 4.5 standard deviations of n p.
void check_rate(long long k, long long n, double p) {
  CAPTURE(k);
  CAPTURE(n);
  CAPTURE(p);
  REQUIRE(n > 100);
  const double sd = std::sqrt(n * p * (1 - p));
  CHECK(std::abs(k - n * p) <= 4.5 * sd + 1);
}

bool is_query(const Tracks& tr, int t, int i) { return tr.query_frame[static_cast<std::size_t>(i)] == t; }

}  // namespace

TEST_CASE("clean priors: reported tracks equal the truth, visibility equals ground-truth occlusion") {
  const Dataset& d = test::small_dataset();
  const Priors p = make_priors(d.truth->scene, d.truth->train, clean_config());
  const Tracks& tr = p.tracks;
  CHECK(tr.visible == tr.visible_true);
  for (std::size_t s = 0; s < tr.visible.size(); ++s) {
    if (!tr.visible[s]) {
      CHECK(tr.uv[s * 2] == -1.0);
      continue;
    }
    CHECK(tr.uv[s * 2] == tr.uv_true[s * 2]);
    CHECK(tr.uv[s * 2 + 1] == tr.uv_true[s * 2 + 1]);
  }
  // Ground-truth visibility against the rendered id buffer: a visible track point lies on its
  // body at its pixel (up to pixels straddling an edge); an occluded in-image one does not. And,
  // exactly, against the nearest hit of the camera ray through the true position.
  const int W = p.width, N = tr.count;
  long long vis = 0, vis_ok = 0, occ = 0, occ_ok = 0, ray_disagree = 0;
  for (int t = 0; t < tr.frames; ++t)
    for (int i = 0; i < N; ++i) {
      const std::size_t s = static_cast<std::size_t>(t) * N + i;
      const Vector2d uv(tr.uv_true[s * 2], tr.uv_true[s * 2 + 1]);
      if (!d.truth->scene.train_cameras[t].contains(uv) || tr.depth_true[s] <= 0) {
        CHECK(tr.visible_true[s] == 0);
        continue;
      }
      const std::size_t pix = static_cast<std::size_t>(uv.y()) * W + static_cast<std::size_t>(uv.x());
      const int id = d.truth->train[t].body[pix];
      const Camera& cam = d.truth->scene.train_cameras[t];
      const Vector3d w(tr.positions_true[s * 3], tr.positions_true[s * 3 + 1], tr.positions_true[s * 3 + 2]);
      Hit hit;
      intersect_scene(d.truth->scene, t, cam.ray(uv), 0.0, 1e9, &hit);
      const double dist = (w - cam.center()).norm();
      const bool nearest_is_point = hit.body == tr.body[i] && std::abs(hit.distance - dist) < 1e-4 * dist;
      ray_disagree += nearest_is_point != (tr.visible_true[s] == 1);
      const double z = d.truth->train[t].depth[pix];
      if (tr.visible_true[s]) {
        ++vis;
        vis_ok += id == tr.body[i];
      } else {
        ++occ;
        occ_ok += id != tr.body[i] || z < tr.depth_true[s] - 0.02;
      }
    }
  CHECK(vis > 2000);
  CHECK(occ > 100);
  CHECK(ray_disagree == 0);
  // At 96x72 the objects are a few pixels wide, so pixel centres across an edge are common.
  CHECK(static_cast<double>(vis_ok) / vis > 0.9);
  CHECK(static_cast<double>(occ_ok) / occ > 0.9);
}

TEST_CASE("track statistics follow the configuration") {
  const Dataset& d = test::small_dataset();
  PriorConfig c;
  c.tracks = 600;
  c.jitter_px = 0.8;
  c.outlier_rate = 0.08;
  c.outlier_min_px = 5;
  c.outlier_max_px = 15;
  c.drop_rate = 0.06;
  c.lost_track_rate = 0;
  c.occluded_reported_rate = 0.25;
  const Priors p = make_priors(d.truth->scene, d.truth->train, c);
  const Tracks& tr = p.tracks;
  const int N = tr.count;
  long long clean = 0, reported = 0, outliers = 0, visible = 0, dropped = 0, occluded_in_image = 0, occ_rep = 0;
  double sx = 0, sxx = 0, syy = 0;
  for (int t = 0; t < tr.frames; ++t)
    for (int i = 0; i < N; ++i) {
      const std::size_t s = static_cast<std::size_t>(t) * N + i;
      const SampleKind k = tr.kind[s];
      CHECK(tr.visible[s] == (reported_visible(k) ? 1 : 0));
      if (is_query(tr, t, i)) {
        CHECK(k == SampleKind::clean);
        CHECK(tr.uv[s * 2] == tr.uv_true[s * 2]);  // the query point is given exactly
        continue;
      }
      const double dx = tr.uv[s * 2] - tr.uv_true[s * 2], dy = tr.uv[s * 2 + 1] - tr.uv_true[s * 2 + 1];
      reported += reported_visible(k);
      if (tr.visible_true[s]) {
        ++visible;
        CHECK(k != SampleKind::hidden);
        CHECK(k != SampleKind::occluded_reported);
        dropped += k == SampleKind::dropped;
      } else {
        CHECK((k == SampleKind::hidden || k == SampleKind::occluded_reported));
        const bool in_image = tr.depth_true[s] > 0 &&
                              d.truth->scene.train_cameras[t].contains(Vector2d(tr.uv_true[s * 2], tr.uv_true[s * 2 + 1]));
        if (in_image) {
          ++occluded_in_image;
          occ_rep += k == SampleKind::occluded_reported;
        } else {
          CHECK(k == SampleKind::hidden);
        }
      }
      if (k == SampleKind::clean) {
        ++clean;
        sx += dx;
        sxx += dx * dx;
        syy += dy * dy;
      }
      if (k == SampleKind::outlier) {
        ++outliers;
        const double len = std::hypot(dx, dy);
        CHECK(len > 5 - 6 * 0.8);
        CHECK(len < 15 + 6 * 0.8);
      }
    }
  // Jitter: zero mean, per-axis RMS = jitter_px (to 4%, thousands of samples).
  REQUIRE(clean > 2000);
  CHECK(std::abs(sx / clean) < 0.1);
  CHECK(std::sqrt(sxx / clean) == doctest::Approx(0.8).epsilon(0.04));
  CHECK(std::sqrt(syy / clean) == doctest::Approx(0.8).epsilon(0.04));
  // Outliers are drawn among visible, non-dropped samples.
  check_rate(outliers, visible - dropped, 0.08);
  check_rate(dropped, visible, 0.06);
  check_rate(occ_rep, occluded_in_image, 0.25);
  const TrackStats st = track_stats(tr);
  CHECK(st.jitter_rms_px == doctest::Approx(0.8).epsilon(0.04));
  CHECK(st.outlier_fraction == doctest::Approx(static_cast<double>(outliers) / reported));
  CHECK(st.dropped_fraction == doctest::Approx(static_cast<double>(dropped) / visible));
}

TEST_CASE("lost tracks lose one contiguous run, never at the query frame") {
  const Dataset& d = test::small_dataset();
  PriorConfig c = clean_config(300);
  c.lost_track_rate = 1.0;  // every track loses a run
  const Priors p = make_priors(d.truth->scene, d.truth->train, c);
  const Tracks& tr = p.tracks;
  int with_run = 0;
  for (int i = 0; i < tr.count; ++i) {
    int runs = 0, prev = 0, len = 0;
    for (int t = 0; t < tr.frames; ++t) {
      const std::size_t s = static_cast<std::size_t>(t) * tr.count + i;
      const int lost = tr.kind[s] == SampleKind::dropped;
      if (lost && is_query(tr, t, i)) FAIL("the query sample was dropped");
      runs += lost && !prev;
      len += lost;
      prev = lost;
    }
    // A run can be split in two by the query frame (which is never lost).
    CHECK(runs <= 2);
    CHECK(len <= std::max(2, tr.frames / 3));
    with_run += len > 0;
  }
  CHECK(with_run > tr.count / 2);  // runs over frames where the point was visible show up
}

TEST_CASE("tracks start on the requested bodies; GT trajectories follow the analytic motion") {
  const Dataset& d = test::small_dataset();
  const Tracks& tr = d.priors.tracks;
  int on_objects = 0;
  for (int i = 0; i < tr.count; ++i) {
    const int b = tr.body[i];
    on_objects += d.truth->scene.bodies[b].foreground;
    const Vector3d local(tr.local[i * 3], tr.local[i * 3 + 1], tr.local[i * 3 + 2]);
    for (int t = 0; t < tr.frames; t += 4) {
      const std::size_t s = static_cast<std::size_t>(t) * tr.count + i;
      const Vector3d w(tr.positions_true[s * 3], tr.positions_true[s * 3 + 1], tr.positions_true[s * 3 + 2]);
      CHECK((w - world_point(d.truth->scene, b, local, t)).norm() < 1e-12);
      double z;
      const Vector2d uv = d.truth->scene.train_cameras[t].project(w, &z);
      CHECK(uv.x() == doctest::Approx(tr.uv_true[s * 2]));
      CHECK(z == doctest::Approx(tr.depth_true[s]));
    }
    // The query sample is the centre of a pixel on that body.
    const int q = tr.query_frame[i];
    const std::size_t s = static_cast<std::size_t>(q) * tr.count + i;
    const double u = tr.uv_true[s * 2], v = tr.uv_true[s * 2 + 1];
    CHECK(u - std::floor(u) == doctest::Approx(0.5).epsilon(1e-6));
    CHECK(v - std::floor(v) == doctest::Approx(0.5).epsilon(1e-6));
    CHECK(d.truth->train[q].body[static_cast<std::size_t>(v) * d.truth->scene.width() + static_cast<std::size_t>(u)] == b);
  }
  CHECK(on_objects == static_cast<int>(std::lround(0.8 * tr.count)));
  // Both the static box and the moving bodies carry tracks.
  for (const char* name : {"upper_arm", "forearm", "box", "ball", "floor", "wall"}) {
    CAPTURE(name);
    CHECK(std::count(tr.body.begin(), tr.body.end(), d.truth->scene.find_body(name)) >= 5);
  }
}

TEST_CASE("depth prior: relative noise as configured, holes, edges") {
  const Dataset& d = test::small_dataset();
  PriorConfig c = clean_config(50);
  c.depth_noise = 0.03;
  c.depth_hole_rate = 0.05;
  c.depth_edge_hole_rate = 0.5;
  c.depth_edge_outlier_rate = 0.5;
  const Priors p = make_priors(d.truth->scene, d.truth->train, c);
  const Priors exact = make_priors(d.truth->scene, d.truth->train, clean_config(50));
  const int W = p.width, H = p.height;
  long long interior = 0, holes = 0, edge = 0, edge_hole = 0, between = 0;
  double s1 = 0, s2 = 0;
  for (int t = 0; t < p.frames; ++t)
    for (int y = 1; y < H - 1; ++y)
      for (int x = 1; x < W - 1; ++x) {
        const std::size_t pix = static_cast<std::size_t>(y) * W + x;
        const double z = d.truth->train[t].depth[pix];
        const double zn = p.depth[static_cast<std::size_t>(t) * W * H + pix];
        CHECK(exact.depth[static_cast<std::size_t>(t) * W * H + pix] == static_cast<float>(z));
        if (z <= 0) {
          CHECK(zn == 0.0);
          continue;
        }
        bool is_edge = false;
        double lo = z, hi = z;
        for (auto [dx, dy] : {std::pair{-1, 0}, {1, 0}, {0, -1}, {0, 1}}) {
          const std::size_t q = static_cast<std::size_t>(y + dy) * W + x + dx;
          const double zq = d.truth->train[t].depth[q];
          if (d.truth->train[t].body[q] != d.truth->train[t].body[pix] || std::abs(zq - z) > 0.05 * std::max(z, zq)) {
            is_edge = true;
            if (zq > 0) {
              lo = std::min(lo, zq);
              hi = std::max(hi, zq);
            }
          }
        }
        if (is_edge) {
          ++edge;
          edge_hole += zn == 0;
          between += zn > 0 && zn >= lo * (1 - 0.2) && zn <= hi * (1 + 0.2);
          continue;
        }
        ++interior;
        if (zn == 0) {
          ++holes;
          continue;
        }
        const double rel = zn / z - 1;
        s1 += rel;
        s2 += rel * rel;
      }
  check_rate(holes, interior, 0.05);
  const double n = static_cast<double>(interior - holes);
  CHECK(std::abs(s1 / n) < 0.003);
  CHECK(std::sqrt(s2 / n) == doctest::Approx(0.03).epsilon(0.05));
  // Edge pixels: holes at >= the edge hole rate (plus the ones bordering empty space), the rest
  // between both sides of the edge (flying pixels) up to the multiplicative noise.
  REQUIRE(edge > 200);
  CHECK(static_cast<double>(edge_hole) / edge > 0.45);
  CHECK(edge_hole + between >= edge * 95 / 100);
}

TEST_CASE("depth prior: moving bodies get their own relative noise (the occluder layout's preset)") {
  DatasetConfig cfg = test::small_config(5);
  apply_scene_layout(SceneLayout::occluder, &cfg);
  CHECK(cfg.scene.layout == SceneLayout::occluder);
  CHECK(cfg.priors.moving_depth_factor == 3.0);
  const Dataset d = make_dataset(cfg);
  PriorConfig c = clean_config(50);
  c.depth_noise = 0.01;
  c.moving_depth_factor = 5.0;
  const Priors p = make_priors(d.truth->scene, d.truth->train, c);
  const int W = p.width, H = p.height;
  double s2[2] = {0, 0};
  long long n[2] = {0, 0};
  for (int t = 0; t < p.frames; ++t)
    for (int y = 1; y < H - 1; ++y)
      for (int x = 1; x < W - 1; ++x) {
        const std::size_t pix = static_cast<std::size_t>(y) * W + x;
        const double z = d.truth->train[t].depth[pix];
        if (z <= 0) continue;
        bool interior = true;  // same body and depth as the 4 neighbours: no edge treatment
        for (auto [dx, dy] : {std::pair{-1, 0}, {1, 0}, {0, -1}, {0, 1}}) {
          const std::size_t q = static_cast<std::size_t>(y + dy) * W + x + dx;
          interior = interior && d.truth->train[t].body[q] == d.truth->train[t].body[pix] &&
                     std::abs(d.truth->train[t].depth[q] - z) <= 0.05 * std::max<double>(z, d.truth->train[t].depth[q]);
        }
        const double zn = p.depth[static_cast<std::size_t>(t) * W * H + pix];
        if (!interior || zn == 0) continue;
        const int moving = d.truth->scene.bodies[static_cast<std::size_t>(d.truth->train[t].body[pix])].moves ? 1 : 0;
        s2[moving] += (zn / z - 1) * (zn / z - 1);
        ++n[moving];
      }
  REQUIRE(n[1] > 300);
  CHECK(std::sqrt(s2[0] / n[0]) == doctest::Approx(0.01).epsilon(0.1));
  CHECK(std::sqrt(s2[1] / n[1]) == doctest::Approx(0.05).epsilon(0.1));
}

TEST_CASE("semantic features: unit norm; arm links close, arm and box clearly different") {
  const Dataset& d = test::small_dataset();
  const Priors& p = d.priors;
  const int C = p.feature_dim;
  for (std::size_t k = 0; k < p.features.size() / static_cast<std::size_t>(C); k += 37) {
    double n2 = 0;
    for (int c = 0; c < C; ++c) n2 += double(p.features[k * C + c]) * p.features[k * C + c];
    CHECK(std::sqrt(n2) == doctest::Approx(1.0).epsilon(1e-5));
  }
  auto emb = [&](const char* name) {
    return Eigen::Map<const Eigen::VectorXd>(p.body_embedding.data() + d.truth->scene.find_body(name) * C, C);
  };
  CHECK(emb("upper_arm").dot(emb("forearm")) > 0.85);
  CHECK(std::abs(emb("upper_arm").dot(emb("box"))) < 0.35);
  CHECK(std::abs(emb("forearm").dot(emb("box"))) < 0.35);
  CHECK(std::abs(emb("ball").dot(emb("box"))) < 0.35);
  // Track feature samples on the arm are closer to the arm than to the box, and vice versa,
  // for most samples (patches straddling an edge blur both).
  const LiftedTracks l = lift_tracks(d.cameras, p);
  long long arm = 0, arm_ok = 0, box = 0, box_ok = 0;
  for (int t = 0; t < l.frames; ++t)
    for (int j = 0; j < l.count; ++j) {
      const std::size_t s = static_cast<std::size_t>(t) * l.count + j;
      if (!l.visible[s]) continue;
      const Eigen::Map<const Eigen::VectorXd> f(l.feature_samples.data() + s * C, C);
      CHECK(f.norm() == doctest::Approx(1.0).epsilon(1e-9));
      const double ca = f.dot(emb("forearm")), cb = f.dot(emb("box"));
      const int cls = d.truth->scene.bodies[l.body[j]].semantic_class;
      if (cls == classes::arm) {
        ++arm;
        arm_ok += ca > cb;
      } else if (cls == classes::box) {
        ++box;
        box_ok += cb > ca;
      }
    }
  REQUIRE(arm > 200);
  REQUIRE(box > 50);
  CHECK(static_cast<double>(arm_ok) / arm > 0.9);
  CHECK(static_cast<double>(box_ok) / box > 0.9);
}

TEST_CASE("object mask covers the foreground objects, dilated") {
  const Dataset& d = test::small_dataset();
  const Priors& p = d.priors;
  const int W = p.width, H = p.height;
  long long fg = 0, in_mask = 0, bg_in_mask = 0, bg = 0;
  for (int t = 0; t < p.frames; ++t)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t pix = static_cast<std::size_t>(y) * W + x;
        const int b = d.truth->train[t].body[pix];
        const bool is_fg = b >= 0 && d.truth->scene.bodies[b].foreground;
        const std::uint8_t m = p.object_mask[static_cast<std::size_t>(t) * W * H + pix];
        fg += is_fg;
        in_mask += is_fg && m;
        bg += !is_fg;
        bg_in_mask += !is_fg && m;
      }
  CHECK(in_mask == fg);
  CHECK(bg_in_mask > 0);         // the dilation
  CHECK(bg_in_mask < fg);        // by one pixel only
  CHECK(bg_in_mask < bg / 10);
}

TEST_CASE("lift_tracks: back-projection with the depth prior, smg view layouts, interpolated gaps") {
  const Dataset& d = test::small_dataset();
  // Exact priors: lifted positions match the truth up to sampling the depth at the pixel centre.
  const Priors p = make_priors(d.truth->scene, d.truth->train, clean_config(300));
  LiftOptions lo;
  lo.min_visible_frames = 1;
  const LiftedTracks l = lift_tracks(d.cameras, p, lo);
  REQUIRE(l.count == 300);
  CHECK(smg::validate_positions<double>(l.positions_view(), l.frames, l.count).is_ok());
  CHECK(smg::validate_visibility<std::uint8_t>(l.visibility_view(), l.frames, l.count).is_ok());
  CHECK(smg::validate_feature_samples<double>(l.feature_samples_view(), l.frames, l.count, p.feature_dim).is_ok());
  CHECK(smg::validate_quaternions<double>(l.rotations_true_view(), l.frames, l.count, smg::QuaternionNorm::require_unit).is_ok());
  std::vector<double> err;
  for (int t = 0; t < l.frames; ++t)
    for (int j = 0; j < l.count; ++j) {
      const std::size_t s = static_cast<std::size_t>(t) * l.count + j;
      CHECK(l.visible[s] == p.tracks.visible[static_cast<std::size_t>(t) * p.tracks.count + l.track[j]]);
      if (!l.visible[s]) continue;
      const Vector3d a(l.positions[s * 3], l.positions[s * 3 + 1], l.positions[s * 3 + 2]);
      const Vector3d b(l.positions_true[s * 3], l.positions_true[s * 3 + 1], l.positions_true[s * 3 + 2]);
      const double e = (a - b).norm();
      err.push_back(e);
      // At the query frame the reported position is a pixel centre, where the depth map is exact.
      if (p.tracks.query_frame[l.track[j]] == t) CHECK(e < 1e-5);
    }
  std::sort(err.begin(), err.end());
  REQUIRE(err.size() > 1000);
  CHECK(err[err.size() / 2] < 0.005);       // median: well under a centimetre
  CHECK(err[err.size() * 9 / 10] < 0.03);   // tail: pixels across depth edges

  // Gaps are filled linearly between lifted frames, constant outside.
  for (int j = 0; j < l.count; ++j) {
    std::vector<int> vis;
    for (int t = 0; t < l.frames; ++t)
      if (l.visible[static_cast<std::size_t>(t) * l.count + j]) vis.push_back(t);
    REQUIRE(!vis.empty());
    auto pos = [&](int t) {
      const std::size_t s = static_cast<std::size_t>(t) * l.count + j;
      return Vector3d(l.positions[s * 3], l.positions[s * 3 + 1], l.positions[s * 3 + 2]);
    };
    for (int t = 0; t < l.frames; ++t) {
      if (t < vis.front()) CHECK((pos(t) - pos(vis.front())).norm() == 0.0);
      if (t > vis.back()) CHECK((pos(t) - pos(vis.back())).norm() == 0.0);
    }
    for (std::size_t k = 0; k + 1 < vis.size(); ++k)
      for (int t = vis[k] + 1; t < vis[k + 1]; ++t) {
        const double a = double(t - vis[k]) / (vis[k + 1] - vis[k]);
        CHECK((pos(t) - ((1 - a) * pos(vis[k]) + a * pos(vis[k + 1]))).norm() < 1e-12);
      }
  }
}

TEST_CASE("lift_tracks: the filters keep the right tracks and map them back") {
  const Dataset& d = test::small_dataset();
  LiftOptions strict;
  strict.min_visible_frames = d.truth->scene.frames();
  const LiftedTracks all = lift_tracks(d.cameras, d.priors, LiftOptions{1, false});
  const LiftedTracks full = lift_tracks(d.cameras, d.priors, strict);
  CHECK(full.count < all.count);
  for (int j = 0; j < full.count; ++j) {
    int n = 0;
    for (int t = 0; t < full.frames; ++t) n += full.visible[static_cast<std::size_t>(t) * full.count + j];
    CHECK(n == full.frames);
    CHECK(full.body[j] == d.priors.tracks.body[full.track[j]]);
  }
  // The object filter uses the (dilated) object mask at the query pixel, as a pipeline would: a
  // few background tracks next to objects pass it.
  const LiftedTracks objects = lift_tracks(d.cameras, d.priors, LiftOptions{1, true});
  CHECK(objects.count < all.count);
  int on_objects = 0;
  for (int j = 0; j < objects.count; ++j) {
    const int i = objects.track[j], q = d.priors.tracks.query_frame[i];
    const std::size_t s = static_cast<std::size_t>(q) * d.priors.tracks.count + i;
    const std::size_t pix = static_cast<std::size_t>(d.priors.tracks.uv_true[s * 2 + 1]) * d.truth->scene.width() +
                            static_cast<std::size_t>(d.priors.tracks.uv_true[s * 2]);
    CHECK(d.priors.object_mask[static_cast<std::size_t>(q) * d.truth->scene.width() * d.truth->scene.height() + pix] == 1);
    on_objects += d.truth->scene.bodies[objects.body[j]].foreground;
  }
  CHECK(on_objects > objects.count * 9 / 10);
  int all_on_objects = 0;
  for (int j = 0; j < all.count; ++j) all_on_objects += d.truth->scene.bodies[all.body[j]].foreground;
  CHECK(on_objects == all_on_objects);  // no object track is lost
}

TEST_CASE("priors are deterministic for a seed and identical for 1, 2 and 7 threads") {
  const Dataset& d = test::small_dataset();
  const PriorConfig c = test::small_config().priors;
  const Priors a = make_priors(d.truth->scene, d.truth->train, c, smg::ParallelOptions{1, 0});
  const Priors b = make_priors(d.truth->scene, d.truth->train, c, smg::ParallelOptions{2, 0});
  const Priors e = make_priors(d.truth->scene, d.truth->train, c, smg::ParallelOptions{7, 0});
  for (const Priors* x : {&b, &e, &d.priors}) {
    CHECK(x->depth == a.depth);
    CHECK(x->features == a.features);
    CHECK(x->object_mask == a.object_mask);
    CHECK(x->tracks.uv == a.tracks.uv);
    CHECK(x->tracks.visible == a.tracks.visible);
    CHECK(x->tracks.body == a.tracks.body);
    CHECK(x->tracks.local == a.tracks.local);
  }
  PriorConfig other = c;
  other.seed = 1;
  const Priors f = make_priors(d.truth->scene, d.truth->train, other);
  CHECK(f.depth != a.depth);
  CHECK(f.tracks.uv != a.tracks.uv);
}

TEST_CASE("validate_prior_config rejects bad values with a clear message") {
  PriorConfig c;
  CHECK(validate_prior_config(c).is_ok());
  c.feature_dim = classes::count;  // no room for the void direction
  CHECK(validate_prior_config(c).message().find("feature_dim") != std::string::npos);
  c = PriorConfig();
  c.outlier_rate = 1.5;
  CHECK(validate_prior_config(c).message() == "priors: every rate must be in [0, 1]");
  c = PriorConfig();
  c.moving_depth_factor = std::nan("");
  CHECK(validate_prior_config(c).message() == "priors: moving_depth_factor must be in [0, 10]");
  c = PriorConfig();
  c.tracks = 0;
  CHECK(validate_prior_config(c).message().find("tracks") != std::string::npos);
  const Dataset& d = test::small_dataset();
  CHECK_THROWS_AS(make_priors(d.truth->scene, d.truth->train, c), std::invalid_argument);
  CHECK_THROWS_AS(make_priors(d.truth->scene, {}, PriorConfig()), std::invalid_argument);
}

TEST_CASE("bending layout: tracks and lifted tracks cover the arm's links, with the standard priors") {
  DatasetConfig cfg = test::small_config(2);
  apply_scene_layout(SceneLayout::bending, &cfg);
  CHECK(cfg.priors.moving_depth_factor == PriorConfig().moving_depth_factor);
  const Dataset d = make_dataset(cfg);
  std::vector<int> per_link(static_cast<std::size_t>(d.truth->scene.arm.links), 0);
  for (int b : d.priors.tracks.body) {
    const Body& body = d.truth->scene.bodies[static_cast<std::size_t>(b)];
    if (body.semantic_class == classes::arm) ++per_link[static_cast<std::size_t>(body.link)];
  }
  // Every link is tracked: the graph then has edges inside the arm across its bending joints.
  for (int n : per_link) CHECK(n >= 3);
  const LiftedTracks l = lift_tracks(d.cameras, d.priors, {3, true});
  int arm = 0;
  for (int b : l.body) arm += d.truth->scene.bodies[static_cast<std::size_t>(b)].semantic_class == classes::arm;
  CHECK(arm >= 20);
}

TEST_CASE("tracker failures: each knob measured on the generated priors (off, typical, double)") {
  DatasetConfig cfg = test::small_config(4);
  cfg.scene.frames = 16;
  cfg.scene.width = 96;
  cfg.scene.height = 72;
  cfg.priors.tracks = 1000;
  const PriorConfig typical = tracker_failures(cfg.priors, 1.0), twice = tracker_failures(cfg.priors, 2.0);
  CHECK(typical.stick_rate == 0.3);
  CHECK(twice.switch_rate == 0.1);
  CHECK(twice.moving_depth_factor == 3.0);
  CHECK(tracker_failures(cfg.priors, 0.0).occluded_reported_rate == 0.0);
  CHECK(tracker_failures(cfg.priors, 5.0).stick_rate == 1.0);  // clamped
  std::vector<TrackStats> st;
  std::vector<Dataset> ds;
  for (const TrackerFailures tf : {TrackerFailures::off, TrackerFailures::typical, TrackerFailures::twice}) {
    cfg.tracker_failures = tf;
    ds.push_back(make_dataset(cfg));
    st.push_back(track_stats(ds.back().priors.tracks));
  }
  // Off: no failure of these kinds at all.
  CHECK(st[0].occluded_visible_rate == 0.0);
  CHECK(st[0].stuck_track_rate == 0.0);
  CHECK(st[0].switched_track_rate == 0.0);
  // Typical and double: the measured rates follow the knobs (binomial noise over a few hundred
  // tracks; switches need another body within switch_radius_px, so they fall a little short).
  MESSAGE("typical: occluded visible " << st[1].occluded_visible_rate << ", stuck " << st[1].stuck_track_rate
                                       << ", switched " << st[1].switched_track_rate);
  MESSAGE("double: occluded visible " << st[2].occluded_visible_rate << ", stuck " << st[2].stuck_track_rate
                                      << ", switched " << st[2].switched_track_rate);
  CHECK(st[1].occluded_visible_rate > 0.2);
  CHECK(st[1].occluded_visible_rate < 0.4);
  CHECK(st[1].stuck_track_rate == doctest::Approx(0.3).epsilon(0.4));
  CHECK(st[2].stuck_track_rate == doctest::Approx(0.6).epsilon(0.25));
  CHECK(st[1].switched_track_rate > 0.02);
  CHECK(st[1].switched_track_rate < 0.08);
  CHECK(st[2].switched_track_rate > st[1].switched_track_rate);
  CHECK(st[2].occluded_visible_rate > 1.6 * st[1].occluded_visible_rate);
  // Failures change what is reported, never the truth; and a stuck or switched sample lies on a
  // body other than the track's own (up to the jitter at a silhouette).
  const Tracks& tr = ds[2].priors.tracks;
  CHECK(tr.positions_true == ds[0].priors.tracks.positions_true);
  CHECK(tr.visible_true == ds[0].priors.tracks.visible_true);
  // Where: without jitter a failed sample is the exact projection of the other body's visible
  // point, so the pixel holding it shows that body unless a silhouette crosses the pixel.
  cfg.priors.jitter_px = 0;
  const Dataset exact = make_dataset(cfg);
  const Tracks& tx = exact.priors.tracks;
  long long failed = 0, elsewhere = 0;
  const int W = exact.truth->scene.width(), H = exact.truth->scene.height();
  for (std::size_t s = 0; s < tx.kind.size(); ++s) {
    if (tx.kind[s] != SampleKind::stuck && tx.kind[s] != SampleKind::switched) continue;
    CHECK(tx.visible[s] == 1);
    const int t = static_cast<int>(s / static_cast<std::size_t>(tx.count));
    const int x = static_cast<int>(std::floor(tx.uv[s * 2])), y = static_cast<int>(std::floor(tx.uv[s * 2 + 1]));
    ++failed;
    REQUIRE((x >= 0 && y >= 0 && x < W && y < H));
    const int b = exact.truth->train[static_cast<std::size_t>(t)].body[static_cast<std::size_t>(y) * W + x];
    elsewhere += b != tx.body[s % static_cast<std::size_t>(tx.count)];
  }
  REQUIRE(failed > 50);
  CHECK(static_cast<double>(elsewhere) / failed > 0.9);
}
