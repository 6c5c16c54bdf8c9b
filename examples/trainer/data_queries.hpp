// examples/trainer/data_queries.hpp — 3D query tracks of a scene: Q.json, carrying queries through time, their error (docs/data.md).
#pragma once

#include <string>
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
std::vector<float> carry_queries(const TrackQueries& queries, const Dataset& data, const Nodes& nodes,
                                 const GaussianModel<float>& model, smg::ParallelOptions parallel = {});

// 3D tracking error of [M][T][3] estimates against truth of the same shape: mean EPE (metres)
// and the fractions within 5 cm and 10 cm (docs/data.md section 4).
struct QueryTrackError {
  double epe = 0, within_5cm = 0, within_10cm = 0;
};
QueryTrackError query_track_error(const std::vector<float>& estimate, const std::vector<float>& truth);

}  // namespace trainer
