// examples/trainer/pipeline.hpp — the whole trainer in one call: dataset, stage 0 (lifting,
// node selection, graph), stage 1 (nodes), stage 2 (Gaussians + nodes), evaluation.
//
// default_config() holds every hyperparameter; they are the same for every variant (only
// TrainerConfig::variant changes between the rungs of the ablation ladder). The trainer
// program (train.cpp) maps flags onto it; tests run tiny configurations in-process.
#pragma once

#include <string>
#include <vector>

#include "trainer/dataset.hpp"
#include "trainer/evaluate.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/nodes.hpp"
#include "trainer/priors.hpp"
#include "trainer/progress.hpp"
#include "trainer/stage2.hpp"
#include "trainer/variant.hpp"

namespace trainer {

struct TrainerConfig {
  VariantSpec variant = variant_spec(Variant::full);
  DatasetConfig dataset;
  LiftOptions lift{3, /*objects_only=*/true};
  NodeOptions nodes;
  NodeLossOptions node_loss;
  Stage1Options stage1;
  InitOptions init;  // frame lists filled by resolve_frames() when empty
  Stage2Options stage2;
  int threads = 0;   // 0 = all hardware threads
};

// The defaults (quick = the CI-sized run: fewer frames, a smaller image, fewer iterations).
TrainerConfig default_config(bool quick = false);

// Fills empty InitOptions frame lists from the frame count: static Gaussians from 4 frames
// spread over the training orbit, dynamic ones from 8 reference frames.
void resolve_frames(TrainerConfig& config);

struct TrainerResult {
  Dataset data;
  LiftedTracks lifted;
  Nodes nodes;
  GaussianModel<float> model;
  Stage1Result stage1;
  Stage2Result stage2;
  TrackMetrics tracks_lifted;  // the node trajectories as lifted (before stage 1)
  TrackMetrics tracks_stage1;  // after stage 1
  Evaluation evaluation;       // after stage 2
  std::vector<std::vector<Image>> renders;  // [test views + 1][T], the training view last
  double seconds_dataset = 0, seconds_stage0 = 0, seconds_total = 0;
};

// The dataset and stage 0 only (lifting, node selection, graph, initial rotations): fills
// data, lifted, nodes (the stage-1 starting point), tracks_lifted, seconds_dataset and
// seconds_stage0 of the result; run_trainer starts with it. Throws like run_trainer.
TrainerResult run_stage0(const TrainerConfig& config, const Progress& progress);

// Runs everything. Throws std::invalid_argument on a bad configuration (the dataset's
// validation), std::runtime_error if the optimisation fails.
TrainerResult run_trainer(const TrainerConfig& config, const Progress& progress);

}  // namespace trainer
