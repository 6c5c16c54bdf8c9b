// examples/trainer/pictures.hpp — what a person looks at after a run.
//
// write_pictures writes into the output folder:
//   <test view>.png    strip per test view: rows = frames, columns = ground truth | render |
//                      absolute error x4
//   contact_sheet.png  over time (columns = frames): training view ground truth and render, then
//                      each test view's ground truth and render
//   nodes.png          the node trajectories seen from the test views: ground-truth position
//                      (white ring) and estimate (dot coloured by error: green < 5% of the
//                      extent, orange < 10%, red beyond), on the dimmed ground-truth image
// Returns the paths written.
#pragma once

#include <string>
#include <vector>

#include "trainer/image.hpp"
#include "trainer/pipeline.hpp"

namespace trainer {

std::vector<std::string> write_pictures(const std::string& dir, const TrainerResult& result, int frames_shown = 6);

}  // namespace trainer
