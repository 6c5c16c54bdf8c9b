// examples/torch/smg_torch_skin_views.hpp — smg's skin views over dqb's checked tensors
// (SkinInputs, smg_torch_common.hpp), shared by the CPU operator (smg_torch_skin.cpp) and the CUDA
// launches (smg_torch_cuda.cu).
#pragma once

#include "smg/skin/blend.hpp"
#include "smg_torch_common.hpp"

namespace smg_torch {

// Node positions [T, N, 3] and quaternions [T, N, 4].
template <class S>
smg::SkinNodes<S> nodes_of(const SkinInputs& in) {
  return {smg::PositionsView<const S>(cptr<S>(in.x), in.T, in.N),
          smg::QuaternionsView<const S>(cptr<S>(in.q), in.T, in.N)};
}

// Points with their drivers [P, D] int32, weights [P, D], t_ref, positions and quaternions.
template <class S>
smg::SkinPoints<S> points_of(const SkinInputs& in, const at::Tensor& drivers,
                             const at::Tensor& weights) {
  smg::SkinPoints<S> p;
  p.drivers = smg::SkinDriversView(cptr<std::int32_t>(drivers), in.P, drivers.size(1));
  p.weights = smg::TableView<const S, Eigen::Dynamic>(cptr<S>(weights), in.P, weights.size(1));
  p.t_ref = smg::SkinIndexView(cptr<std::int32_t>(in.t_ref), in.P);
  p.positions = smg::TableView<const S, 3>(cptr<S>(in.pts), in.P);
  if (in.pq.defined()) p.quaternions = smg::TableView<const S, 4>(cptr<S>(in.pq), in.P);
  return p;
}

// The incoming gradients [Q, P, 3] / [Q, P, 4] (undefined = not given).
template <class S>
smg::SkinBlendOutputGradients<S> output_gradients(const SkinInputs& in, const at::Tensor& grad_x,
                                                  const at::Tensor& grad_q) {
  smg::SkinBlendOutputGradients<S> go;
  if (grad_x.defined()) go.positions = {cptr<S>(grad_x), in.Q, in.P};
  if (grad_q.defined()) go.quaternions = {cptr<S>(grad_q), in.Q, in.P};
  return go;
}

// The requested gradients (undefined = not computed) w.r.t. node positions, raw node
// quaternions, points and raw point quaternions.
template <class S>
smg::SkinBlendGradients<S> blend_gradients(const SkinInputs& in, const at::Tensor& gx,
                                           const at::Tensor& gq, const at::Tensor& gp,
                                           const at::Tensor& gpq) {
  smg::SkinBlendGradients<S> gr;
  if (gx.defined()) gr.node_positions = {mptr<S>(gx), in.T, in.N};
  if (gq.defined()) gr.node_quaternions = {mptr<S>(gq), in.T, in.N};
  if (gp.defined()) gr.points = {mptr<S>(gp), in.P};
  if (gpq.defined()) gr.point_quaternions = {mptr<S>(gpq), in.P};
  return gr;
}

}  // namespace smg_torch
