// smg/skin/blend_element.hpp — one (query, point) element of the batched blend and what the CPU
// loops (skin/blend.hpp) and the CUDA kernels (cuda/dqb.cuh) share: the output and gradient
// views, their shape checks and validators (validate_skin_blend, validate_skin_blend_backward),
// the store of one element's outputs and one point's backward step (docs/math/skin.md
// (S6)-(S18)). Why a header of its own: device headers must not reach the CPU thread pool
// (core/parallel.hpp), which the loops in blend.hpp use.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/core/quaternion.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/validate.hpp"
#include "smg/skin/blend_point.hpp"
#include "smg/skin/skin_views.hpp"

namespace smg {

// What skin_blend writes; each view is optional (null data = not computed).
template <class S>
struct SkinBlendOutputs {
  SequenceView<S, 3> positions;    // [Q][P][3] blended positions p'
  SequenceView<S, 4> quaternions;  // [Q][P][4] blended rotations q' (w, x, y, z), unit
  // [Q][P][D·78]: for driver column k, a row-major 6x13 block (SkinDriverJacobian: rows p', θ';
  // columns x_ref, φ_ref, x_t, φ_t, weight); zero for padding columns. The nodes are
  // drivers[p][k] at frames t_ref[p] (x_ref, φ_ref) and t_query[q] (x_t, φ_t).
  SequenceView<S, Eigen::Dynamic> J_drivers;
  SequenceView<S, Eigen::Dynamic> J_point;  // [Q][P][36]: row-major 6x6 (SkinPointJacobian)
};

// Scalars of one driver column of SkinBlendOutputs::J_drivers (a row-major 6x13
// SkinDriverJacobian) and of one point's J_point (a row-major 6x6 SkinPointJacobian).
constexpr Index kSkinDriverJacobianSize = 6 * 13;
constexpr Index kSkinPointJacobianSize = 6 * 6;

namespace detail {
template <class S>
inline Status check_skin_common(const SkinNodes<S>& nodes, const SkinPoints<S>& points,
                                SkinIndexView t_query) {
  const Index T = nodes.frames(), N = nodes.nodes();
  if (Status s = validate_positions<S>(nodes.positions, -1, -1, "positions"); !s) return s;
  if (Status s = validate_quaternions<S>(nodes.quaternions, T, N,
                                         QuaternionNorm::normalize_on_entry, "quaternions");
      !s)
    return s;
  if (Status s = check_points(points, T, N, true); !s) return s;
  return check_index_array(t_query, t_query.rows(), T, "t_query", "T");
}
template <class S, int Dim>
inline Status check_qp_view(SequenceView<S, Dim> v, Index Q, Index P, Index dim,
                            const std::string& name) {
  if (v.frames() != Q || v.nodes() != P || v.dim() != dim) {
    std::ostringstream s;
    s << name << ": expected shape [Q=" << Q << "][P=" << P << "][" << dim << "], got ["
      << v.frames() << "][" << v.nodes() << "][" << v.dim() << "]";
    return skin_error(s.str());
  }
  if (v.size() > 0 && v.data() == nullptr) return skin_error(name + ": null data pointer");
  return Status::ok();
}

// The shapes of skin_blend's non-empty outputs for Q query frames, P points and D driver
// columns (the CPU validator and the CUDA launcher check the same).
template <class S>
inline Status check_blend_outputs(const SkinBlendOutputs<S>& out, Index Q, Index P, Index D) {
  if (out.positions.data())
    if (Status s = check_qp_view(out.positions, Q, P, 3, "out_positions"); !s) return s;
  if (out.quaternions.data())
    if (Status s = check_qp_view(out.quaternions, Q, P, 4, "out_quaternions"); !s) return s;
  if (out.J_drivers.data())
    if (Status s = check_qp_view(out.J_drivers, Q, P, D * kSkinDriverJacobianSize, "J_drivers"); !s)
      return s;
  if (out.J_point.data())
    if (Status s = check_qp_view(out.J_point, Q, P, kSkinPointJacobianSize, "J_point"); !s)
      return s;
  return Status::ok();
}

// Writes element (q, p) of every requested output of `out` from the blend state st of point p
// (reference position x, rotation qp) and its D drivers d: p', q', and the Jacobians (six rows
// of vector-Jacobian products, skin_blend_jacobian_rows), driver columns D .. Dmax − 1 (padding)
// zero. One function for the CPU loop (skin_blend) and the CUDA kernel (cuda/dqb.cuh).
template <class S>
SMG_HOST_DEVICE inline void skin_store_outputs(SkinMethod method, const SkinDriver<S>* d, Index D,
                                               Index Dmax, const Vector3<S>& x,
                                               const Quaternion<S>& qp,
                                               const SkinBlendState<S>& st,
                                               const SkinBlendOutputs<S>& out, Index q, Index p) {
  if (out.positions.data()) {
    S* o = out.positions.ptr(q, p);
    for (int c = 0; c < 3; ++c) o[c] = st.position(c);
  }
  if (out.quaternions.data()) to_wxyz(st.rotation, out.quaternions.ptr(q, p));
  if (out.J_drivers.data()) {
    S* J = out.J_drivers.ptr(q, p);
    for (Index k = D * kSkinDriverJacobianSize; k < Dmax * kSkinDriverJacobianSize; ++k) J[k] = S(0);
  }
  if (!out.J_drivers.data() && !out.J_point.data()) return;
  skin_blend_jacobian_rows(
      method, d, D, x, qp, st,
      [&](int row, Index k, const SkinDriverGradient<S>& g) {
        if (!out.J_drivers.data()) return;
        // Row `row` of driver k's 6x13 block: columns x_ref, φ_ref, x_t, φ_t, weight.
        S* J = out.J_drivers.ptr(q, p) + k * kSkinDriverJacobianSize + row * 13;
        for (int c = 0; c < 3; ++c) {
          J[c] = g.x_ref(c);
          J[3 + c] = g.phi_ref(c);
          J[6 + c] = g.x_t(c);
          J[9 + c] = g.phi_t(c);
        }
        J[12] = g.weight;
      },
      [&](int row, const Vector3<S>& g_p, const Vector3<S>& g_phi_p) {
        if (!out.J_point.data()) return;
        // Row `row` of the point's 6x6 block: columns p, φ_p.
        S* J = out.J_point.ptr(q, p) + row * 6;
        for (int c = 0; c < 3; ++c) {
          J[c] = g_p(c);
          J[3 + c] = g_phi_p(c);
        }
      });
}
}  // namespace detail

// Checks skin_blend's arguments: positions [T][N][3] finite; quaternions [T][N][4] finite,
// nonzero; drivers [P][D] (entries in [−1, N), trailing padding, entry 0 valid); weights [P][D]
// finite, >= 0, 0 on padding, positive maximum per point; t_ref [P] and t_query [Q] in [0, T);
// points [P][3] finite; point_quats absent or [P][4] finite nonzero; each non-empty output's
// shape.
template <class S>
Status validate_skin_blend(const SkinNodes<S>& nodes, const SkinPoints<S>& points,
                           SkinIndexView t_query, const SkinBlendOutputs<S>& out) {
  if (Status s = detail::check_skin_common(nodes, points, t_query); !s) return s;
  return detail::check_blend_outputs(out, t_query.rows(), points.count(), points.width());
}

// dL/d(outputs) given to skin_blend_backward; each optional (null data = zero). The rotation
// gradient may be given in the right tangent of q' ([Q][P][3]) and/or as the raw 4-vector
// dL/dq' ([Q][P][4], w, x, y, z — what an autograd framework holding q' as a tensor produces;
// its component along q' is ignored, q' being unit by construction). Both are summed.
template <class S>
struct SkinBlendOutputGradients {
  SequenceView<const S, 3> positions;    // [Q][P][3]
  SequenceView<const S, 3> rotations;    // [Q][P][3], right tangent of q'
  SequenceView<const S, 4> quaternions;  // [Q][P][4], raw
};

// Where skin_blend_backward adds (+=) its gradients; each optional (null data = not computed).
// Zero them before the first call if they should hold only this gradient.
template <class S>
struct SkinBlendGradients {
  PositionsView<S> node_positions;        // [T][N][3]
  TangentsView<S> node_rotations;         // [T][N][3], right tangent of the normalised node quats
  QuaternionsView<S> node_quaternions;    // [T][N][4], raw: w.r.t. the given node 4-vectors (Q5)
  TableView<S, 3> points;                 // [P][3] reference positions
  TableView<S, 3> point_rotations;        // [P][3], right tangent of the normalised point quats
  TableView<S, 4> point_quaternions;      // [P][4], raw: w.r.t. the given (unnormalised) 4-vector
  TableView<S, Eigen::Dynamic> weights;   // [P][D], the weights as free inputs (see weights.hpp)
};

namespace detail {
// The shapes of skin_blend_backward's non-empty gradient buffers for T frames, N nodes, P points
// and D driver columns (the CPU validator and the CUDA launcher check the same).
template <class S>
inline Status check_blend_gradients(const SkinBlendGradients<S>& grads, Index T, Index N, Index P,
                                    Index D) {
  if (Status s = validate_optional_output(grads.node_positions, T, N, "grad_node_positions"); !s)
    return s;
  if (Status s = validate_optional_output(grads.node_rotations, T, N, "grad_node_rotations"); !s)
    return s;
  if (Status s = validate_optional_output(grads.node_quaternions, T, N, "grad_node_quaternions");
      !s)
    return s;
  if (grads.points.data())
    if (Status s = check_output_table<S, 3>(grads.points, P, 3, "grad_points"); !s) return s;
  if (grads.point_rotations.data())
    if (Status s = check_output_table<S, 3>(grads.point_rotations, P, 3, "grad_point_rotations");
        !s)
      return s;
  if (grads.point_quaternions.data())
    if (Status s = check_output_table<S, 4>(grads.point_quaternions, P, 4,
                                            "grad_point_quaternions");
        !s)
      return s;
  if (grads.weights.data())
    if (Status s = check_output_table<S, Eigen::Dynamic>(grads.weights, P, D, "grad_weights"); !s)
      return s;
  return Status::ok();
}
}  // namespace detail

namespace detail {
// Scalars of one (point, driver) edge record of skin_blend_backward's point pass:
// ∂L/∂x_t (3), ∂L/∂x_ref (3), ∂L/∂φ_t (3) (= −∂L/∂φ_ref).
constexpr Index kSkinEdgeStride = 9;

// The point pass of skin_blend_backward for point p at query q (frame t): loads its drivers
// into d (scratch of points.width() entries), recomputes the blend into st, adds the point's
// own gradients to grads (points, point_rotations, point_quaternions, weights) and writes the
// edge record of driver k to edge(k) (kSkinEdgeStride scalars; null: not needed) for the node
// pass. One function for the CPU loop and the CUDA kernel (cuda/dqb.cuh).
template <class S, class Edge>
SMG_HOST_DEVICE inline void skin_backward_point(SkinMethod method, const SkinNodes<S>& nodes,
                                                const SkinPoints<S>& points, Index q, Index t,
                                                Index p, const SkinBlendOutputGradients<S>& grad_out,
                                                const SkinBlendGradients<S>& grads,
                                                SkinDriver<S>* d, SkinBlendState<S>& st,
                                                Edge&& edge) {
  const Index D = skin_load_ref(nodes, points, p, true, d);
  skin_load_query(nodes, points, p, t, D, d);
  const Vector3<S> x = points.positions.row(p);
  const Quaternion<S> qp = skin_point_quaternion(points.quaternions, p);
  skin_blend_forward(method, d, D, x, qp, st);
  Vector3<S> gp = Vector3<S>::Zero(), gr = Vector3<S>::Zero();
  if (grad_out.positions.data()) gp = grad_out.positions(q, p);
  if (grad_out.rotations.data()) gr = grad_out.rotations(q, p);
  if (grad_out.quaternions.data()) {
    // (S17): raw 4-vector -> right tangent of the unit q' (Q3).
    const Vector4<S> qo = to_wxyz(st.rotation);
    add_tangent_gradient_from_quaternion(qo.data(), grad_out.quaternions.ptr(q, p), gr.data());
  }
  Vector3<S> g_p, g_phi_p;
  skin_blend_backward(
      method, d, D, x, qp, st, gp, gr,
      [&](Index k, const SkinDriverGradient<S>& g) {
        if (grads.weights.data()) grads.weights(p, k) += g.weight;
        S* e = edge(k);
        if (!e) return;
        for (int c = 0; c < 3; ++c) {
          e[c] = g.x_t(c);
          e[3 + c] = g.x_ref(c);
          e[6 + c] = g.phi_t(c);
        }
      },
      g_p, g_phi_p);
  if (grads.points.data()) grads.points.row(p) += g_p;
  if (grads.point_rotations.data()) grads.point_rotations.row(p) += g_phi_p;
  if (grads.point_quaternions.data() && points.quaternions.rows() != 0)
    // (S17): right tangent of q̂ = q/|q| -> raw q (Q5).
    add_quaternion_gradient_from_tangent(points.quaternions.ptr(p), g_phi_p.data(),
                                         grads.point_quaternions.ptr(p));
}
}  // namespace detail

// Checks skin_blend_backward's arguments: those of skin_blend, each non-empty output gradient
// [Q][P][3|4] finite, and each non-empty gradient buffer's shape.
template <class S>
Status validate_skin_blend_backward(const SkinNodes<S>& nodes, const SkinPoints<S>& points,
                                    SkinIndexView t_query,
                                    const SkinBlendOutputGradients<S>& grad_out,
                                    const SkinBlendGradients<S>& grads) {
  if (Status s = detail::check_skin_common(nodes, points, t_query); !s) return s;
  const Index Q = t_query.rows(), P = points.count(), T = nodes.frames(), N = nodes.nodes();
  auto finite = [&](auto v, Index dim, const char* name) -> Status {
    if (!v.data()) return Status::ok();
    if (Status s = detail::check_qp_view(v, Q, P, dim, name); !s) return s;
    return detail::check_finite(name, v, "q", "p");
  };
  if (Status s = finite(grad_out.positions, 3, "grad_out_positions"); !s) return s;
  if (Status s = finite(grad_out.rotations, 3, "grad_out_rotations"); !s) return s;
  if (Status s = finite(grad_out.quaternions, 4, "grad_out_quaternions"); !s) return s;
  return detail::check_blend_gradients(grads, T, N, P, points.width());
}

}  // namespace smg
