// examples/trainer/stage2.hpp — stage 2: Gaussians and nodes optimised together against the
// training images (photometric L1 + expected-depth L1), with the nodes' stage-1 objective
// (data term + the variant's regularisers) kept on, and simple density control (pruning).
//
// Per iteration: one training frame (a seeded random permutation per epoch, as 3DGS picks
// cameras), DQB-posed dynamic Gaussians + static Gaussians rendered with the library's
// splatter, loss
//   L = mean_{pixels, channels} |I - I*| + lambda_depth * mean_{pixels with depth} |D - D*|
//       + node_weight * E_nodes                                              (nodes.hpp)
// and Adam on every Gaussian parameter (raw quaternions, as 3DGS) and on the node positions
// and rotations (right-tangent steps). Gradients: render_backward -> skin_blend_backward for
// the photometric part, the library's energies for E_nodes. Skinning weights are constants
// (stop-gradient) and are recomputed at every density-control step.
#pragma once

#include <cstdint>

#include "trainer/dataset.hpp"
#include "trainer/gaussians.hpp"
#include "trainer/nodes.hpp"
#include "trainer/progress.hpp"

namespace trainer {

struct Stage2Options {
  int iterations = 1200;
  double lambda_depth = 0.1;
  // Learning rates (Adam steps): means and node positions in metres, log-decayed to *_final.
  double lr_means = 5e-4, lr_means_final = 5e-5;
  double lr_quats = 2e-3;
  double lr_log_scales = 5e-3;
  double lr_opacity = 2.5e-2;
  double lr_colors = 5e-3;
  double lr_node_position = 2e-4, lr_node_position_final = 2e-5;
  double lr_node_rotation = 2e-3, lr_node_rotation_final = 2e-4;
  double node_weight = 1.0;  // weight of the nodes' objective relative to stage 1
  // hold (--stage2-unobserved hold): no photometric gradient reaches node i's pose at frame t
  // when its track is unobserved there (Nodes::visible[t][i] == 0), so that only the
  // regularisers move the nodes where no observation carries evidence; move (false): the
  // photometric gradient reaches every pose the render reads (the rendered frame's and the
  // Gaussians' reference frames').
  bool hold_unobserved = false;
  int confidence_every = 50;
  // Density control: prune every prune_every iterations in [prune_from, iterations - prune_tail).
  int prune_every = 250, prune_from = 500, prune_tail = 200;
  double prune_opacity = 0.01;  // below: removed
  double prune_scale = 0.15;    // metres; a Gaussian larger than this is removed
  int log_every = 200;
  std::uint64_t seed = 0;
};

// Mean wall time per iteration of each part of a stage-2 iteration (milliseconds), measured
// with steady_clock around the calls; `other` is the rest (node conversion, gradient zeroing,
// density control).
struct Stage2Timing {
  double skin_forward = 0, render_forward = 0, loss = 0, render_backward = 0, skin_backward = 0;
  double regularisers = 0, adam = 0, other = 0, total = 0;
};

struct Stage2Result {
  int iterations = 0;
  double seconds = 0;
  double last_l1 = 0, last_depth = 0;  // mean over the last 10% of iterations
  NodeLossTerms nodes_final;
  int pruned = 0;
  int gaussians = 0, fixed = 0;
  Stage2Timing timing;
};

Stage2Result train_gaussians(const Dataset& data, Nodes& nodes, NodeObjective& objective, GaussianModel<float>& model,
                             const Stage2Options& options, const Progress& progress,
                             smg::ParallelOptions parallel = {});

// The loss of one rendered frame and its gradient with respect to image and depth:
// mean |I - I*| over pixels and channels, plus lambda_depth * mean |D - D*| over pixels where
// the depth prior is > 0. Writes dL/dI and dL/dD (dL/dD = 0 where there is no depth prior).
template <class S>
void photometric_loss(const S* image, const S* depth, const float* target_rgb, const float* target_depth, int width,
                      int height, double lambda_depth, S* grad_image, S* grad_depth, double* l1, double* depth_l1);

}  // namespace trainer
