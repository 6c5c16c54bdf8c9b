// examples/trainer/dataset.hpp — the sequence the trainer reads (Dataset), from the procedural
// scene (make_dataset, here) or from disk (dataset_from_dycheck, data_scene.hpp).
//
// The stages read the sequence, never the truth:
//   stage 0/1 (nodes)   lift_tracks(cameras, priors) -> positions/visibility/feature samples in
//                       smg's view layouts
//   stage 2 (Gaussians) images[t] (targets), priors.depth, priors.object_mask, cameras[t]
//   evaluation          the procedural test views (truth->test, masked by truth->test_covisible)
//                       or the validation frames (eval); 3D tracking error against the truth
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "smg/core/parallel.hpp"
#include "trainer/priors.hpp"
#include "trainer/raycast.hpp"
#include "trainer/scene.hpp"

namespace trainer {

// Which tracker failures the priors get (priors.hpp, tracker_failures): the layout's own
// priors (apply_scene_layout; what every published figure used), none, the typical rates of
// TAPIR-class trackers, or twice those.
enum class TrackerFailures { scene, off, typical, twice };
inline const std::vector<std::string>& tracker_failure_names() {
  static const std::vector<std::string> names = {"scene", "off", "typical", "double"};
  return names;
}

struct DatasetConfig {
  SceneConfig scene;
  PriorConfig priors;
  TrackerFailures tracker_failures = TrackerFailures::scene;  // applied on top of `priors`
  int supersample = 2;           // k x k colour rays per pixel for every ground-truth image
  bool covisibility = true;      // compute test_covisible (needs surface points of test renders)
  int covisible_min_frames = 1;  // see covisibility_mask
};

struct DatasetTiming {  // seconds (wall clock)
  double scene = 0, render_train = 0, render_test = 0, covisibility = 0, priors = 0, total = 0;
};

// A validation frame of a scene read from disk (data_scene.hpp): its own camera and image, the
// covisible mask of Dycheck's protocol, and the training frame whose time it shows.
struct EvalFrame {
  std::string name;                     // "{camera}_{time:05d}"
  int time_id = 0;                      // the split's time id
  int frame = 0;                        // training frame index rendered for it (nearest time id)
  Camera camera;                        // at 2x
  Image rgb;                            // [H][W][3]
  std::vector<std::uint8_t> covisible;  // [H][W] 0/1
};

// The procedural scene's ground truth (make_dataset only): the generator's scene (bodies,
// motions, test cameras), its renders of the training camera (colour, depth, body ids, surface
// points) and of the test cameras, and the test views' co-visibility masks. Everything that
// reports an error against the truth reads it from here; no stage reads it to train.
struct GroundTruth {
  Scene scene;
  std::vector<RenderOutput> train;                          // [T]
  std::vector<std::vector<RenderOutput>> test;              // [views][T] (with surface points)
  std::vector<std::vector<std::uint8_t>> test_covisible;    // [views] [T][H][W] (if requested)
};

// The sequence the trainer reads, from any source: training cameras and images, priors,
// validation frames, and optional ground truth. Two adapters fill it: make_dataset (the
// procedural scene: scene, ray caster, priors; truth everywhere) and dataset_from_dycheck
// (data_scene.hpp; every on-disk layout is read into a DycheckScene by its own reader,
// layouts.hpp). The stages read only the fields above `truth`.
struct Dataset {
  std::string source = "procedural";     // or the scene folder it was read from
  int width = 0, height = 0;             // training images (pixels; 2x for a Dycheck scene)
  std::vector<Camera> cameras;           // [T] training cameras
  std::vector<Image> images;             // [T] training images [H][W][3]
  std::vector<int> time_ids;             // [T] time id of each training frame (procedural: t)
  std::vector<std::string> frame_names;  // [T] training frame names (procedural: "0_{t:05d}")
  Priors priors;
  std::vector<EvalFrame> eval;           // validation frames (a scene from disk)
  // Diagonal (metres) that scales the tracking thresholds and, for a scene from disk, every
  // length of the configuration: the procedural scene's object bounds; for a scene from disk,
  // the lifted tracks' extent, set by run_stage0 (pipeline.hpp).
  double extent = 0;
  std::uint64_t seed = 0;                // the procedural scene's seed (0 from disk): seeds stage 2
  DatasetTiming seconds;
  std::optional<GroundTruth> truth;      // the procedural scene only

  int frames() const { return static_cast<int>(cameras.size()); }
};

// The ground truth that `who` (a function that cannot work without it) reads: the one place
// where its absence (a scene from disk) is refused, as std::invalid_argument("<who>: needs the
// procedural scene's ground truth").
inline const GroundTruth& need_truth(const Dataset& d, const char* who) {
  if (!d.truth) throw std::invalid_argument(std::string(who) + ": needs the procedural scene's ground truth");
  return *d.truth;
}

// The ground truth, or an empty one (no bodies, classes, cameras or views) for a scene from disk:
// for code that loops over what the truth has, so that its absence is handled here, once.
inline const GroundTruth& truth_or_empty(const Dataset& d) {
  static const GroundTruth empty;
  return d.truth ? *d.truth : empty;
}

// Selects a scene layout and the priors that go with it: the occluder layout's depth prior is
// three times noisier on moving bodies (6 % relative sigma) and mixes more edge pixels (45 %),
// as a monocular depth estimator does on thin parts that leave and re-enter the view.
void apply_scene_layout(SceneLayout layout, DatasetConfig* config);

// Validates both configs (std::invalid_argument with a one-line message) and builds the dataset.
// Deterministic for a seed and the same for any thread count.
Dataset make_dataset(const DatasetConfig& config, smg::ParallelOptions parallel = {});

}  // namespace trainer
