// examples/trainer/data_scene.hpp — the trainer on a scene from disk (docs/data.md): a Dycheck
// iPhone folder plus priors turned into the trainer's Dataset, the scene's length scale, the
// evaluation on its validation frames with Dycheck's metrics, 3D query tracks, and the exporter
// that writes the procedural scene in that layout.
//
// How a scene from disk enters the pipeline (docs/data.md section 5):
//   training frames  -> Dataset::train[t].rgb, Scene::train_cameras[t] (sorted by time id)
//   sensor depth     -> Priors::depth (lifting, Gaussian initialisation, depth loss)
//   priors/masks     -> Priors::object_mask (dynamic Gaussians and node tracks inside, static
//                       Gaussians outside); frames without a mask seed no Gaussians
//   priors/features  -> Priors::features on their own grid, sampled bilinearly (graph gate)
//   priors/tracks    -> Priors::tracks (reported uv and visibility; no truth)
//   validation frames-> Dataset::eval, each rendered at the training frame of the nearest time id
// Lengths of the configuration tuned in metres on the procedural scene are multiplied by
// scene_extent / kReferenceExtent, so the scene's own scale decides them (pipeline.hpp).
#pragma once

#include <string>
#include <vector>

#include "trainer/dataset.hpp"
#include "trainer/dycheck.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/image.hpp"
#include "trainer/nodes.hpp"

namespace trainer {

// The robust extent (metres) of the lifted object tracks measured on the default procedural
// scene (seed 0) by lifted_extent: the reference that the metre-valued defaults were tuned at.
constexpr double kReferenceExtent = 1.63;

// Turns a scene read by read_dycheck into the trainer's Dataset (moves the images out of
// `scene`). Throws DataError when the scene cannot be trained: no training frame with a mask,
// fewer than 2 training frames.
Dataset dataset_from_dycheck(DycheckScene&& scene);

// Diagonal (metres) of the box holding the 2nd to 98th percentile, per axis, of every lifted
// sample of the given tracks: the scale of what moves, robust to flying depth pixels. 0 when
// fewer than 16 samples are lifted.
double lifted_extent(const LiftedTracks& lifted);

// The training frame index (into Dataset::time_ids, sorted) whose time id is nearest to
// `time_id` (the earlier one on a tie).
int nearest_frame(const std::vector<int>& time_ids, int time_id);

// Image metrics of one validation frame (Dycheck's definitions, dycheck_metrics.hpp).
struct FrameScore {
  std::string name;
  double mpsnr = 0, mssim = 0, mssim_covisible = 0, psnr = 0, ssim = 0;
};
struct DataEvaluation {
  std::vector<FrameScore> frames;  // [V] in Dataset::eval order
  FrameScore mean;                 // the mean over every validation frame of every camera
  double seconds = 0;
};

// Renders every validation frame (the model at EvalFrame::frame, through the frame's camera) and
// scores it. renders (optional, out): [V] images.
DataEvaluation evaluate_frames(const Dataset& data, const Nodes& nodes, const GaussianModel<float>& model,
                               smg::ParallelOptions parallel = {}, std::vector<Image>* renders = nullptr);

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

}  // namespace trainer
