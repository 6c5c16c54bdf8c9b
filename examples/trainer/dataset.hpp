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
#include <vector>

#include "smg/core/parallel.hpp"
#include "trainer/priors.hpp"
#include "trainer/raycast.hpp"
#include "trainer/scene.hpp"

namespace trainer {

struct DatasetConfig {
  SceneConfig scene;
  PriorConfig priors;
  int supersample = 2;           // k x k colour rays per pixel for every ground-truth image
  bool covisibility = true;      // compute test_covisible (needs surface points of test renders)
  int covisible_min_frames = 1;  // see covisibility_mask
};

struct DatasetTiming {  // seconds (wall clock)
  double scene = 0, render_train = 0, render_test = 0, covisibility = 0, priors = 0, total = 0;
};

struct Dataset {
  Scene scene;
  std::vector<RenderOutput> train;                          // [T]
  std::vector<std::vector<RenderOutput>> test;              // [views][T] (with surface points)
  std::vector<std::vector<std::uint8_t>> test_covisible;    // [views] [T][H][W] (if requested)
  Priors priors;
  DatasetTiming seconds;
};

// Validates both configs (std::invalid_argument with a one-line message) and builds the dataset.
// Deterministic for a seed and the same for any thread count.
Dataset make_dataset(const DatasetConfig& config, smg::ParallelOptions parallel = {});

}  // namespace trainer
