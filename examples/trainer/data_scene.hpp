// examples/trainer/data_scene.hpp — the trainer on a scene from disk (docs/data.md): a Dycheck
// iPhone folder plus priors turned into the trainer's Dataset, and the scene's length scale.
// Its evaluation on the validation frames is data_evaluate.hpp, 3D query tracks data_queries.hpp,
// and the exporter that writes the procedural scene in that layout data_export.hpp.
//
// How a scene from disk enters the pipeline (docs/data.md section 5):
//   training frames  -> Dataset::images[t], Dataset::cameras[t] (sorted by time id)
//   sensor depth     -> Priors::depth (lifting, Gaussian initialisation, depth loss)
//   priors/masks     -> Priors::object_mask (dynamic Gaussians and node tracks inside, static
//                       Gaussians outside); frames without a mask seed no Gaussians
//   priors/features  -> Priors::features on their own grid, sampled bilinearly (graph gate)
//   priors/tracks    -> Priors::tracks (reported uv and visibility; no truth)
//   validation frames-> Dataset::eval, each rendered at the training frame of the nearest time id
// Lengths of the configuration tuned in metres on the procedural scene are multiplied by
// scene_extent / kReferenceExtent, so the scene's own scale decides them (pipeline.hpp).
#pragma once

#include <vector>

#include "trainer/dataset.hpp"
#include "trainer/dycheck.hpp"

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

}  // namespace trainer
