// examples/trainer/gaussians.hpp — the stage-2 model: static and node-driven Gaussians, their
// initialisation, rendering through the library's splatter with DQB skinning, the backward into
// Gaussian and node parameters, and density control.
//
// One parameter table holds every Gaussian; rows [0, fixed) are static, rows [fixed, G) are
// dynamic. A dynamic row stores its reference pose (position and rotation at t_ref) and is
// driven at frame t by dual-quaternion blending of its drivers' motion t_ref -> t
// (smg::skin_blend: the anchor node nearest to it at t_ref and the anchor's graph neighbours,
// weights softmax(-|p - x_k(t_ref)|^2 / 2 sigma_k^2), held constant: stop-gradient).
// Colours are plain RGB (sh_degree -1): the scene's appearance is view independent.
//
// Rendering frame t: the dynamic rows' poses are blended into a render table, the static rows
// are copied, and smg::splat::render_forward draws colour, alpha and expected depth. The
// backward (smg::splat::render_backward then smg::skin_blend_backward) gives gradients for
// every Gaussian parameter (raw quaternions, as 3DGS optimises them) and for the node
// positions and rotations (right tangent) at frame t and at the reference frames.
//
// Templated on the scalar: float for training, double for the gradient checks in the tests.
#pragma once

#include <cstdint>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/views.hpp"
#include "smg/skin.hpp"
#include "smg/splat.hpp"
#include "trainer/camera.hpp"
#include "trainer/dataset.hpp"
#include "trainer/nodes.hpp"

namespace trainer {

// Parameters of G Gaussians, in the splatter's layouts.
template <class S>
struct GaussianTable {
  std::vector<S> means;       // [G][3]
  std::vector<S> quats;       // [G][4] (w, x, y, z), any nonzero norm
  std::vector<S> log_scales;  // [G][3]
  std::vector<S> opacity;     // [G] logits
  std::vector<S> colors;      // [G][3] RGB

  int size() const { return static_cast<int>(opacity.size()); }
  void resize(int G);
  void fill(S value);
  // Keeps rows with keep[row] != 0, in order.
  void compact(const std::vector<std::uint8_t>& keep);
  // Appends row r of `other`.
  void push_row(const GaussianTable& other, int r);
};

// How dynamic rows are attached to the nodes (indexed by row - fixed).
template <class S>
struct Skinning {
  int width = 0;                       // D = graph k + 1
  std::vector<std::int32_t> drivers;   // [P][D] anchor first, -1 padded
  std::vector<S> weights;              // [P][D]
  std::vector<std::int32_t> t_ref;     // [P]
  std::vector<S> sigma;                // [N] skinning length scale per node (metres)
};

template <class S>
struct GaussianModel {
  int fixed = 0;           // rows [0, fixed) are static
  GaussianTable<S> table;  // all rows; dynamic rows hold the reference pose
  Skinning<S> skin;
  int count() const { return table.size(); }
  int dynamic() const { return table.size() - fixed; }
};

// Node trajectories in the model's scalar (stage 2 keeps the nodes in double and converts
// them for every render).
template <class S>
struct NodeState {
  int frames = 0, count = 0;
  std::vector<S> positions;  // [T][N][3]
  std::vector<S> rotations;  // [T][N][4]
  void assign(const Nodes& n);
  smg::SkinNodes<S> skin_nodes() const {
    return {smg::PositionsView<const S>(positions.data(), frames, count),
            smg::QuaternionsView<const S>(rotations.data(), frames, count)};
  }
};

// Gradients of a loss with respect to the model and the nodes (same layouts; node rotations in
// the right tangent [T][N][3]).
template <class S>
struct ModelGrads {
  GaussianTable<S> table;
  std::vector<S> node_positions;
  std::vector<S> node_rotations;
  void zero(int gaussians, int frames, int nodes);
};

// The splatter's camera from the trainer's.
template <class S>
smg::splat::Camera<S> splat_camera(const Camera& camera);

struct InitOptions {
  std::vector<int> static_frames;   // training frames whose non-object pixels seed static Gaussians
  int static_stride = 2;            // every stride-th pixel in x and y
  std::vector<int> dynamic_frames;  // reference frames whose object pixels seed dynamic Gaussians
  int dynamic_stride = 1;
  double opacity = 0.5;             // initial opacity
  double scale = 0.7;               // initial sigma = scale * stride * depth / f (pixel footprint)
  double max_anchor_distance = 1.5; // in node units: farther object pixels are dropped (mask
                                    // dilation and flying depth pixels at object edges)
  double sigma = 1.0;               // skinning sigma = sigma * node unit
};

// Builds the initial model from the dataset's priors (depth, object mask, training images) and
// the nodes after stage 1. Static Gaussians: back-projected non-object pixels with depth;
// dynamic: back-projected object pixels attached to the nearest node at their frame.
template <class S>
GaussianModel<S> init_model(const Dataset& data, const Nodes& nodes, const InitOptions& options,
                            smg::ParallelOptions parallel = {});

// Recomputes the skinning weights of every dynamic row from the current node positions at its
// reference frame (drivers unchanged).
template <class S>
void update_skinning_weights(GaussianModel<S>& model, const NodeState<S>& nodes, smg::ParallelOptions parallel = {});

// The model's dynamic rows as smg's skinning input: views into the model (drivers, weights and
// reference frames [P], reference positions and rotations of rows [fixed, count)).
template <class S>
smg::SkinPoints<S> skin_points(const GaussianModel<S>& model);

// The model posed at frame t: every row's position (means [G][3]) and rotation (quats [G][4],
// (w, x, y, z)); static rows copied, dynamic rows blended by smg::skin_blend (DQB) from their
// reference pose. What ModelRenderer::render draws, and what OUT/ply/frame_<t>.ply holds (ply.hpp).
template <class S>
void pose_model(const GaussianModel<S>& model, const NodeState<S>& nodes, int t, std::vector<S>* means,
                std::vector<S>* quats, smg::ParallelOptions parallel = {});

// Renders a model at frame t and back-propagates image gradients into model and node gradients.
template <class S>
class ModelRenderer {
 public:
  // Draws the model at frame t through `camera`: image [H][W][3], alpha and depth [H][W]
  // (alpha, depth optional: null).
  void render(const GaussianModel<S>& model, const NodeState<S>& nodes, int t, const smg::splat::Camera<S>& camera,
              S* image, S* alpha, S* depth, smg::ParallelOptions parallel = {});
  // Given dL/dimage (and optionally dL/ddepth) of the last render, *adds* dL/d(parameters) and
  // dL/d(node poses) to `grads` (sized by ModelGrads::zero).
  void backward(const GaussianModel<S>& model, const NodeState<S>& nodes, const smg::splat::Camera<S>& camera,
                const S* grad_image, const S* grad_depth, ModelGrads<S>& grads, smg::ParallelOptions parallel = {});

  // Wall time spent in each library call since construction (seconds; stage 2 prints the means
  // per iteration). steady_clock reads cost ~20 ns, nothing next to the calls they time.
  struct Times {
    double skin_forward = 0, render_forward = 0, render_backward = 0, skin_backward = 0;
  };
  const Times& times() const { return times_; }

  const smg::splat::RenderWorkspace<S>& workspace() const { return ws_; }
  // Positions [G][3] of every Gaussian at the last rendered frame.
  const std::vector<S>& posed_means() const { return means_; }

 private:
  smg::splat::GaussianParams<S> params(const GaussianModel<S>& model) const;
  int t_ = 0;
  std::vector<S> means_, quats_;  // [G][3], [G][4] posed at frame t_
  smg::splat::RenderWorkspace<S> ws_;
  smg::SkinWorkspace<S> skin_ws_;
  GaussianTable<S> g_;  // render gradients
  std::vector<S> g_quats_tangent_;
  Times times_;
};

// Density control: removes Gaussians whose opacity is below min_opacity or whose largest scale
// exceeds max_scale (metres). keep (out) is the row mask applied. Returns the number removed.
template <class S>
int prune(GaussianModel<S>& model, double min_opacity, double max_scale, std::vector<std::uint8_t>* keep);

}  // namespace trainer
