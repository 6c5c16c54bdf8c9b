// examples/trainer/evaluate.hpp — held-out views and 3D tracking error.
//
// Image metrics (metrics.hpp) on the two fixed test cameras at every frame, averaged over frames
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

struct Evaluation {
  std::vector<ViewMetrics> views;
  ViewMetrics mean;        // the mean over the test views
  double train_psnr = 0;   // training view, all frames
  TrackMetrics tracks;
  double seconds = 0;
};

// 3D tracking error of the nodes.
TrackMetrics track_metrics(const Scene& scene, const Nodes& nodes);

// Renders both test views (and the training view) at every frame and computes every metric.
// renders (optional, out): [views + 1][T] images, test views first, the training view last.
Evaluation evaluate(const Dataset& data, const Nodes& nodes, const GaussianModel<float>& model,
                    smg::ParallelOptions parallel = {}, std::vector<std::vector<Image>>* renders = nullptr);

}  // namespace trainer
