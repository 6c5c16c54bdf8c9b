// smg/cuda/dqb.cuh — dual-quaternion blending (and LBS) of many points on the GPU: forward
// (S6)-(S13) and backward (S14)-(S18), with the same views, options and results as the CPU
// smg::skin_blend / smg::skin_blend_backward (smg/skin/blend.hpp).
//
// Scheme (deterministic: no atomics, every sum in a fixed order):
//   forward: one thread per (query q, point p) loads its drivers with the CPU's loaders
//     (detail::skin_load_ref / skin_load_query) and calls detail::skin_blend_forward (and
//     skin_blend_jacobian_rows for the Jacobians) — the functions the CPU loop calls;
//   backward, for each query frame in turn (as the CPU): one thread per point recomputes the
//     forward, calls detail::skin_blend_backward, adds the point and weight gradients (each
//     owned by its point) and writes the per-edge node contributions (∂L/∂x_t, ∂L/∂x_ref, ∂L/∂φ_t)
//     to scratch [P·D][9]; then one thread per node gathers its edges through the driver
//     incidence (build_driver_incidence: edges p·D + k in increasing order, the CPU's order) and
//     adds them to its rows of the node gradients.
// Up to kSkinMaxD = 32 drivers per point (local arrays sized at compile time: 8, 16 or 32).
#pragma once

#include "smg/cuda/common.cuh"

#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "smg/core/rotation_gradient.hpp"
#include "smg/skin/blend.hpp"
#include "smg/skin/blend_point.hpp"
#include "smg/skin/skin_views.hpp"

namespace smg::cuda {

// Largest D (drivers per point) the CUDA skinning kernels take.
constexpr Index kSkinMaxD = 32;

// The edges (point p, driver column k) of a driver table [P][D] grouped by driven node: for node
// n, the edges e = p·D + k with drivers(p, k) = n, in increasing e, at entries[offsets[n] ..
// offsets[n+1]) (a ReverseGraph with nodes = N and k = D, over a table of P rows). Build it once
// per driver table from DEVICE memory (copies the table to the host, orders it there, uploads
// the result; synchronises `stream`). Entries outside [0, N) (−1 padding) are skipped.
inline Status build_driver_incidence(const std::int32_t* drivers_device, Index points, Index width,
                                     Index nodes, cudaStream_t stream, ReverseGraph& out) {
  out.nodes = nodes;
  out.k = width;
  std::vector<std::int32_t> d(static_cast<std::size_t>(points * width));
  if (!d.empty()) {
    SMG_CUDA_TRY(cudaMemcpyAsync(d.data(), drivers_device, d.size() * sizeof(std::int32_t),
                                 cudaMemcpyDeviceToHost, stream),
                 "build_driver_incidence: copy of the driver table");
    SMG_CUDA_TRY(cudaStreamSynchronize(stream), "build_driver_incidence: synchronise");
  }
  std::vector<std::int32_t> offsets(static_cast<std::size_t>(nodes + 1), 0);
  for (const std::int32_t n : d)
    if (n >= 0 && n < nodes) ++offsets[static_cast<std::size_t>(n) + 1];
  for (Index n = 0; n < nodes; ++n)
    offsets[static_cast<std::size_t>(n + 1)] += offsets[static_cast<std::size_t>(n)];
  std::vector<std::int64_t> entries(static_cast<std::size_t>(offsets.back()));
  std::vector<std::int32_t> fill(offsets.begin(), offsets.end() - 1);
  for (std::size_t e = 0; e < d.size(); ++e)
    if (d[e] >= 0 && d[e] < nodes)
      entries[static_cast<std::size_t>(fill[static_cast<std::size_t>(d[e])]++)] =
          static_cast<std::int64_t>(e);
  if (Status s = out.offsets.allocate(offsets.size(), stream); !s) return s;
  if (Status s = out.entries.allocate(entries.size(), stream); !s) return s;
  SMG_CUDA_TRY(cudaMemcpyAsync(out.offsets.get(), offsets.data(),
                               offsets.size() * sizeof(std::int32_t), cudaMemcpyHostToDevice, stream),
               "build_driver_incidence: upload");
  if (!entries.empty())
    SMG_CUDA_TRY(cudaMemcpyAsync(out.entries.get(), entries.data(),
                                 entries.size() * sizeof(std::int64_t), cudaMemcpyHostToDevice,
                                 stream),
                 "build_driver_incidence: upload");
  SMG_CUDA_TRY(cudaStreamSynchronize(stream), "build_driver_incidence: synchronise");
  return Status::ok();
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

// Forward, element e = q·P + p (< Q·P). The kernels are thin wrappers of these host-device
// per-element steps (which also lets a host loop run them without a GPU).
template <class S, int DMax>
SMG_HOST_DEVICE inline void skin_forward_at(Index e, const SkinNodes<S>& nodes,
                                            const SkinPoints<S>& points, SkinIndexView t_query,
                                            const SkinBlendOutputs<S>& out, SkinMethod method) {
  const Index P = points.count(), Dmax = points.width();
  const Index q = e / P, p = e % P;
  SkinDriver<S> d[DMax];
  smg::detail::SkinBlendState<S> st;
  const Index D = smg::detail::skin_load_ref(nodes, points, p, true, d);
  const Vector3<S> x = points.positions.row(p);
  const Quaternion<S> qp = smg::detail::skin_point_quaternion(points.quaternions, p);
  smg::detail::skin_load_query(nodes, points, p, Index(t_query(q, 0)), D, d);
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

// Backward, point pass of query q (frame t), point p (< P).
template <class S, int DMax>
SMG_HOST_DEVICE inline void skin_backward_point_at(
    Index p, const SkinNodes<S>& nodes, const SkinPoints<S>& points, Index q, Index t,
    const SkinBlendOutputGradients<S>& grad_out, const SkinBlendGradients<S>& grads,
    SkinMethod method, S* edge_buf) {
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
__global__ void skin_backward_point_kernel(SkinNodes<S> nodes, SkinPoints<S> points, Index q,
                                           Index t, SkinBlendOutputGradients<S> grad_out,
                                           SkinBlendGradients<S> grads, SkinMethod method,
                                           S* edge_buf) {
  const Index p = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (p < points.count())
    skin_backward_point_at<S, DMax>(p, nodes, points, q, t, grad_out, grads, method, edge_buf);
}

// Backward, node pass of query frame t, node n: its edges in increasing p·D + k.
template <class S>
SMG_HOST_DEVICE inline void skin_backward_node_at(Index n, const SkinNodes<S>& nodes,
                                                  const SkinPoints<S>& points, Index t,
                                                  const SkinBlendGradients<S>& grads,
                                                  const std::int32_t* offsets,
                                                  const std::int64_t* entries, const S* edge_buf) {
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
__global__ void skin_backward_node_kernel(SkinNodes<S> nodes, SkinPoints<S> points, Index t,
                                          SkinBlendGradients<S> grads, const std::int32_t* offsets,
                                          const std::int64_t* entries, const S* edge_buf) {
  const Index n = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (n < nodes.nodes()) skin_backward_node_at(n, nodes, points, t, grads, offsets, entries, edge_buf);
}

template <class S, int DMax>
Status skin_backward_points(const SkinNodes<S>& nodes, const SkinPoints<S>& points, Index q,
                            Index t, const SkinBlendOutputGradients<S>& grad_out,
                            const SkinBlendGradients<S>& grads, SkinMethod method, S* edge_buf,
                            cudaStream_t stream) {
  skin_backward_point_kernel<S, DMax><<<grid_for(points.count()), kThreads, 0, stream>>>(
      nodes, points, q, t, grad_out, grads, method, edge_buf);
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
// precondition, as validate_skin_blend checks them on the CPU); CUDA errors come back as the
// Status. Stream-ordered, nothing synchronised; deterministic.
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
// table (needed only when a node gradient is requested; may be empty otherwise). Per query frame
// one point pass and one node pass, in the CPU's order. Copies t_query [Q] to the host first
// (synchronises `stream` once); then stream-ordered. Deterministic.
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
  // Each query frame is one point pass and one node pass (the frame picks the node rows the node
  // pass writes): the frames are copied to the host once.
  std::vector<std::int32_t> frames(static_cast<std::size_t>(Q));
  SMG_CUDA_TRY(cudaMemcpyAsync(frames.data(), t_query.data(), frames.size() * sizeof(std::int32_t),
                               cudaMemcpyDeviceToHost, stream),
               "smg::cuda::skin_blend_backward: copy of t_query");
  SMG_CUDA_TRY(cudaStreamSynchronize(stream), "smg::cuda::skin_blend_backward: synchronise");
  DeviceBuffer<S> edge_buf;
  if (to_nodes)
    if (Status s = edge_buf.allocate(static_cast<std::size_t>(P * D * detail::kSkinEdgeStride), stream);
        !s)
      return s;
  for (Index q = 0; q < Q; ++q) {
    const Index t = frames[static_cast<std::size_t>(q)];
    const Status s =
        D <= 8 ? detail::skin_backward_points<S, 8>(nodes, points, q, t, grad_out, grads,
                                                    options.method, edge_buf.get(), stream)
        : D <= 16 ? detail::skin_backward_points<S, 16>(nodes, points, q, t, grad_out, grads,
                                                        options.method, edge_buf.get(), stream)
                  : detail::skin_backward_points<S, 32>(nodes, points, q, t, grad_out, grads,
                                                        options.method, edge_buf.get(), stream);
    if (!s) return s;
    if (!to_nodes || N == 0) continue;
    detail::skin_backward_node_kernel<S><<<grid_for(N), kThreads, 0, stream>>>(
        nodes, points, t, grads, incidence.offsets.get(), incidence.entries.get(), edge_buf.get());
    SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::skin_blend_backward: node kernel launch");
  }
  return Status::ok();
}

}  // namespace smg::cuda
