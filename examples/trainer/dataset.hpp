// examples/trainer/dataset.hpp — everything the trainer reads, generated in one call.
//
// A Dataset is the scene (scene.hpp), the ground-truth renders of the training camera and of the
// test cameras (raycast.hpp), the test views' co-visibility masks and the priors
// (priors.hpp). The pipeline's stages consume it as follows:
//   stage 1 (nodes)     lift_tracks(dataset.scene, dataset.priors) -> positions/visibility/
//                       feature samples in smg's view layouts; truth for the 3D tracking error
//   stage 2 (Gaussians) train[t].rgb (target images), priors.depth, priors.object_mask,
//                       scene.train_cameras[t]
//   evaluation          test[v][t].rgb against renders of scene.test_cameras[v], masked by
//                       test_covisible[v]; tracking_error against LiftedTracks::positions_true
#pragma once

#include <cstdint>
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

// The procedural scene (make_dataset) fills scene, train, test, test_covisible and priors, with
// ground truth everywhere. A scene read from disk (dataset_from_dycheck) fills scene with the
// training cameras, image size and frame count only (no bodies), train[t].rgb, priors (tracks
// without truth), and eval; has_truth is false and test / test_covisible are empty.
struct Dataset {
  Scene scene;
  std::vector<RenderOutput> train;                          // [T]
  std::vector<std::vector<RenderOutput>> test;              // [views][T] (with surface points)
  std::vector<std::vector<std::uint8_t>> test_covisible;    // [views] [T][H][W] (if requested)
  Priors priors;
  DatasetTiming seconds;

  bool has_truth = true;                 // analytic ground truth available (procedural scene)
  std::string source = "procedural";     // or the scene folder it was read from
  std::vector<int> time_ids;             // [T] time id of each training frame (procedural: t)
  std::vector<std::string> frame_names;  // [T] training frame names (procedural: "0_{t:05d}")
  std::vector<EvalFrame> eval;           // validation frames of a scene from disk
};

// Selects a scene layout and the priors that go with it: the occluder layout's depth prior is
// three times noisier on moving bodies (6 % relative sigma) and mixes more edge pixels (45 %),
// as a monocular depth estimator does on thin parts that leave and re-enter the view.
void apply_scene_layout(SceneLayout layout, DatasetConfig* config);

// Validates both configs (std::invalid_argument with a one-line message) and builds the dataset.
// Deterministic for a seed and the same for any thread count.
Dataset make_dataset(const DatasetConfig& config, smg::ParallelOptions parallel = {});

}  // namespace trainer
