// smg/cuda/dqb.cuh — dual-quaternion blending (and LBS) of many points on the GPU: forward
// (S6)-(S13) and backward (S14)-(S18), with the same views, options and results as the CPU
// smg::skin_blend / smg::skin_blend_backward (smg/skin/blend.hpp).
//
// Scheme (deterministic: no atomics, every sum in a fixed order):
//   forward: one thread per (query q, point p) loads its drivers with the CPU's loaders
//     (detail::skin_load_ref / skin_load_query) and calls detail::skin_blend_forward (and
//     skin_blend_jacobian_rows for the Jacobians) — the functions the CPU loop calls;
//   backward, for each query q in turn (as the CPU; the host passes q, the kernels read the
//     frame t_query[q]: nothing is read back): one thread per point recomputes the forward,
//     calls detail::skin_blend_backward, adds the point and weight gradients (each owned by its
//     point) and writes the per-edge node contributions (∂L/∂x_t, ∂L/∂x_ref, ∂L/∂φ_t) to scratch
//     [P·D][9]; then one thread per node gathers its edges through the driver incidence
//     (build_driver_incidence, built on the device: edges p·D + k in increasing order, the CPU's
//     order) and adds them to its rows of the node gradients.
// Nothing here synchronises the stream or reads device memory on the host.
// Up to kSkinMaxD = 32 drivers per point (local arrays sized at compile time: 8, 16 or 32).
#pragma once

#include "smg/cuda/common.cuh"

#include <cstdint>
#include <limits>
#include <sstream>
#include <string>

#include "smg/core/rotation_gradient.hpp"
#include "smg/skin/blend_element.hpp"
#include "smg/skin/blend_point.hpp"
#include "smg/skin/skin_views.hpp"

namespace smg::cuda {

// Largest D (drivers per point) the CUDA skinning kernels take.
constexpr Index kSkinMaxD = 32;

// The edges (point p, driver column k) of a driver table [P][D] grouped by driven node: for node
// n, the edges e = p·D + k with drivers(p, k) = n, in increasing e (the CPU's order), at
// entries[offsets[n] .. offsets[n+1]) (a ReverseGraph with nodes = N and k = D, over a table of
// P rows: detail::build_in_edges, the builder of build_reverse_graph). Build it once per driver
// table (int32, or int64) from DEVICE memory, on `stream`, entirely on the device: nothing is
// read back or synchronised. Entries outside [0, N) (−1 padding) are skipped. P·D < 2^31.
template <class I>
Status build_driver_incidence(const I* drivers_device, Index points, Index width, Index nodes,
                              cudaStream_t stream, ReverseGraph& out) {
  return detail::build_in_edges(drivers_device, points, width, nodes, stream, out,
                                "build_driver_incidence");
}

namespace detail {

// A [rows][cols] table expected as [er][ec] (`shape` spells it for the message), with data
// unless empty.
inline Status table_shape(Index rows, Index cols, Index er, Index ec, const void* data,
                          const std::string& name, const std::string& shape) {
  if (rows != er || cols != ec) {
    std::ostringstream s;
    s << name << ": expected shape " << shape << ", got [" << rows << "][" << cols << "]";
    return Status::error(s.str());
  }
  if (rows * cols > 0 && data == nullptr) return Status::error(name + ": null data pointer");
  return Status::ok();
}

// The driver table [P][D] of the skinning kernels: P rows, 1 <= D <= kSkinMaxD, data unless
// empty.
inline Status check_driver_table(SkinDriversView drivers, Index P) {
  const Index D = drivers.cols();
  if (drivers.rows() != P || D < 1) {
    std::ostringstream s;
    s << "drivers: expected shape [P=" << P << "][D>=1], got [" << drivers.rows() << "][" << D
      << "]";
    return Status::error(s.str());
  }
  if (drivers.size() > 0 && drivers.data() == nullptr)
    return Status::error("drivers: null data pointer");
  if (D > kSkinMaxD) {
    std::ostringstream s;
    s << "drivers: D=" << D << " drivers per point exceeds the CUDA skinning kernels' maximum of "
      << kSkinMaxD;
    return Status::error(s.str());
  }
  return Status::ok();
}

// t_ref [P] (the reference frame of each point), data unless empty.
inline Status check_t_ref(SkinIndexView t_ref, Index P) {
  if (t_ref.rows() != P) {
    std::ostringstream s;
    s << "t_ref: expected " << P << " entries, got " << t_ref.rows();
    return Status::error(s.str());
  }
  if (P > 0 && t_ref.data() == nullptr) return Status::error("t_ref: null data pointer");
  return Status::ok();
}

// Shape checks of the skinning inputs (the contents live on the device and are not read).
template <class S>
Status check_skin_shapes(const SkinNodes<S>& nodes, const SkinPoints<S>& points,
                         SkinIndexView t_query) {
  const Index T = nodes.frames(), N = nodes.nodes(), P = points.count(), D = points.width();
  if (Status s = smg::detail::check_shape("positions", nodes.positions.data(), T, N,
                                          nodes.positions.dim(), -1, -1, 3, "T", "N");
      !s)
    return s;
  if (Status s = smg::detail::check_shape("quaternions", nodes.quaternions.data(),
                                          nodes.quaternions.frames(), nodes.quaternions.nodes(),
                                          nodes.quaternions.dim(), T, N, 4, "T", "N");
      !s)
    return s;
  if (Status s = check_driver_table(points.drivers, P); !s) return s;
  const std::string ps = std::to_string(P);
  if (Status s = table_shape(points.weights.rows(), points.weights.cols(), P, D,
                             points.weights.data(), "weights",
                             "[P=" + ps + "][D=" + std::to_string(D) + "]");
      !s)
    return s;
  if (Status s = check_t_ref(points.t_ref, P); !s) return s;
  if (Status s = table_shape(points.positions.rows(), points.positions.cols(), P, 3,
                             points.positions.data(), "points", "[P=" + ps + "][3]");
      !s)
    return s;
  if (points.quaternions.rows() != 0 || points.quaternions.data() != nullptr)
    if (Status s = table_shape(points.quaternions.rows(), points.quaternions.cols(), P, 4,
                               points.quaternions.data(), "point_quats", "[P=" + ps + "][4]");
        !s)
      return s;
  if (t_query.rows() > 0 && t_query.data() == nullptr)
    return Status::error("t_query: null data pointer");
  return Status::ok();
}

// The frame of query q, t_query[q] read where the kernels run (on the device: the launchers
// never read t_query back); −1 when it is outside [0, T). The forward then writes NaN outputs
// for query q, and both passes of the backward skip query q (it adds nothing to any gradient)
// rather than clamp it: a clamped frame would add a wrong gradient silently, and a device-side
// error flag would have to be read back. Such a t_query breaks the precondition
// (validate_skin_blend / validate_skin_blend_backward on the CPU and smg_torch's validate=True
// report it); skipping only keeps the device from reading out of bounds.
SMG_HOST_DEVICE inline Index skin_query_frame(SkinIndexView t_query, Index q, Index T) {
  const Index t = t_query(q, 0);
  return t >= 0 && t < T ? t : Index(-1);
}

// Writes NaN to every requested output of element (q, p): its query frame is out of range
// (skin_query_frame), so that the broken precondition shows in the outputs.
template <class S>
SMG_HOST_DEVICE inline void skin_store_nan(const SkinBlendOutputs<S>& out, Index q, Index p) {
  const S nan = std::numeric_limits<S>::quiet_NaN();
  auto fill = [&](S* o, Index n) {
    for (Index i = 0; i < n; ++i) o[i] = nan;
  };
  if (out.positions.data()) fill(out.positions.ptr(q, p), 3);
  if (out.quaternions.data()) fill(out.quaternions.ptr(q, p), 4);
  if (out.J_drivers.data()) fill(out.J_drivers.ptr(q, p), out.J_drivers.dim());
  if (out.J_point.data()) fill(out.J_point.ptr(q, p), out.J_point.dim());
}

// Forward, element e = q·P + p (< Q·P). The kernels are thin wrappers of these host-device
// per-element steps (which also lets a host loop run them without a GPU). A query frame out of
// range gives NaN outputs (skin_query_frame), not an out-of-bounds read.
template <class S, int DMax>
SMG_HOST_DEVICE inline void skin_forward_at(Index e, const SkinNodes<S>& nodes,
                                            const SkinPoints<S>& points, SkinIndexView t_query,
                                            const SkinBlendOutputs<S>& out, SkinMethod method) {
  const Index P = points.count(), Dmax = points.width();
  const Index q = e / P, p = e % P;
  const Index t = skin_query_frame(t_query, q, nodes.frames());
  if (t < 0) {
    skin_store_nan(out, q, p);
    return;
  }
  SkinDriver<S> d[DMax];
  smg::detail::SkinBlendState<S> st;
  const Index D = smg::detail::skin_load_ref(nodes, points, p, true, d);
  const Vector3<S> x = points.positions.row(p);
  const Quaternion<S> qp = smg::detail::skin_point_quaternion(points.quaternions, p);
  smg::detail::skin_load_query(nodes, points, p, t, D, d);
  smg::detail::skin_blend_forward(method, d, D, x, qp, st);
  smg::detail::skin_store_outputs(method, d, D, Dmax, x, qp, st, out, q, p);
}

template <class S, int DMax>
__global__ void skin_forward_kernel(SkinNodes<S> nodes, SkinPoints<S> points,
                                    SkinIndexView t_query, SkinBlendOutputs<S> out,
                                    SkinMethod method) {
  const Index e = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (e < t_query.rows() * points.count())
    skin_forward_at<S, DMax>(e, nodes, points, t_query, out, method);
}

using smg::detail::kSkinEdgeStride;  // per edge: ∂L/∂x_t (3), ∂L/∂x_ref (3), ∂L/∂φ_t (3)

// Backward, point pass of query q (frame t_query[q]; skipped when out of range), point p (< P).
template <class S, int DMax>
SMG_HOST_DEVICE inline void skin_backward_point_at(
    Index p, const SkinNodes<S>& nodes, const SkinPoints<S>& points, SkinIndexView t_query,
    Index q, const SkinBlendOutputGradients<S>& grad_out, const SkinBlendGradients<S>& grads,
    SkinMethod method, S* edge_buf) {
  const Index t = skin_query_frame(t_query, q, nodes.frames());
  if (t < 0) return;
  const Index Dmax = points.width();
  SkinDriver<S> d[DMax];
  smg::detail::SkinBlendState<S> st;
  smg::detail::skin_backward_point(method, nodes, points, q, t, p, grad_out, grads, d, st,
                                   [&](Index k) -> S* {
                                     return edge_buf ? edge_buf + (p * Dmax + k) * kSkinEdgeStride
                                                     : nullptr;
                                   });
}

template <class S, int DMax>
__global__ void skin_backward_point_kernel(SkinNodes<S> nodes, SkinPoints<S> points,
                                           SkinIndexView t_query, Index q,
                                           SkinBlendOutputGradients<S> grad_out,
                                           SkinBlendGradients<S> grads, SkinMethod method,
                                           S* edge_buf) {
  const Index p = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (p < points.count())
    skin_backward_point_at<S, DMax>(p, nodes, points, t_query, q, grad_out, grads, method,
                                    edge_buf);
}

// Backward, node pass of query q (frame t_query[q]; skipped when out of range, as the point pass
// of q, whose edge records it would read), node n: its edges in increasing p·D + k.
template <class S>
SMG_HOST_DEVICE inline void skin_backward_node_at(Index n, const SkinNodes<S>& nodes,
                                                  const SkinPoints<S>& points,
                                                  SkinIndexView t_query, Index q,
                                                  const SkinBlendGradients<S>& grads,
                                                  const std::int32_t* offsets,
                                                  const std::int64_t* entries, const S* edge_buf) {
  const Index t = skin_query_frame(t_query, q, nodes.frames());
  if (t < 0) return;
  const Index Dmax = points.width();
  using V3 = Eigen::Map<const Vector3<S>>;
  Vector3<S> gx_t = Vector3<S>::Zero(), gphi_t = Vector3<S>::Zero();
  for (std::int32_t i = offsets[n]; i < offsets[n + 1]; ++i) {
    const Index e = entries[i];
    const S* g = edge_buf + e * kSkinEdgeStride;
    const Index tr = points.t_ref(e / Dmax, 0);
    gx_t += V3(g);
    gphi_t += V3(g + 6);
    if (grads.node_positions.data()) grads.node_positions(tr, n) += V3(g + 3);
    if (grads.node_rotations.data()) grads.node_rotations(tr, n) -= V3(g + 6);
    if (grads.node_quaternions.data()) {
      const Vector3<S> minus_phi = -V3(g + 6);
      add_quaternion_gradient_from_tangent(nodes.quaternions.ptr(tr, n), minus_phi.data(),
                                           grads.node_quaternions.ptr(tr, n));
    }
  }
  if (offsets[n + 1] == offsets[n]) return;
  if (grads.node_positions.data()) grads.node_positions(t, n) += gx_t;
  if (grads.node_rotations.data()) grads.node_rotations(t, n) += gphi_t;
  if (grads.node_quaternions.data())
    add_quaternion_gradient_from_tangent(nodes.quaternions.ptr(t, n), gphi_t.data(),
                                         grads.node_quaternions.ptr(t, n));
}

template <class S>
__global__ void skin_backward_node_kernel(SkinNodes<S> nodes, SkinPoints<S> points,
                                          SkinIndexView t_query, Index q,
                                          SkinBlendGradients<S> grads, const std::int32_t* offsets,
                                          const std::int64_t* entries, const S* edge_buf) {
  const Index n = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (n < nodes.nodes())
    skin_backward_node_at(n, nodes, points, t_query, q, grads, offsets, entries, edge_buf);
}

template <class S, int DMax>
Status skin_backward_points(const SkinNodes<S>& nodes, const SkinPoints<S>& points,
                            SkinIndexView t_query, Index q,
                            const SkinBlendOutputGradients<S>& grad_out,
                            const SkinBlendGradients<S>& grads, SkinMethod method, S* edge_buf,
                            cudaStream_t stream) {
  skin_backward_point_kernel<S, DMax><<<grid_for(points.count()), kThreads, 0, stream>>>(
      nodes, points, t_query, q, grad_out, grads, method, edge_buf);
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::skin_blend_backward: point kernel launch");
  return Status::ok();
}

}  // namespace detail

// Blends every point at every query frame (S6)-(S13) on the GPU: the same outputs as
// smg::skin_blend (positions [Q][P][3], quaternions [Q][P][4] (w, x, y, z), and optionally
// J_drivers [Q][P][D·78] and J_point [Q][P][36]; each optional), with options.method (DQB or
// LBS; options.parallel is ignored). Every view — nodes (positions [T][N][3], quaternions
// [T][N][4], normalised on load), points (drivers [P][D] int32 −1 padded, weights [P][D], t_ref
// [P], positions [P][3], quaternions [P][4] or empty), t_query [Q] and the outputs — is over
// DEVICE memory. D <= kSkinMaxD. Shapes are checked on the host (the contents are the caller's
// precondition, as validate_skin_blend checks them on the CPU; a t_query entry outside [0, T)
// gives NaN outputs for that query instead of an out-of-bounds read); CUDA errors come back as
// the Status. Stream-ordered, nothing read back or synchronised; deterministic.
template <class S>
Status skin_blend(const SkinNodes<S>& nodes, const SkinPoints<S>& points, SkinIndexView t_query,
                  const SkinBlendOutputs<S>& out, const SkinOptions& options,
                  cudaStream_t stream) {
  if (Status s = detail::check_skin_shapes(nodes, points, t_query); !s) return s;
  const Index Q = t_query.rows(), P = points.count(), D = points.width();
  if (Status s = smg::detail::check_blend_outputs(out, Q, P, D); !s) return s;
  const Index n = Q * P;
  if (n == 0) return Status::ok();
  const unsigned grid = grid_for(n);
  if (D <= 8)
    detail::skin_forward_kernel<S, 8><<<grid, kThreads, 0, stream>>>(nodes, points, t_query, out,
                                                                     options.method);
  else if (D <= 16)
    detail::skin_forward_kernel<S, 16><<<grid, kThreads, 0, stream>>>(nodes, points, t_query, out,
                                                                      options.method);
  else
    detail::skin_forward_kernel<S, 32><<<grid, kThreads, 0, stream>>>(nodes, points, t_query, out,
                                                                      options.method);
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::skin_blend: kernel launch");
  return Status::ok();
}

// Backward of skin_blend on the GPU (the vector-Jacobian product (S14)-(S18)): ADDS to `grads`
// exactly what smg::skin_blend_backward adds (node positions [T][N][3], node rotations [T][N][3]
// right tangent or raw node quaternions [T][N][4], point positions [P][3], point rotations
// [P][3] / raw point quaternions [P][4], weights [P][D]; each optional), given dL/d(outputs)
// grad_out ([Q][P][3] positions, [Q][P][3] right-tangent rotations and/or [Q][P][4] raw
// quaternions; each optional). All views over DEVICE memory. `incidence`:
// build_driver_incidence(points.drivers.data(), P, D, N, stream, incidence) for this driver
// table (needed only when a node gradient is requested; may be empty otherwise). Per query q,
// in increasing q, one point pass and one node pass (the CPU's order; 2·Q launches): the
// kernels read the frame t_query[q] themselves, so nothing is read back or synchronised —
// stream-ordered throughout. A t_query entry outside [0, T) is skipped on the device (that query
// adds nothing: detail::skin_query_frame); the other contents are the caller's precondition, as
// for skin_blend. Deterministic.
template <class S>
Status skin_blend_backward(const SkinNodes<S>& nodes, const SkinPoints<S>& points,
                           SkinIndexView t_query, const SkinBlendOutputGradients<S>& grad_out,
                           const SkinBlendGradients<S>& grads, const ReverseGraph& incidence,
                           const SkinOptions& options, cudaStream_t stream) {
  if (Status s = detail::check_skin_shapes(nodes, points, t_query); !s) return s;
  const Index Q = t_query.rows(), P = points.count(), D = points.width();
  const Index T = nodes.frames(), N = nodes.nodes();
  auto qp = [&](auto v, Index dim, const char* name) -> Status {
    if (!v.data()) return Status::ok();
    return smg::detail::check_qp_view(v, Q, P, dim, name);
  };
  if (Status s = qp(grad_out.positions, 3, "grad_out_positions"); !s) return s;
  if (Status s = qp(grad_out.rotations, 3, "grad_out_rotations"); !s) return s;
  if (Status s = qp(grad_out.quaternions, 4, "grad_out_quaternions"); !s) return s;
  if (Status s = smg::detail::check_blend_gradients(grads, T, N, P, D); !s) return s;
  const bool to_nodes = grads.node_positions.data() || grads.node_rotations.data() ||
                        grads.node_quaternions.data();
  if (to_nodes && (incidence.nodes != N || incidence.k != D)) {
    std::ostringstream s;
    s << "incidence: built for [N=" << incidence.nodes << "] nodes and [D=" << incidence.k
      << "] drivers per point, this call has [N=" << N << "][D=" << D
      << "] (build_driver_incidence(points.drivers.data(), P, D, N, stream, incidence))";
    return Status::error(s.str());
  }
  if (Q == 0 || P == 0) return Status::ok();
  // Each query is one point pass and one node pass; the node pass of q reads the edge records
  // the point pass of q wrote (one scratch for every q: the passes are stream-ordered), and the
  // frame t_query[q] picks the node rows it writes: the kernels read it, the host passes q.
  DeviceBuffer<S> edge_buf;
  if (to_nodes)
    if (Status s = edge_buf.allocate(static_cast<std::size_t>(P * D * detail::kSkinEdgeStride), stream);
        !s)
      return s;
  for (Index q = 0; q < Q; ++q) {
    const Status s =
        D <= 8 ? detail::skin_backward_points<S, 8>(nodes, points, t_query, q, grad_out, grads,
                                                    options.method, edge_buf.get(), stream)
        : D <= 16 ? detail::skin_backward_points<S, 16>(nodes, points, t_query, q, grad_out, grads,
                                                        options.method, edge_buf.get(), stream)
                  : detail::skin_backward_points<S, 32>(nodes, points, t_query, q, grad_out, grads,
                                                        options.method, edge_buf.get(), stream);
    if (!s) return s;
    if (!to_nodes || N == 0) continue;
    detail::skin_backward_node_kernel<S><<<grid_for(N), kThreads, 0, stream>>>(
        nodes, points, t_query, q, grads, incidence.offsets.get(), incidence.entries.get(),
        edge_buf.get());
    SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::skin_blend_backward: node kernel launch");
  }
  return Status::ok();
}

}  // namespace smg::cuda
