// examples/trainer/data_evaluate.hpp — a scene from disk scored on its validation frames with Dycheck's metrics (docs/data.md).
// Below evaluate.hpp, which holds the results of both kinds of scene: this file knows nothing of
// it, so that the evaluation's modules depend one way.
#pragma once

#include <string>
#include <vector>

#include "trainer/dataset.hpp"
#include "trainer/dycheck_metrics.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/image.hpp"
#include "trainer/nodes.hpp"

namespace trainer {

// Image metrics of one validation frame (Dycheck's definitions, dycheck_metrics.hpp), with the
// frame's name: the metrics' own struct, so that a metric added there needs no copy here.
struct FrameScore : DycheckImageMetrics {
  std::string name;
};

// The validation-frame part of evaluate() (evaluate.hpp): renders every validation frame (the
// model at EvalFrame::frame, through the frame's camera), scores it into `frames` (replaced, in
// Dataset::eval order) and `mean` (the mean over every frame), and keeps the renders in `renders`
// when it is given.
void evaluate_frames(const Dataset& data, const Nodes& nodes, const GaussianModel<float>& model,
                     smg::ParallelOptions parallel, std::vector<FrameScore>* frames, FrameScore* mean,
                     std::vector<Image>* renders = nullptr);

}  // namespace trainer
