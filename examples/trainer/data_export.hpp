// examples/trainer/data_export.hpp — the exporter: the procedural dataset in the Dycheck layout, with true query tracks (docs/data.md).
#pragma once

#include <vector>

#include "trainer/data_queries.hpp"
#include "trainer/dataset.hpp"
#include "trainer/dycheck.hpp"

namespace trainer {

// The exporter: the procedural dataset in the Dycheck layout. Training frames "0_{t:05d}" (the
// training camera; sensor depth = the noisy depth prior), validation frames "{v+1}_{t:05d}" of the
// test cameras at every time except every val_gap-th (t % val_gap == val_gap - 1; 0 = no gap),
// covisible masks from the analytic ground truth, tracks / object masks from the priors, feature
// maps on a grid of feature_cell x feature_cell pixels per cell. Needs a dataset with test views
// and covisibility (make_dataset's defaults).
DycheckScene to_dycheck(const Dataset& data, int val_gap = 4, int feature_cell = 4);

// Queries for the exported scene with their true 3D tracks: the true pixel at frame 0 of up to
// `count` object tracks (arm, box, ball) truly visible at frame 0, spread over the tracks, and
// their true world positions [M][T][3].
void export_queries(const Dataset& data, int count, TrackQueries* queries, std::vector<float>* truth);
// The same queries and truth as a QuerySet, with each query's semantic class and each sample's
// true visibility in the training view: what a procedural run is scored by (kQueryCount queries,
// the count --export-dycheck writes, so that a run and the --data run of its export score the
// same points).
QuerySet export_query_set(const Dataset& data, int count);
constexpr int kQueryCount = 256;

}  // namespace trainer
