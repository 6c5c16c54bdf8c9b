// examples/trainer/data_evaluate.hpp — a scene from disk scored on its validation frames with Dycheck's metrics (docs/data.md).
#pragma once

#include <string>
#include <vector>

#include "trainer/dataset.hpp"
#include "trainer/evaluate.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/image.hpp"
#include "trainer/nodes.hpp"

namespace trainer {

// The validation-frame part of evaluate() (evaluate.hpp): renders every validation frame (the
// model at EvalFrame::frame, through the frame's camera), scores it into e->frames and
// e->frames_mean, and keeps the renders in e->frame_renders when `keep_renders`.
void evaluate_frames(const Dataset& data, const Nodes& nodes, const GaussianModel<float>& model,
                     smg::ParallelOptions parallel, bool keep_renders, Evaluation* e);

}  // namespace trainer
