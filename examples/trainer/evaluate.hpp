// examples/trainer/evaluate.hpp — the evaluation of a run: held-out views and 3D tracking error
// (procedural scene), or the validation frames (a scene from disk; data_evaluate.hpp).
//
// Procedural scene: image metrics (metrics.hpp) on the two fixed test cameras at every frame, averaged over frames
// (Dycheck's mPSNR / mSSIM are per-frame means):
//   psnr, ssim                  the whole image
//   psnr_masked, ssim_masked    co-visible pixels only (Dycheck's protocol; dataset.hpp)
//   psnr_box                    the static box's pixels (ground-truth segmentation of the test
//                               view; the region where motion leaking from the arm shows)
//   psnr_objects                pixels of any foreground object (arm, box, ball)
// and the training view's PSNR (how well the model fits what it was trained on).
//
// 3D tracking error of the node trajectories against the true motion of their tracks
// (tracking_error: EPE, fractions within 5% and 10% of the scene extent) over all samples, per
// object (arm, box, ball), and over the samples where the node was not observed ("hidden":
// there only the regularisers and the photometric loss decide the motion).
#pragma once

#include <string>
#include <vector>

#include "trainer/data_evaluate.hpp"  // FrameScore, evaluate_frames
#include "trainer/dataset.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/image.hpp"
#include "trainer/metrics.hpp"
#include "trainer/nodes.hpp"

namespace trainer {

struct ViewMetrics {
  std::string name;
  double psnr = 0, ssim = 0, psnr_masked = 0, ssim_masked = 0, psnr_box = 0, psnr_objects = 0;
  std::vector<double> psnr_per_frame, psnr_box_per_frame;
};

struct TrackMetrics {
  TrackingError all, box, arm, ball, hidden, box_hidden;
};

// The evaluation of a run: the procedural scene's test views (with truth) and the validation
// frames of a scene from disk (Dycheck's protocol). A dataset has one or the other; each part
// is empty where its data is.
struct Evaluation {
  // Test views (Dataset::truth).
  std::vector<ViewMetrics> views;
  ViewMetrics mean;        // the mean over the test views
  double train_psnr = 0;   // training view, all frames
  TrackMetrics tracks;
  std::vector<std::vector<Image>> renders;  // [test views + 1][T], the training view last (if asked)
  // Validation frames (Dataset::eval).
  std::vector<FrameScore> frames;           // [V] in Dataset::eval order
  FrameScore frames_mean;                   // the mean over every validation frame of every camera
  std::vector<Image> frame_renders;         // [V] (if asked)
  double seconds = 0;
};

// 3D tracking error of the nodes.
TrackMetrics track_metrics(const Scene& scene, const Nodes& nodes);

// Node EPE (track_metrics' `all`) split by what explains it (docs/results.md, "Why node EPE and
// query EPE disagree"), procedural scenes only:
//   failed / clean: samples whose lifted track was a failed tracker report (Nodes::failed_report)
//     and the others;
//   conf_low / conf_mid / conf_high: samples by `confidence` [T][N] below 0.3, 0.3 to 0.7, from
//     0.7 (the caller passes the confidences of the lifted trajectories: stage 0 is shared by
//     every variant, so the bands hold the same samples in each);
//   driving / idle: nodes with skinning weight > 0 on the query points (`node_weight` [N],
//     score_queries) and nodes that drive none;
//   weighted_epe: the mean node error weighted by `node_weight` (what the query points see of it).
struct NodeErrorSplit {
  TrackingError failed, clean, conf_low, conf_mid, conf_high, driving, idle;
  double weighted_epe = 0;
};
NodeErrorSplit node_error_split(const Scene& scene, const Nodes& nodes, const std::vector<double>& confidence,
                                const std::vector<double>& node_weight);

// Renders what the dataset has to evaluate against and scores it: with truth, both test views and
// the training view at every frame, and the nodes' tracking error; the validation frames, each
// at its training frame (EvalFrame::frame) through its own camera. With `keep_renders` the
// rendered images are kept in the result.
Evaluation evaluate(const Dataset& data, const Nodes& nodes, const GaussianModel<float>& model,
                    smg::ParallelOptions parallel = {}, bool keep_renders = false);

}  // namespace trainer
