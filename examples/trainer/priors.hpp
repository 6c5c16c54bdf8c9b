// examples/trainer/priors.hpp — what off-the-shelf models would give a real pipeline.
//
// From the ground truth of the training view (scene.hpp, raycast.hpp) this draws, with seeded
// and thread-count-independent noise:
//   * 2D tracks (a point tracker such as CoTracker/TAPIR): query points on visible surfaces,
//     followed by their analytic motion, with pixel jitter, jump outliers, dropped samples, lost
//     runs, occluded samples reported as visible, and (off by default: tracker_failures() below)
//     tracks that stick to an occluder and identity switches to a neighbouring object;
//   * depth maps (a depth estimator): multiplicative noise, a per-frame scale error, holes, and
//     "flying pixels" and holes at depth edges;
//   * semantic feature maps (DINO-like): per-body unit embeddings on a coarse patch grid,
//     noisy and bilinearly upsampled, so features blur across object boundaries;
//   * an object mask (a video segmenter): the foreground objects, dilated.
// lift_tracks turns tracks + depth + features into the pipeline's starting point in the layouts
// of smg's views: positions [T][N][3], visibility [T][N], feature samples [T][N][C].
#pragma once

#include <cstdint>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/core/views.hpp"
#include "trainer/raycast.hpp"
#include "trainer/scene.hpp"

namespace trainer {

struct PriorConfig {
  std::uint64_t seed = 0;  // mixed with the scene seed

  // Tracks.
  int tracks = 1000;                     // N
  double object_fraction = 0.8;          // share of queries on foreground objects (arm, box, ball)
  double jitter_px = 0.5;                // sigma of the Gaussian noise on every reported position
  double outlier_rate = 0.02;            // reported-visible samples replaced by a jump
  double outlier_min_px = 6, outlier_max_px = 24;  // jump length range
  double drop_rate = 0.03;               // visible samples reported invisible
  double lost_track_rate = 0.15;         // tracks that lose a run of 2 .. T/3 frames
  double occluded_reported_rate = 0.1;   // occluded (in-image) samples reported visible
  // Tracker failures of TAPIR-class trackers (docs/trainer.md, "Tracker failures"); 0 here so
  // that the scenes' priors stay what every published figure used: tracker_failures() sets them.
  double stick_rate = 0;                 // tracks that stay on the occluder while their point is
                                         // hidden behind it (reported visible, on the occluder)
  double switch_rate = 0;                // tracks that switch to a neighbouring body for a stretch
  double switch_radius_px = 6;           // how far the other body may be from the true position

  // Depth.
  double depth_noise = 0.02;             // relative sigma per pixel
  double moving_depth_factor = 1.0;      // depth_noise times this on moving bodies (arm, ball)
  double depth_scale_jitter = 0.01;      // relative sigma of a per-frame scale error
  double depth_hole_rate = 0.01;         // pixels without depth (0)
  double depth_edge_outlier_rate = 0.3;  // edge pixels whose depth mixes both sides
  double depth_edge_hole_rate = 0.2;     // edge pixels without depth

  // Semantic features.
  int feature_dim = 8;                   // C >= classes::count + 1
  int feature_patch = 4;                 // pixels per patch side (DINO's patches are coarse)
  double feature_noise = 0.15;           // norm of the noise added to each patch feature
  double part_spread = 0.25;             // offset of each body from its class embedding

  // Object mask.
  int mask_dilate_px = 1;
};

// The tracker failures at `scale` times the typical rates of TAPIR-class trackers (scale 0: none;
// 1: typical; 2: twice), set on top of `base`: occluded_reported_rate, stick_rate, switch_rate
// and the depth prior's moving_depth_factor (1 + scale (typical − 1)). The typical rates and
// where they come from: docs/trainer.md, "Tracker failures". Rates are clamped to 1.
PriorConfig tracker_failures(PriorConfig base, double scale);

// What a point tracker reports for one (frame, track) sample, and why.
enum class SampleKind : std::uint8_t {
  hidden = 0,             // not visible and reported so (occluded or out of the image)
  clean = 1,              // visible, reported at the true position + jitter
  outlier = 2,            // visible, reported at a wrong position (a jump)
  dropped = 3,            // visible but reported invisible (a drop or a lost run)
  occluded_reported = 4,  // occluded but reported visible at the true position + jitter
  stuck = 5,              // occluded, reported visible on the occluder (the track stuck to it)
  switched = 6,           // reported on a neighbouring body's point (an identity switch)
};
inline bool reported_visible(SampleKind k) {
  return k == SampleKind::clean || k == SampleKind::outlier || k == SampleKind::occluded_reported ||
         k == SampleKind::stuck || k == SampleKind::switched;
}

// 2D tracks of the training camera. Layouts: [T][N][...], row-major.
struct Tracks {
  int frames = 0, count = 0;
  // Ground truth.
  std::vector<int> body;              // [N] body the query point lies on
  std::vector<double> local;          // [N][3] query point in the body frame
  std::vector<int> query_frame;       // [N]
  std::vector<double> uv_true;        // [T][N][2] true projection (pixels, centre +0.5)
  std::vector<double> depth_true;     // [T][N] true depth z (<= 0 behind the camera)
  std::vector<std::uint8_t> visible_true;  // [T][N] in the image and unoccluded
  std::vector<std::uint8_t> in_image_true;  // [T][N] in front of the camera and inside the image
  std::vector<std::int32_t> occluder_true;  // [T][N] the other body in front of a point hidden in the
                                           // image; -1 if visible, outside or hidden by its own body
  std::vector<double> positions_true;      // [T][N][3] world positions
  std::vector<double> rotations_true;      // [T][N][4] the body's rotation (w, x, y, z)
  // What the tracker reports.
  std::vector<double> uv;             // [T][N][2] reported position; (-1, -1) where not reported
  std::vector<std::uint8_t> visible;  // [T][N] reported visibility
  std::vector<SampleKind> kind;       // [T][N] why (statistics and tests)
};

struct Priors {
  int frames = 0, width = 0, height = 0, feature_dim = 0;
  Tracks tracks;
  std::vector<float> depth;               // [T][H][W] metres (z), 0 = no depth
  // Feature maps on a grid of feature_width x feature_height cells per frame, [T][h][w][C]; cell
  // (a, b) covers pixels [b W/w, (b+1) W/w) x [a H/h, (a+1) H/h) (docs/data.md section 2). 0 means
  // one cell per pixel (the procedural priors: [T][H][W][C], unit norm).
  int feature_width = 0, feature_height = 0;
  std::vector<float> features;
  std::vector<std::uint8_t> object_mask;  // [T][H][W]
  // [T] 0 where a frame has no mask / no feature map (a scene from disk may lack them; those
  // slices are zero). Empty: every frame has both.
  std::vector<std::uint8_t> has_mask, has_features;
  std::vector<double> body_embedding;     // [bodies][C] clean embedding of each body
  std::vector<double> void_embedding;     // [C] where nothing is hit
};

// Checks ranges and that feature_dim leaves room for every class plus the void.
smg::Status validate_prior_config(const PriorConfig& config);

// Draws all priors from the training renders (render_training_view of the same scene). Throws
// std::invalid_argument with validate_prior_config's message on a bad config. The result is the
// same for any thread count.
Priors make_priors(const Scene& scene, const std::vector<RenderOutput>& train, const PriorConfig& config,
                   smg::ParallelOptions parallel = {});

struct LiftOptions {
  int min_visible_frames = 3;  // keep tracks lifted in at least this many frames
  bool objects_only = false;   // keep tracks whose query pixel lies in the object mask
};

// Lifted tracks: the stage-1 input. N here counts the kept tracks; track[i] is the index into
// Priors::tracks. A sample is lifted ("visible") when it was reported visible, its reported
// position lies in the image and the depth map has a value at that pixel (nearest pixel); the
// position is then the back-projection of the reported position with that depth through the
// training camera of its frame. Samples that are not lifted hold the linear interpolation in
// time of the lifted ones (constant before the first and after the last): an initialisation, not
// an observation. Feature samples are the bilinearly sampled, renormalised feature map at the
// reported position where lifted, 0 elsewhere.
struct LiftedTracks {
  int frames = 0, count = 0, feature_dim = 0;
  std::vector<int> track;                 // [N] index into Priors::tracks
  std::vector<double> positions;          // [T][N][3]
  std::vector<std::uint8_t> visible;      // [T][N]
  std::vector<double> feature_samples;    // [T][N][C]
  std::vector<double> positions_true;     // [T][N][3] ground truth, for 3D tracking error
  std::vector<double> rotations_true;     // [T][N][4] ground-truth body rotation (w, x, y, z)
  std::vector<int> body;                  // [N] ground-truth body (diagnostics only)

  smg::PositionsView<const double> positions_view() const {
    return {positions.data(), frames, count};
  }
  smg::VisibilityView<const std::uint8_t> visibility_view() const {
    return {visible.data(), frames, count};
  }
  smg::FeatureSamplesView<const double> feature_samples_view() const {
    return {feature_samples.data(), frames, count, feature_dim};
  }
  smg::PositionsView<const double> positions_true_view() const {
    return {positions_true.data(), frames, count};
  }
  smg::QuaternionsView<const double> rotations_true_view() const {
    return {rotations_true.data(), frames, count};
  }
};

// Lifts the tracks through the training cameras ([T], Dataset::cameras) with the depth prior.
LiftedTracks lift_tracks(const std::vector<Camera>& cameras, const Priors& priors, const LiftOptions& options = {});

// Feature map sample at a continuous pixel position (bilinear between cell centres, clamped at
// the border), renormalised; writes C values (zeros where the frame has no feature map).
void sample_features(const Priors& priors, int t, double u, double v, double* out);

// Summary statistics of the reported tracks over the tracked samples (the query sample of each
// track is given, not tracked, and is left out).
struct TrackStats {
  double visible_fraction = 0;   // reported-visible samples / all samples
  double outlier_fraction = 0;   // outliers / reported-visible samples
  double dropped_fraction = 0;   // dropped / truly visible samples
  double occluded_reported_fraction = 0;  // occluded_reported / reported-visible samples
  // The tracker-failure knobs as measured (rates per the knob's own denominator):
  double occluded_visible_rate = 0;  // (occluded_reported + stuck) / occluded in-image samples
  double stuck_track_rate = 0;       // tracks with a stuck sample / tracks whose point is hidden
                                     // in the image behind another body at some tracked frame
  double switched_track_rate = 0;    // tracks with a switched sample / tracks
  double jitter_rms_px = 0;      // per-axis RMS of (uv - uv_true) over clean samples
};
TrackStats track_stats(const Tracks& tracks);

}  // namespace trainer
