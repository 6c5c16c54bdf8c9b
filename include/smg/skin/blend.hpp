// smg/skin/blend.hpp — dual-quaternion blending (and LBS) of many points at many query times:
// forward, per-point Jacobians, and the batched vector-Jacobian product (backward) into node and
// point gradient buffers.
//
// For every query frame t = t_query[q] and point p (drivers, weights, t_ref, reference pose:
// SkinPoints), out[q][p] = the blended motion t_ref[p] -> t applied to the point's reference
// position and rotation (equations (S6)-(S13), smg/skin/blend_point.hpp). Node and point
// quaternions are normalised on entry; rotation gradients are right-tangent 3-vectors of the
// normalised quaternions unless a field says "raw".
//
// Determinism: points are split into chunks that depend only on P; each point's outputs and
// point gradients are written by its own chunk; gradients into node buffers are scatter-added
// through SkinWorkspace's incidence in the fixed order (node, query, point, driver). Results
// are bit-identical for any thread count. Allocation: per parallel chunk (scratch of D drivers)
// and in the workspace (resized only when the sizes or the driver table change). The views,
// validators and per-element steps these loops share with the CUDA kernels: blend_element.hpp.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/skin/blend_element.hpp"
#include "smg/skin/blend_point.hpp"
#include "smg/skin/skin_views.hpp"

namespace smg {

// Blends every point at every query frame (S6)-(S13) with options.method (DQB or LBS) and writes
// the requested outputs; `parallel` sets the CPU threads. Precondition: validate_skin_blend.
template <class S>
void skin_blend(const SkinNodes<S>& nodes, const SkinPoints<S>& points, SkinIndexView t_query,
                const SkinBlendOutputs<S>& out, const SkinOptions& options = {},
                ParallelOptions parallel = {}) {
  const Index Q = t_query.rows(), Dmax = points.width();
  SMG_ASSERT(nodes.quaternions.frames() == nodes.frames() &&
                 nodes.quaternions.nodes() == nodes.nodes(),
             "skin_blend: node quaternions shape");
  SMG_ASSERT(points.weights.rows() == points.count() && points.weights.cols() == Dmax &&
                 points.t_ref.rows() == points.count() && points.positions.rows() == points.count(),
             "skin_blend: points shape");
  SMG_ASSERT(out.positions.data() == nullptr ||
                 (out.positions.frames() == Q && out.positions.nodes() == points.count()),
             "skin_blend: output positions shape");
  SMG_ASSERT(out.quaternions.data() == nullptr ||
                 (out.quaternions.frames() == Q && out.quaternions.nodes() == points.count()),
             "skin_blend: output quaternions shape");
  const SkinMethod method = options.method;
  parallel_for(
      points.count(),
      [&](Index begin, Index end) {
        std::vector<SkinDriver<S>> d(static_cast<std::size_t>(Dmax));
        detail::SkinBlendState<S> st;
        for (Index p = begin; p < end; ++p) {
          const Index D = detail::skin_load_ref(nodes, points, p, true, d.data());
          const Vector3<S> x = points.positions.row(p);
          const Quaternion<S> qp = detail::skin_point_quaternion(points.quaternions, p);
          for (Index q = 0; q < Q; ++q) {
            detail::skin_load_query(nodes, points, p, t_query(q, 0), D, d.data());
            detail::skin_blend_forward(method, d.data(), D, x, qp, st);
            detail::skin_store_outputs(method, d.data(), D, Dmax, x, qp, st, out, q, p);
          }
        }
      },
      parallel);
}

// Backward of skin_blend (the vector-Jacobian product): adds to `grads` the gradient of a loss
// L given dL/d(outputs) (S14)-(S18). Weights are treated as inputs (their gradient goes to
// grads.weights if requested; chain with skinning_weights_backward to differentiate the
// weights themselves). The forward is recomputed (it costs about as much as reading a cache).
// Each query frame is one pass over the points (writing per-edge contributions into the
// workspace) and one pass over the nodes (adding them in the fixed order).
template <class S>
void skin_blend_backward(const SkinNodes<S>& nodes, const SkinPoints<S>& points,
                         SkinIndexView t_query, const SkinBlendOutputGradients<S>& grad_out,
                         const SkinBlendGradients<S>& grads, SkinWorkspace<S>& ws,
                         const SkinOptions& options = {}, ParallelOptions parallel = {}) {
  const Index Q = t_query.rows(), P = points.count(), Dmax = points.width(), N = nodes.nodes();
  const Index T = nodes.frames();
  SMG_ASSERT(nodes.quaternions.frames() == T && nodes.quaternions.nodes() == N,
             "skin_blend_backward: node quaternions shape");
  SMG_ASSERT(points.weights.rows() == P && points.weights.cols() == Dmax &&
                 points.t_ref.rows() == P && points.positions.rows() == P,
             "skin_blend_backward: points shape");
  SMG_ASSERT(grads.node_positions.data() == nullptr ||
                 (grads.node_positions.frames() == T && grads.node_positions.nodes() == N),
             "skin_blend_backward: grad node_positions shape");
  SMG_ASSERT(grads.node_rotations.data() == nullptr ||
                 (grads.node_rotations.frames() == T && grads.node_rotations.nodes() == N),
             "skin_blend_backward: grad node_rotations shape");
  SMG_ASSERT(grads.node_quaternions.data() == nullptr ||
                 (grads.node_quaternions.frames() == T && grads.node_quaternions.nodes() == N),
             "skin_blend_backward: grad node_quaternions shape");
  (void)T;
  const SkinMethod method = options.method;
  const bool to_nodes = grads.node_positions.data() || grads.node_rotations.data() ||
                        grads.node_quaternions.data();
  constexpr Index kStride = detail::kSkinEdgeStride;
  if (to_nodes) {
    ws.incidence.update(points.drivers, N);
    ws.edge_buffer.resize(ws.incidence.edges.size() * kStride);
  }
  S* buf = ws.edge_buffer.data();
  const auto& inc = ws.incidence;
  for (Index q = 0; q < Q; ++q) {
    const Index t = t_query(q, 0);
    parallel_for(
        P,
        [&](Index begin, Index end) {
          std::vector<SkinDriver<S>> d(static_cast<std::size_t>(Dmax));
          detail::SkinBlendState<S> st;
          for (Index p = begin; p < end; ++p)
            detail::skin_backward_point(
                method, nodes, points, q, t, p, grad_out, grads, d.data(), st, [&](Index k) {
                  return to_nodes ? buf + inc.slot[static_cast<std::size_t>(p * Dmax + k)] * kStride
                                  : nullptr;
                });
        },
        parallel);
    if (!to_nodes) continue;
    parallel_for(
        N,
        [&](Index begin, Index end) {
          for (Index n = begin; n < end; ++n) {
            Vector3<S> gx_t = Vector3<S>::Zero(), gphi_t = Vector3<S>::Zero();
            for (Index i = inc.offsets[n]; i < inc.offsets[n + 1]; ++i) {
              const Index e = inc.edges[static_cast<std::size_t>(i)];
              const S* g = buf + i * kStride;
              const Index tr = points.t_ref(e / Dmax, 0);
              gx_t += Eigen::Map<const Vector3<S>>(g);
              gphi_t += Eigen::Map<const Vector3<S>>(g + 6);
              if (grads.node_positions.data())
                grads.node_positions(tr, n) += Eigen::Map<const Vector3<S>>(g + 3);
              if (grads.node_rotations.data())
                grads.node_rotations(tr, n) -= Eigen::Map<const Vector3<S>>(g + 6);
              if (grads.node_quaternions.data()) {
                const Vector3<S> minus_phi = -Eigen::Map<const Vector3<S>>(g + 6);
                add_quaternion_gradient_from_tangent(nodes.quaternions.ptr(tr, n),
                                                     minus_phi.data(),
                                                     grads.node_quaternions.ptr(tr, n));
              }
            }
            if (inc.offsets[n + 1] == inc.offsets[n]) continue;
            if (grads.node_positions.data()) grads.node_positions(t, n) += gx_t;
            if (grads.node_rotations.data()) grads.node_rotations(t, n) += gphi_t;
            if (grads.node_quaternions.data())
              add_quaternion_gradient_from_tangent(nodes.quaternions.ptr(t, n), gphi_t.data(),
                                                   grads.node_quaternions.ptr(t, n));
          }
        },
        parallel);
  }
}

}  // namespace smg
