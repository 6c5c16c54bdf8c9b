// examples/trainer/metrics_json.hpp — OUT/metrics.json of smg_trainer: one writer for every run
// (docs/trainer.md, "Outputs"; docs/data.md, "What the trainer writes").
//
// One key set: the keys common to every run (program, variant, scene, image size, threads, the
// C-ARAP settings, extent, graph and model statistics, timings, out), then the keys that need
// what the run has. Keys that need ground truth (test-view PSNR/SSIM, node EPE, the confidence
// diagnostics) are absent for a scene from disk; its Dycheck scores (mPSNR, mSSIM, per frame)
// and the query-track error (with --track-truth) are present only there. The generated scene's
// metrics.json keeps its keys and their order.
#pragma once

#include <string>
#include <vector>

#include "trainer/data_queries.hpp"
#include "trainer/pipeline.hpp"

namespace trainer {

// What metrics.json reports beyond the TrainerResult.
struct RunRecord {
  const TrainerConfig* config = nullptr;  // as given on the command line (variant, seed, C-ARAP settings)
  std::string out;                        // OUT
  double seconds_read = 0;                // a scene from disk: reading and validating its files
  double seconds_write = 0;               // a scene from disk: writing the renders and tracks
  // --track-queries: the number of queries; with --track-truth, the 3D error of their tracks.
  int queries = 0;
  const QueryTrackError* query_error = nullptr;
};

// The metrics.json line (one JSON object, no newline) of a finished run.
std::string metrics_json(const TrainerResult& result, const RunRecord& run);

// Writes `line` and a newline to OUT/metrics.json; std::runtime_error naming the file if that fails.
void write_metrics_json(const std::string& out_dir, const std::string& line);

}  // namespace trainer
