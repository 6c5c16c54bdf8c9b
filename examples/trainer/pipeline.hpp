// examples/trainer/pipeline.hpp — the whole trainer in one call: dataset, stage 0 (lifting,
// node selection, graph), stage 1 (nodes), stage 2 (Gaussians + nodes), evaluation.
//
// default_config() holds every hyperparameter; they are the same for every variant (only
// TrainerConfig::variant changes between the rungs of the ablation ladder). The trainer
// program (train.cpp) maps flags onto it; tests run tiny configurations in-process.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "trainer/data_queries.hpp"
#include "trainer/data_scene.hpp"
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
  // false (--no-image-eval): no rendering after stage 2; the evaluation keeps the 3D errors only
  // (node EPE, query EPE), for studies that read nothing else.
  bool image_eval = true;
};

// The defaults (quick = the CI-sized run: fewer frames, a smaller image, fewer iterations).
TrainerConfig default_config(bool quick = false);

// Fills empty InitOptions frame lists from the frame count: static Gaussians from 4 frames
// spread over the training orbit, dynamic ones from 8 reference frames. With `has_mask` ([T],
// a scene from disk; empty: every frame) the frames are spread over the frames that have a mask.
void resolve_frames(TrainerConfig& config);
void resolve_frames(TrainerConfig& config, int frames, const std::vector<std::uint8_t>& has_mask);

// Multiplies every length of the configuration that is in metres (node unit, Huber widths,
// confidence epsilon, position learning rates, prune scale) by `factor`: the scene's extent over
// kReferenceExtent for a scene from disk (data_scene.hpp).
void scale_lengths(TrainerConfig& config, double factor);

// What a run can see of its scene before stage 1, without any truth (docs/results.md, "What the
// trainer sees before stage 1"): over the nodes' lifted trajectories,
//   low_confidence: the share of observed samples whose confidence c (E6, of the lifted
//     trajectories) is below 0.3;
//   visibility_flips: the share of consecutive frame pairs (t-1, t) of a node whose observed
//     flag differs (occlusions and tracker dropouts switch it);
//   observed: the share of samples observed.
struct SceneSignals {
  double low_confidence = 0, visibility_flips = 0, observed = 0;
};
SceneSignals scene_signals(const Nodes& nodes, const std::vector<double>& confidence);

struct TrainerResult {
  Dataset data;
  LiftedTracks lifted;
  Nodes nodes;
  GaussianModel<float> model;
  Stage1Result stage1;
  Stage2Result stage2;
  TrackMetrics tracks_lifted;  // the node trajectories as lifted (before stage 1)
  TrackMetrics tracks_stage1;  // after stage 1
  // What the confidences (E6) measure (procedural scenes only): of the lifted trajectories stage 1
  // starts from, and of its result (nodes.hpp, confidence_diagnostics).
  ConfidenceDiagnostics confidence_lifted, confidence_stage1;
  Evaluation evaluation;       // after stage 2, with the renders: test views or validation frames
  // The surface query tracks the run is scored by (docs/trainer.md, "Query tracks"): on the
  // procedural scene the kQueryCount points --export-dycheck writes (export_query_set, set by
  // run_stage0); on a scene from disk whatever the caller sets (smg_trainer: --track-queries and
  // --track-truth), or none. Scored after stage 1 (the stage-1 nodes with the initial model, as a
  // run with --stage2-iters 0 ends) and after stage 2, by the same score_queries.
  std::optional<QuerySet> queries;
  QueryScore query_stage1, query_stage2;
  // Node EPE after stage 1 split by failed reports, confidence band and query influence
  // (procedural scenes with queries; evaluate.hpp, node_error_split).
  NodeErrorSplit node_split_stage1;
  SceneSignals signals;  // of the lifted trajectories (every run)
  double seconds_dataset = 0, seconds_stage0 = 0, seconds_total = 0;

  // The configuration the stages ran with (frame lists resolved; lengths scaled for a scene from
  // disk by length_factor = extent / kReferenceExtent, 1 for the procedural scene).
  TrainerConfig config;
  double length_factor = 1.0;
};

// The dataset and stage 0 only (lifting, node selection, graph, initial rotations): fills
// data, lifted, nodes (the stage-1 starting point), tracks_lifted, seconds_dataset and
// seconds_stage0 of the result; run_trainer starts with it. Throws like run_trainer.
TrainerResult run_stage0(const TrainerConfig& config, const Progress& progress);
// The same on a given dataset (a scene from disk: dataset_from_dycheck). For a dataset without
// truth the scene extent is measured on the lifted object tracks (lifted_extent) and the
// configuration's lengths are scaled by extent / kReferenceExtent; too few lifted object tracks,
// or none selected as a node, throws DataError (the scene's files are the problem); without
// feature maps (priors.feature_dim 0) the graph is geometric (config.variant.semantic_graph off).
TrainerResult run_stage0(const TrainerConfig& config, Dataset data, const Progress& progress);

// Runs everything. Throws std::invalid_argument on a bad configuration (the dataset's
// validation), std::runtime_error if the optimisation fails.
TrainerResult run_trainer(const TrainerConfig& config, const Progress& progress);
// The same on a given dataset (evaluate() scores the test views where the dataset has truth and
// the validation frames where it has them).
TrainerResult run_trainer(const TrainerConfig& config, Dataset data, const Progress& progress);
// Stages 1 and 2 and the evaluation on the result of run_stage0 (its config and data): what
// run_trainer does after stage 0, for a caller that checks stage 0 first (smg_trainer --data
// creates OUT only once the scene has passed stage 0).
TrainerResult run_trainer(TrainerResult stage0, const Progress& progress);

}  // namespace trainer
