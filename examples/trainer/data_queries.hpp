// examples/trainer/data_queries.hpp — 3D query tracks of a scene: Q.json, carrying queries through time, their error (docs/data.md).
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "trainer/dataset.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/nodes.hpp"

namespace trainer {

// Query points for 3D tracking (docs/data.md section 3): pixels in one training frame.
struct TrackQueries {
  std::string frame;                // training frame name
  std::vector<double> xy;           // [M][2] pixels at 2x, centre convention
  int count() const { return static_cast<int>(xy.size() / 2); }
};

// Reads Q.json ({"frame": "0_00000", "xy_2x": [[x, y], ...]}); the frame must be one of
// data.frame_names and every point inside its image. Throws DataError naming the file.
TrackQueries read_track_queries(const std::string& path, const Dataset& data);
// Writes Q.json. Throws DataError naming the file.
void write_track_queries(const std::string& path, const TrackQueries& queries);

// Carries the queries through time with the reconstruction: each is lifted with the frame's
// sensor depth (the model's rendered depth where the sensor has none) and driven by DQB from the
// nodes, exactly as a dynamic Gaussian anchored at that frame (its nearest node and the node's
// graph neighbours, the model's skinning sigma). Returns [M][T][3] world positions (metres).
// With `node_weight`, also [N]: each node's skinning weight summed over the queries (how much of
// the surface the queries sample that node drives; 0 for a node that drives no query).
std::vector<float> carry_queries(const TrackQueries& queries, const Dataset& data, const Nodes& nodes,
                                 const GaussianModel<float>& model, smg::ParallelOptions parallel = {},
                                 std::vector<double>* node_weight = nullptr);

// 3D tracking error of [M][T][3] estimates against truth of the same shape: mean EPE (metres)
// and the fractions within 5 cm and 10 cm (docs/data.md section 4), over the samples where
// `mask` ([M][T], nonzero = count) is set, or all samples without one. `samples` counts them;
// with none, every figure is NaN.
struct QueryTrackError {
  double epe = 0, within_5cm = 0, within_10cm = 0;
  long long samples = 0;
};
QueryTrackError query_track_error(const std::vector<float>& estimate, const std::vector<float>& truth,
                                  const std::vector<std::uint8_t>* mask = nullptr);

// The queries a run is scored by: the points, their true tracks where known and, on the
// procedural scene (export_queries), each query's semantic class and each sample's true
// visibility. The procedural run and the --data run of its export build this from the same
// points and truth, and both score it with score_queries: one code path (docs/trainer.md).
struct QuerySet {
  TrackQueries queries;
  std::vector<float> truth;           // [M][T][3] metres; empty: no truth, nothing scored
  std::vector<int> semantic_class;    // [M] classes::* of the body under each query; empty: unknown
  std::vector<std::uint8_t> visible;  // [M][T] truly visible in the training view; empty: unknown
};

// One scoring of a QuerySet against a reconstruction (after stage 1 or after stage 2).
struct QueryScore {
  bool scored = false;                // truth was given
  std::vector<float> tracks;          // [M][T][3] the carried queries (carry_queries)
  std::vector<double> node_weight;    // [N] skinning weight of the queries on each node
  QueryTrackError all, visible, hidden;            // visible/hidden: samples by QuerySet::visible
  std::vector<std::pair<int, QueryTrackError>> by_class;  // (class, error), classes in ascending order
};

// Carries the set's queries with the reconstruction and scores them against the set's truth.
QueryScore score_queries(const QuerySet& set, const Dataset& data, const Nodes& nodes,
                         const GaussianModel<float>& model, smg::ParallelOptions parallel = {});

}  // namespace trainer
