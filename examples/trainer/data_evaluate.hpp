// examples/trainer/data_evaluate.hpp — a scene from disk scored on its validation frames with Dycheck's metrics (docs/data.md).
#pragma once

#include <string>
#include <vector>

#include "trainer/dataset.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/image.hpp"
#include "trainer/nodes.hpp"

namespace trainer {

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

}  // namespace trainer
