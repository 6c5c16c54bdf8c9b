// examples/trainer/priors.cpp — tracks, depth, features and masks as a real pipeline gets them.
#include "trainer/priors.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <unordered_set>

#include "trainer/random.hpp"
#include "trainer/util.hpp"

namespace trainer {

namespace {

// Random streams (random.hpp: derive_seed); the index is the frame or the track.
enum : std::uint64_t {
  kStreamEmbedding = 101,
  kStreamFeatures = 102,
  kStreamDepth = 103,
  kStreamQueries = 104,
  kStreamTrack = 105,
  kStreamFailure = 106,  // stick and switch draws: a stream of their own, so that with both
                         // rates 0 every other draw (and every published run) is unchanged
};

std::uint64_t prior_seed(const Scene& s, const PriorConfig& c) { return mix64(s.config.seed) ^ mix64(c.seed + 0x5EEDull); }

// Orthonormal class embeddings (Gram-Schmidt on Gaussian vectors), the last one for "void".
std::vector<Eigen::VectorXd> class_embeddings(Random& rng, int count, int dim) {
  std::vector<Eigen::VectorXd> out;
  while (static_cast<int>(out.size()) < count) {
    Eigen::VectorXd v(dim);
    for (int k = 0; k < dim; ++k) v(k) = rng.normal();
    for (const auto& e : out) v -= v.dot(e) * e;
    if (v.norm() > 1e-3) out.push_back(v.normalized());
  }
  return out;
}

void feature_maps(const std::vector<RenderOutput>& train, const PriorConfig& cfg, std::uint64_t seed,
                  Priors* p, smg::ParallelOptions parallel) {
  const int T = p->frames, W = p->width, H = p->height, C = p->feature_dim, P = cfg.feature_patch;
  const int PW = (W + P - 1) / P, PH = (H + P - 1) / P;
  p->features.assign(sz(T) * H * W * C, 0.0f);
  const double noise = cfg.feature_noise / std::sqrt(static_cast<double>(C));
  smg::parallel_for_chunks(
      T,
      [&](smg::Index, smg::Index begin, smg::Index end) {
        std::vector<double> patch(sz(PW) * PH * C), f(sz(C));
        auto normalize = [C](double* v) {
          double n2 = 0;
          for (int k = 0; k < C; ++k) n2 += v[k] * v[k];
          const double inv = n2 > 0 ? 1.0 / std::sqrt(n2) : 0.0;
          for (int k = 0; k < C; ++k) v[k] *= inv;
        };
        for (smg::Index tt = begin; tt < end; ++tt) {
          const int t = static_cast<int>(tt);
          Random rng(derive_seed(seed, kStreamFeatures, sz(t)));
          const RenderOutput& r = train[sz(t)];
          // Patch features: mean embedding of the pixels in the patch, plus noise, normalised.
          for (int py = 0; py < PH; ++py)
            for (int px = 0; px < PW; ++px) {
              double* q = patch.data() + (sz(py) * PW + px) * C;
              int n = 0;
              for (int y = py * P; y < std::min(H, (py + 1) * P); ++y)
                for (int x = px * P; x < std::min(W, (px + 1) * P); ++x, ++n) {
                  const int b = r.body[sz(y) * W + x];
                  const double* e = b < 0 ? p->void_embedding.data() : p->body_embedding.data() + sz(b) * C;
                  for (int k = 0; k < C; ++k) q[k] += e[k];
                }
              for (int k = 0; k < C; ++k) q[k] = q[k] / std::max(1, n) + noise * rng.normal();
              normalize(q);
            }
          // Bilinear upsampling between patch centres, then normalise each pixel.
          for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
              const double gx = std::clamp((x + 0.5) / P - 0.5, 0.0, PW - 1.0);
              const double gy = std::clamp((y + 0.5) / P - 0.5, 0.0, PH - 1.0);
              const int x0 = std::min(static_cast<int>(gx), PW - 1), y0 = std::min(static_cast<int>(gy), PH - 1);
              const int x1 = std::min(x0 + 1, PW - 1), y1 = std::min(y0 + 1, PH - 1);
              const double ax = gx - x0, ay = gy - y0;
              const double* q00 = patch.data() + (sz(y0) * PW + x0) * C;
              const double* q01 = patch.data() + (sz(y0) * PW + x1) * C;
              const double* q10 = patch.data() + (sz(y1) * PW + x0) * C;
              const double* q11 = patch.data() + (sz(y1) * PW + x1) * C;
              for (int k = 0; k < C; ++k)
                f[sz(k)] = (1 - ax) * (1 - ay) * q00[k] + ax * (1 - ay) * q01[k] + (1 - ax) * ay * q10[k] +
                           ax * ay * q11[k];
              normalize(f.data());
              float* out = p->features.data() + ((sz(t) * H + y) * W + x) * C;
              for (int k = 0; k < C; ++k) out[k] = static_cast<float>(f[sz(k)]);
            }
          std::fill(patch.begin(), patch.end(), 0.0);
        }
      },
      parallel);
}

void depth_maps(const Scene& scene, const std::vector<RenderOutput>& train, const PriorConfig& cfg,
                std::uint64_t seed, Priors* p, smg::ParallelOptions parallel) {
  const int T = p->frames, W = p->width, H = p->height;
  std::vector<double> sigma(scene.bodies.size(), cfg.depth_noise);  // relative noise per body
  for (const Body& b : scene.bodies)
    if (b.moves) sigma[sz(b.id)] = cfg.depth_noise * cfg.moving_depth_factor;
  p->depth.assign(sz(T) * H * W, 0.0f);
  smg::parallel_for_chunks(
      T,
      [&](smg::Index, smg::Index begin, smg::Index end) {
        for (smg::Index tt = begin; tt < end; ++tt) {
          const int t = static_cast<int>(tt);
          Random rng(derive_seed(seed, kStreamDepth, sz(t)));
          const RenderOutput& r = train[sz(t)];
          const double scale = 1.0 + cfg.depth_scale_jitter * rng.normal();
          for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
              const std::size_t pix = sz(y) * W + x;
              // Draw the same number of values for every pixel so that one pixel's case does
              // not shift the noise of the next.
              const double u_edge = rng.uniform(), u_mix = rng.uniform(), u_hole = rng.uniform();
              const double n = rng.normal();
              const double z = r.depth[pix];
              if (z <= 0) continue;
              // An edge pixel has a 4-neighbour on another body or more than 5% away in depth;
              // the most different neighbour is the other side of the edge.
              double other = z;
              bool edge = false;
              const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
              for (int k = 0; k < 4; ++k) {
                if (nx[k] < 0 || ny[k] < 0 || nx[k] >= W || ny[k] >= H) continue;
                const std::size_t q = sz(ny[k]) * W + nx[k];
                const double zq = r.depth[q];
                if (r.body[q] != r.body[pix] || std::abs(zq - z) > 0.05 * std::max(z, zq)) {
                  edge = true;
                  if (std::abs(zq - z) > std::abs(other - z)) other = zq;
                }
              }
              double d = z;
              if (edge) {
                if (u_edge < cfg.depth_edge_hole_rate) continue;
                if (u_edge < cfg.depth_edge_hole_rate + cfg.depth_edge_outlier_rate) {
                  if (other <= 0) continue;  // the other side is empty space: no depth
                  d = z + u_mix * (other - z);  // a flying pixel between both sides
                }
              }
              if (u_hole < cfg.depth_hole_rate) continue;
              p->depth[sz(t) * H * W + pix] = static_cast<float>(d * scale * std::max(0.05, 1.0 + sigma[sz(r.body[pix])] * n));
            }
        }
      },
      parallel);
}

void object_mask(const Scene& scene, const std::vector<RenderOutput>& train, int dilate, Priors* p,
                 smg::ParallelOptions parallel) {
  const int T = p->frames, W = p->width, H = p->height;
  p->object_mask.assign(sz(T) * H * W, 0);
  smg::parallel_for_chunks(
      T,
      [&](smg::Index, smg::Index begin, smg::Index end) {
        for (smg::Index tt = begin; tt < end; ++tt) {
          const RenderOutput& r = train[sz(tt)];
          std::uint8_t* m = p->object_mask.data() + sz(tt) * H * W;
          for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
              const int b = r.body[sz(y) * W + x];
              if (b < 0 || !scene.bodies[sz(b)].foreground) continue;
              for (int yy = std::max(0, y - dilate); yy <= std::min(H - 1, y + dilate); ++yy)
                for (int xx = std::max(0, x - dilate); xx <= std::min(W - 1, x + dilate); ++xx)
                  m[sz(yy) * W + xx] = 1;
            }
        }
      },
      parallel);
}

// Query points: (frame, pixel) pairs drawn uniformly from the foreground-object pixels (a
// share object_fraction of the tracks) or the background pixels of all training frames, without
// repeats. The query point is the exact surface point hit by the pixel-centre ray.
void sample_queries(const Scene& scene, const std::vector<RenderOutput>& train, const PriorConfig& cfg,
                    std::uint64_t seed, Tracks* tr) {
  const int T = scene.frames(), W = scene.width(), H = scene.height();
  std::vector<std::int64_t> pools[2];  // 0: background, 1: objects; entries t * H * W + pixel
  for (int t = 0; t < T; ++t)
    for (std::size_t pix = 0; pix < sz(W) * H; ++pix) {
      const int b = train[sz(t)].body[pix];
      if (b < 0) continue;
      pools[scene.bodies[sz(b)].foreground ? 1 : 0].push_back(static_cast<std::int64_t>(sz(t) * W * H + pix));
    }
  const int n_objects = static_cast<int>(std::lround(cfg.tracks * cfg.object_fraction));
  Random rng(derive_seed(seed, kStreamQueries));
  std::unordered_set<std::int64_t> used;
  std::size_t taken[2] = {0, 0};
  for (int i = 0; i < cfg.tracks; ++i) {
    int which = i < n_objects ? 1 : 0;
    if (taken[which] >= pools[which].size()) which = 1 - which;
    const auto& pool = pools[which];
    if (taken[which] >= pool.size()) throw std::invalid_argument("priors: more tracks than visible pixels");
    ++taken[which];
    std::int64_t e;
    do {
      e = pool[sz(rng.below(static_cast<std::int64_t>(pool.size())))];
    } while (!used.insert(e).second);
    const int t = static_cast<int>(e / (static_cast<std::int64_t>(W) * H));
    const int pix = static_cast<int>(e % (static_cast<std::int64_t>(W) * H));
    const Camera& cam = scene.train_cameras[sz(t)];
    Hit hit;
    const int row = pix / W;  // integer division intended: the pixel's row
    intersect_scene(scene, t, cam.ray(Eigen::Vector2d(pix % W + 0.5, row + 0.5)), 0.0,
                    std::numeric_limits<double>::infinity(), &hit);
    tr->body.push_back(hit.body);
    for (int c = 0; c < 3; ++c) tr->local.push_back(hit.local(c));
    tr->query_frame.push_back(t);
  }
}

// The body and body-frame point seen at pixel position uv of the training camera at frame t
// (the nearest surface along the ray); false if the ray hits nothing.
bool surface_at(const Scene& scene, int t, const Eigen::Vector2d& uv, int* body, Eigen::Vector3d* local) {
  Hit hit;
  if (!intersect_scene(scene, t, scene.train_cameras[sz(t)].ray(uv), 0.0, std::numeric_limits<double>::infinity(),
                       &hit) || hit.body < 0)
    return false;
  *body = hit.body;
  *local = hit.local;
  return true;
}

// Where an identity switch lands: the pixel nearest to uv (within radius_px, in the training
// render of frame t) whose body is neither `body` nor empty, scanned ring by ring in a fixed
// order; false if there is none.
bool switch_target(const Scene& scene, const RenderOutput& r, int t, const Eigen::Vector2d& uv, int body,
                   double radius_px, int* other, Eigen::Vector3d* local) {
  const int W = r.width, H = r.height;
  const int cx = static_cast<int>(std::floor(uv.x())), cy = static_cast<int>(std::floor(uv.y()));
  const int R = static_cast<int>(std::ceil(radius_px));
  double best = std::numeric_limits<double>::infinity();
  Eigen::Vector2d pick = Eigen::Vector2d::Zero();
  for (int y = cy - R; y <= cy + R; ++y)
    for (int x = cx - R; x <= cx + R; ++x) {
      if (x < 0 || y < 0 || x >= W || y >= H) continue;
      const int b = r.body[sz(y) * W + x];
      if (b < 0 || b == body) continue;
      const Eigen::Vector2d c(x + 0.5, y + 0.5);
      const double d = (c - uv).norm();
      if (d <= radius_px && d < best) {
        best = d;
        pick = c;
      }
    }
  return best < std::numeric_limits<double>::infinity() && surface_at(scene, t, pick, other, local);
}

void follow_tracks(const Scene& scene, const std::vector<RenderOutput>& train, const PriorConfig& cfg,
                   std::uint64_t seed, Tracks* tr, smg::ParallelOptions parallel) {
  const int T = tr->frames, N = tr->count;
  tr->uv_true.assign(sz(T) * N * 2, 0.0);
  tr->depth_true.assign(sz(T) * N, 0.0);
  tr->visible_true.assign(sz(T) * N, 0);
  tr->in_image_true.assign(sz(T) * N, 0);
  tr->occluder_true.assign(sz(T) * N, -1);
  tr->positions_true.assign(sz(T) * N * 3, 0.0);
  tr->rotations_true.assign(sz(T) * N * 4, 0.0);
  tr->uv.assign(sz(T) * N * 2, -1.0);
  tr->visible.assign(sz(T) * N, 0);
  tr->kind.assign(sz(T) * N, SampleKind::hidden);
  smg::parallel_for_chunks(
      N,
      [&](smg::Index, smg::Index begin, smg::Index end) {
        for (smg::Index ii = begin; ii < end; ++ii) {
          const int i = static_cast<int>(ii);
          Random rng(derive_seed(seed, kStreamTrack, sz(i)));
          const int b = tr->body[sz(i)], q = tr->query_frame[sz(i)];
          const Eigen::Vector3d local(tr->local[sz(i) * 3], tr->local[sz(i) * 3 + 1], tr->local[sz(i) * 3 + 2]);
          // A lost run: 2 .. max(2, T/3) consecutive frames, never the query frame.
          int lost_begin = 0, lost_end = 0;
          const double u_lost = rng.uniform();
          const int run = 2 + static_cast<int>(rng.below(std::max(1, T / 3 - 1)));
          const int start = static_cast<int>(rng.below(T));
          if (u_lost < cfg.lost_track_rate) {
            lost_begin = start;
            lost_end = std::min(T, start + run);
          }
          // Failures (their own stream): a sticking track follows the occluder's surface point
          // seen where its own point went hidden, for as long as its point stays hidden in the
          // image; a switching track follows a neighbouring body's point for frames
          // [switch_begin, switch_end), from the pixel nearest its true position.
          Random frng(derive_seed(seed, kStreamFailure, sz(i)));
          const bool sticks = frng.uniform() < cfg.stick_rate;
          const bool switches = frng.uniform() < cfg.switch_rate;
          const int switch_begin = static_cast<int>(frng.below(T));
          const int switch_end = std::min(T, switch_begin + 2 + static_cast<int>(frng.below(std::max(1, T / 4 - 1))));
          int stuck_body = -1, switch_body = -1;
          Eigen::Vector3d stuck_local = Eigen::Vector3d::Zero(), switch_local = Eigen::Vector3d::Zero();
          for (int t = 0; t < T; ++t) {
            const std::size_t s = sz(t) * N + i;
            const Pose& P = scene.poses[sz(t)][sz(b)];
            const Eigen::Vector3d w = P.apply(local);
            const Eigen::Vector4d qw = P.quaternion_wxyz();
            for (int c = 0; c < 3; ++c) tr->positions_true[s * 3 + c] = w(c);
            for (int c = 0; c < 4; ++c) tr->rotations_true[s * 4 + c] = qw(c);
            const Camera& cam = scene.train_cameras[sz(t)];
            double z;
            const Eigen::Vector2d uv = cam.project(w, &z);
            tr->depth_true[s] = z;
            tr->uv_true[s * 2] = uv.x();
            tr->uv_true[s * 2 + 1] = uv.y();
            const bool in_image = z > 1e-6 && cam.contains(uv);
            const bool vis = t == q || point_visible(scene, t, cam, w);
            tr->visible_true[s] = vis ? 1 : 0;
            tr->in_image_true[s] = in_image ? 1 : 0;
            // Fixed number of draws per sample (see depth_maps).
            const double u_drop = rng.uniform(), u_out = rng.uniform(), u_occ = rng.uniform();
            const double jx = rng.normal(), jy = rng.normal();
            const double jump_len = rng.uniform(cfg.outlier_min_px, cfg.outlier_max_px);
            const double jump_dir = rng.uniform(0, 2 * kPi);
            Eigen::Vector2d rep = uv + cfg.jitter_px * Eigen::Vector2d(jx, jy);
            SampleKind k = SampleKind::hidden;
            if (t == q) {
              k = SampleKind::clean;
              rep = uv;  // the tracker is given its query point
            } else if (vis) {
              const bool lost = t >= lost_begin && t < lost_end;
              if (lost || u_drop < cfg.drop_rate) {
                k = SampleKind::dropped;
              } else if (u_out < cfg.outlier_rate) {
                k = SampleKind::outlier;
                rep += jump_len * Eigen::Vector2d(std::cos(jump_dir), std::sin(jump_dir));
              } else {
                k = SampleKind::clean;
              }
            } else if (in_image && u_occ < cfg.occluded_reported_rate &&
                       !(t >= lost_begin && t < lost_end)) {
              k = SampleKind::occluded_reported;
            }
            // The body in front of a point hidden in the image (its own body when it turned away).
            int occluder = -1;
            Eigen::Vector3d occluder_local = Eigen::Vector3d::Zero();
            if (!vis && in_image && surface_at(scene, t, uv, &occluder, &occluder_local) && occluder == b) occluder = -1;
            tr->occluder_true[s] = occluder;
            // Sticking: on the first frame the point is hidden behind another body, take that
            // body's point at the true position; report it (projected, with jitter) while hidden.
            if (sticks && t != q) {
              if (!vis && in_image) {
                if (stuck_body < 0 && occluder >= 0) {
                  stuck_body = occluder;
                  stuck_local = occluder_local;
                }
                if (stuck_body >= 0) {
                  const Eigen::Vector3d o = world_point(scene, stuck_body, stuck_local, t);
                  double zo;
                  const Eigen::Vector2d uo = cam.project(o, &zo);
                  if (zo > 1e-6 && cam.contains(uo) && point_visible(scene, t, cam, o)) {
                    k = SampleKind::stuck;
                    rep = uo + cfg.jitter_px * Eigen::Vector2d(jx, jy);
                  } else if (k != SampleKind::occluded_reported) {
                    k = SampleKind::hidden;
                  }
                }
              } else {
                stuck_body = -1;  // visible again (or out of the image): the next hiding starts afresh
              }
            }
            // Switching: the first frame of the stretch picks the neighbouring body's point.
            if (switches && t >= switch_begin && t < switch_end && t != q) {
              if (t == switch_begin || switch_body < 0) {
                if (!(in_image && switch_target(scene, train[sz(t)], t, uv, b, cfg.switch_radius_px, &switch_body,
                                                &switch_local)))
                  switch_body = -1;
              }
              if (switch_body >= 0) {
                const Eigen::Vector3d o = world_point(scene, switch_body, switch_local, t);
                double zo;
                const Eigen::Vector2d uo = cam.project(o, &zo);
                const bool seen = zo > 1e-6 && cam.contains(uo) && point_visible(scene, t, cam, o);
                k = seen ? SampleKind::switched : SampleKind::hidden;
                rep = uo + cfg.jitter_px * Eigen::Vector2d(jx, jy);
              }
            }
            tr->kind[s] = k;
            if (reported_visible(k)) {
              tr->visible[s] = 1;
              tr->uv[s * 2] = rep.x();
              tr->uv[s * 2 + 1] = rep.y();
            }
          }
        }
      },
      parallel);
}

}  // namespace

smg::Status validate_prior_config(const PriorConfig& c) {
  auto err = [](const std::string& m) { return smg::Status::error("priors: " + m); };
  auto rate = [](double r) { return r >= 0 && r <= 1; };
  if (c.tracks < 1 || c.tracks > 1000000) return err("tracks must be in [1, 1000000], got " + std::to_string(c.tracks));
  if (!rate(c.object_fraction)) return err("object_fraction must be in [0, 1]");
  if (!(c.jitter_px >= 0 && c.jitter_px <= 50)) return err("jitter_px must be in [0, 50]");
  if (!(c.outlier_min_px >= 0 && c.outlier_max_px >= c.outlier_min_px && c.outlier_max_px <= 1000))
    return err("outlier jump range must satisfy 0 <= min <= max <= 1000 px");
  for (double r : {c.outlier_rate, c.drop_rate, c.lost_track_rate, c.occluded_reported_rate, c.stick_rate,
                   c.switch_rate, c.depth_hole_rate, c.depth_edge_outlier_rate, c.depth_edge_hole_rate})
    if (!rate(r)) return err("every rate must be in [0, 1]");
  if (c.depth_edge_outlier_rate + c.depth_edge_hole_rate > 1)
    return err("depth_edge_outlier_rate + depth_edge_hole_rate must be <= 1");
  if (!(c.switch_radius_px >= 1 && c.switch_radius_px <= 64)) return err("switch_radius_px must be in [1, 64]");
  if (!(c.depth_noise >= 0 && c.depth_noise <= 0.5)) return err("depth_noise must be in [0, 0.5]");
  if (!(c.moving_depth_factor >= 0 && c.moving_depth_factor <= 10))
    return err("moving_depth_factor must be in [0, 10]");
  if (!(c.depth_scale_jitter >= 0 && c.depth_scale_jitter <= 0.5)) return err("depth_scale_jitter must be in [0, 0.5]");
  if (c.feature_dim < classes::count + 1 || c.feature_dim > 1024)
    return err("feature_dim must be in [" + std::to_string(classes::count + 1) + ", 1024] (one direction per class plus void), got " +
               std::to_string(c.feature_dim));
  if (c.feature_patch < 1 || c.feature_patch > 64) return err("feature_patch must be in [1, 64]");
  if (!(c.feature_noise >= 0 && c.feature_noise <= 10)) return err("feature_noise must be in [0, 10]");
  if (!(c.part_spread >= 0 && c.part_spread <= 10)) return err("part_spread must be in [0, 10]");
  if (c.mask_dilate_px < 0 || c.mask_dilate_px > 64) return err("mask_dilate_px must be in [0, 64]");
  return smg::Status::ok();
}

Priors make_priors(const Scene& scene, const std::vector<RenderOutput>& train, const PriorConfig& cfg,
                   smg::ParallelOptions parallel) {
  if (smg::Status st = validate_prior_config(cfg); !st) throw std::invalid_argument(st.message());
  if (static_cast<int>(train.size()) != scene.frames())
    throw std::invalid_argument("priors: expected one training render per frame");
  for (const RenderOutput& r : train)
    if (r.width != scene.width() || r.height != scene.height())
      throw std::invalid_argument("priors: training renders must have the scene's image size");
  const std::uint64_t seed = prior_seed(scene, cfg);
  Priors p;
  p.frames = scene.frames();
  p.width = scene.width();
  p.height = scene.height();
  p.feature_dim = cfg.feature_dim;

  // Embeddings: orthonormal per class (+ void); each body is its class direction plus a
  // body-specific offset, so the two arm links are close but not equal.
  {
    Random rng(derive_seed(seed, kStreamEmbedding));
    const int C = cfg.feature_dim;
    const auto cls = class_embeddings(rng, classes::count + 1, C);
    p.void_embedding.assign(cls.back().data(), cls.back().data() + C);
    for (const Body& b : scene.bodies) {
      Eigen::VectorXd off(C);
      for (int k = 0; k < C; ++k) off(k) = rng.normal();
      const Eigen::VectorXd e = (cls[sz(b.semantic_class)] + cfg.part_spread * off.normalized()).normalized();
      p.body_embedding.insert(p.body_embedding.end(), e.data(), e.data() + C);
    }
  }
  feature_maps(train, cfg, seed, &p, parallel);
  depth_maps(scene, train, cfg, seed, &p, parallel);
  object_mask(scene, train, cfg.mask_dilate_px, &p, parallel);

  p.tracks.frames = scene.frames();
  p.tracks.count = cfg.tracks;
  sample_queries(scene, train, cfg, seed, &p.tracks);
  follow_tracks(scene, train, cfg, seed, &p.tracks, parallel);
  return p;
}

void sample_features(const Priors& p, int t, double u, double v, double* out) {
  const int C = p.feature_dim;
  if (!p.has_features.empty() && !p.has_features[sz(t)]) {
    std::fill(out, out + C, 0.0);
    return;
  }
  // Grid coordinates of the pixel position: cell centres at ((b + 0.5) W/w, (a + 0.5) H/h).
  const int W = p.feature_width > 0 ? p.feature_width : p.width;
  const int H = p.feature_height > 0 ? p.feature_height : p.height;
  const double gu = W == p.width ? u : u * W / p.width, gv = H == p.height ? v : v * H / p.height;
  const double gx = std::clamp(gu - 0.5, 0.0, W - 1.0), gy = std::clamp(gv - 0.5, 0.0, H - 1.0);
  const int x0 = std::min(static_cast<int>(gx), W - 1), y0 = std::min(static_cast<int>(gy), H - 1);
  const int x1 = std::min(x0 + 1, W - 1), y1 = std::min(y0 + 1, H - 1);
  const double ax = gx - x0, ay = gy - y0;
  const float* base = p.features.data() + sz(t) * H * W * C;
  auto at = [&](int x, int y, int k) { return static_cast<double>(base[(sz(y) * W + x) * C + k]); };
  double n2 = 0;
  for (int k = 0; k < C; ++k) {
    out[k] = (1 - ax) * (1 - ay) * at(x0, y0, k) + ax * (1 - ay) * at(x1, y0, k) +
             (1 - ax) * ay * at(x0, y1, k) + ax * ay * at(x1, y1, k);
    n2 += out[k] * out[k];
  }
  const double n = std::sqrt(n2);
  for (int k = 0; k < C; ++k) out[k] = n > 0 ? out[k] / n : 0.0;
}

LiftedTracks lift_tracks(const std::vector<Camera>& cameras, const Priors& p, const LiftOptions& options) {
  const Tracks& tr = p.tracks;
  const int T = tr.frames, N0 = tr.count, W = p.width, H = p.height, C = p.feature_dim;
  // Lift every sample first, then keep the tracks that qualify.
  std::vector<double> pos(sz(T) * N0 * 3, 0.0);
  std::vector<std::uint8_t> vis(sz(T) * N0, 0);
  std::vector<int> lifted_count(sz(N0), 0);
  for (int t = 0; t < T; ++t)
    for (int i = 0; i < N0; ++i) {
      const std::size_t s = sz(t) * N0 + i;
      if (!tr.visible[s]) continue;
      const Eigen::Vector2d uv(tr.uv[s * 2], tr.uv[s * 2 + 1]);
      const Camera& cam = cameras[sz(t)];
      if (!cam.contains(uv)) continue;
      const int x = static_cast<int>(uv.x()), y = static_cast<int>(uv.y());
      const double z = p.depth[(sz(t) * H + y) * W + x];
      if (!(z > 0)) continue;
      const Eigen::Vector3d w = cam.unproject(uv, z);
      for (int c = 0; c < 3; ++c) pos[s * 3 + c] = w(c);
      vis[s] = 1;
      ++lifted_count[sz(i)];
    }
  LiftedTracks out;
  out.frames = T;
  out.feature_dim = C;
  for (int i = 0; i < N0; ++i) {
    if (lifted_count[sz(i)] < options.min_visible_frames) continue;
    if (options.objects_only) {
      // The query pixel decides (its true position where known: the query is given, not
      // tracked). A query frame without a mask (a scene from disk) cannot tell: dropped.
      const int q = tr.query_frame[sz(i)];
      if (!p.has_mask.empty() && !p.has_mask[sz(q)]) continue;
      const std::size_t s = sz(q) * N0 + i;
      const std::vector<double>& quv = tr.uv_true.empty() ? tr.uv : tr.uv_true;
      const int x = std::clamp(static_cast<int>(quv[s * 2]), 0, W - 1);
      const int y = std::clamp(static_cast<int>(quv[s * 2 + 1]), 0, H - 1);
      if (!p.object_mask[(sz(q) * H + y) * W + x]) continue;
    }
    out.track.push_back(i);
  }
  const int N = out.count = static_cast<int>(out.track.size());
  out.positions.assign(sz(T) * N * 3, 0.0);
  out.visible.assign(sz(T) * N, 0);
  out.feature_samples.assign(sz(T) * N * C, 0.0);
  out.positions_true.assign(sz(T) * N * 3, 0.0);
  out.rotations_true.assign(sz(T) * N * 4, 0.0);
  // The truth of the selected tracks, in one pass: a scene from disk has none (body -1, positions
  // 0, identity rotations).
  out.body.assign(sz(N), -1);
  if (!tr.positions_true.empty()) {
    for (int j = 0; j < N; ++j) {
      const int i = out.track[sz(j)];
      out.body[sz(j)] = tr.body[sz(i)];
      for (int t = 0; t < T; ++t) {
        const std::size_t s = sz(t) * N0 + i, d = sz(t) * N + j;
        for (int c = 0; c < 3; ++c) out.positions_true[d * 3 + c] = tr.positions_true[s * 3 + c];
        for (int c = 0; c < 4; ++c) out.rotations_true[d * 4 + c] = tr.rotations_true[s * 4 + c];
      }
    }
  } else {
    for (std::size_t d = 0; d < sz(T) * N; ++d) out.rotations_true[d * 4] = 1.0;
  }
  for (int j = 0; j < N; ++j) {
    const int i = out.track[sz(j)];
    for (int t = 0; t < T; ++t) {
      const std::size_t s = sz(t) * N0 + i, d = sz(t) * N + j;
      if (!vis[s]) continue;
      out.visible[d] = 1;
      for (int c = 0; c < 3; ++c) out.positions[d * 3 + c] = pos[s * 3 + c];
      sample_features(p, t, tr.uv[s * 2], tr.uv[s * 2 + 1], out.feature_samples.data() + d * C);
    }
    // Fill the frames that are not lifted: linear in time between lifted neighbours.
    int prev = -1;
    for (int t = 0; t <= T; ++t) {
      if (t < T && !out.visible[sz(t) * N + j]) continue;
      if (t == T && prev < 0) break;  // never lifted (min_visible_frames = 0): stays at 0
      const int lo = prev < 0 ? t : prev, hi = t == T ? prev : t;
      for (int f = prev + 1; f < t; ++f) {
        const double a = (hi == lo) ? 0.0 : static_cast<double>(f - lo) / (hi - lo);
        for (int c = 0; c < 3; ++c)
          out.positions[(sz(f) * N + j) * 3 + c] = (1 - a) * out.positions[(sz(lo) * N + j) * 3 + c] +
                                                   a * out.positions[(sz(hi) * N + j) * 3 + c];
      }
      prev = t;
    }
  }
  return out;
}

PriorConfig tracker_failures(PriorConfig c, double scale) {
  // Typical rates (docs/trainer.md, "Tracker failures", says where each comes from).
  constexpr double kOccludedReported = 0.25, kStick = 0.3, kSwitch = 0.05, kMovingDepth = 2.0;
  c.occluded_reported_rate = std::min(1.0, scale * kOccludedReported);
  c.stick_rate = std::min(1.0, scale * kStick);
  c.switch_rate = std::min(1.0, scale * kSwitch);
  c.moving_depth_factor = 1.0 + scale * (kMovingDepth - 1.0);
  return c;
}

TrackStats track_stats(const Tracks& tr) {
  TrackStats st;
  long long reported = 0, outliers = 0, truly_visible = 0, dropped = 0, occ = 0, clean = 0;
  long long samples = 0, occluded_in_image = 0, occluded_visible = 0;
  const int N = tr.count;
  std::vector<std::uint8_t> hides(sz(N), 0), stuck(sz(N), 0), switched(sz(N), 0);
  double sq = 0;
  for (std::size_t s = 0; s < tr.kind.size(); ++s) {
    // The query samples are given to the tracker, not tracked: leave them out.
    if (tr.query_frame[s % sz(tr.count)] == static_cast<int>(s / sz(tr.count))) continue;
    ++samples;
    const SampleKind k = tr.kind[s];
    const std::size_t i = s % sz(N);
    if (!tr.visible_true[s] && tr.in_image_true[s]) {
      ++occluded_in_image;
      if (tr.occluder_true[s] >= 0) hides[i] = 1;
      occluded_visible += k == SampleKind::occluded_reported || k == SampleKind::stuck;
    }
    if (k == SampleKind::stuck) stuck[i] = 1;
    if (k == SampleKind::switched) switched[i] = 1;
    if (reported_visible(k)) ++reported;
    if (tr.visible_true[s]) ++truly_visible;
    if (k == SampleKind::outlier) ++outliers;
    if (k == SampleKind::dropped) ++dropped;
    if (k == SampleKind::occluded_reported) ++occ;
    if (k == SampleKind::clean) {
      ++clean;
      const double dx = tr.uv[s * 2] - tr.uv_true[s * 2], dy = tr.uv[s * 2 + 1] - tr.uv_true[s * 2 + 1];
      sq += dx * dx + dy * dy;
    }
  }
  const auto frac = [](long long a, long long b) { return b > 0 ? static_cast<double>(a) / b : 0.0; };
  st.visible_fraction = frac(reported, samples);
  st.outlier_fraction = frac(outliers, reported);
  st.dropped_fraction = frac(dropped, truly_visible);
  st.occluded_reported_fraction = frac(occ, reported);
  st.jitter_rms_px = clean > 0 ? std::sqrt(sq / (2.0 * clean)) : 0.0;  // per axis
  st.occluded_visible_rate = frac(occluded_visible, occluded_in_image);
  long long n_hides = 0, n_stuck = 0, n_switched = 0;
  for (int i = 0; i < N; ++i) {
    n_hides += hides[sz(i)];
    n_stuck += stuck[sz(i)];
    n_switched += switched[sz(i)];
  }
  st.stuck_track_rate = frac(n_stuck, n_hides);
  st.switched_track_rate = frac(n_switched, N);
  return st;
}

}  // namespace trainer
