// smg/cuda/lrm.cuh — the LRM energy (E11)-(E14) and its exact gradient (E15)-(E16) on the GPU,
// with the same views, options and results as the CPU smg::lrm() (smg/energy/lrm.hpp).
//
// Scheme (deterministic: no atomics, every sum in a fixed order):
//   1. one thread per (t, i) gathers its K neighbours' positions, velocities (E1) and edge
//      weights w̃ (E7) into local arrays and calls detail::lrm_neighborhood<S, S>
//      (smg/energy/elements/lrm.hpp) — the very function the CPU kernel runs lane-wise; it writes
//      L_{t,i} (Accumulator<S>) to a buffer, ω_i^t to `omega`, and the scaled per-edge ∂L/∂x_k,
//      ∂L/∂u_k to scratch [T][N·K][3];
//   2. one thread per (t, j) gathers the edges into node j (ReverseGraph, increasing i·K + k: the
//      order in which the CPU adds them) into ∂L/∂x^t_j and ∂L/∂u^t_j [T][N][3];
//   3. one thread per (s, j) adds ∂L/∂x^s_j and the velocity parts of the two frames of each
//      difference (E1, E16) to grad_positions, in the CPU's order;
//   4. the energy is deterministic_sum of the per-(t, i) terms times the normalisation.
// Up to kLrmMaxK = 32 neighbours per node (local arrays sized at compile time: 8, 16 or 32).
#pragma once

#include "smg/cuda/common.cuh"

#include <sstream>
#include <string>

#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/elements/lrm.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg::cuda {

// Largest K (neighbours per node) the CUDA LRM kernel takes.
constexpr Index kLrmMaxK = 32;

namespace detail {

template <class S>
struct LrmKernelArgs {
  smg::detail::LrmParams<S> p;
  Literal<S> alpha;    // α of (E7)
  Literal<S> scale;    // weight (/ number of terms with Normalization::mean), when known on the host
  // Normalization::mean on the device: the number of edges is the ReverseGraph's device count,
  // so the scale weight / (T · edges) is formed where it is used (as the CPU forms it).
  double weight = 1.0;
  Index frames = 0;
  const std::int32_t* edge_count = nullptr;

  SMG_HOST_DEVICE Literal<S> gradient_scale() const {
    if (edge_count == nullptr) return scale;
    return Literal<S>(scale_over_count(weight, frames, edge_count));
  }
};

// Step 1, element e = t·N + i (< T·N). The kernels below are thin wrappers of these host-device
// per-element steps (which also lets a host loop run them, e.g. to check the scheme on a machine
// without a GPU). energy_terms, gx_edges and gu_edges hold the elements from e = base on (the
// fused step, cuda/regularizers.cuh, keeps one chunk of frames at a time).
template <class S, class I, int KMax>
SMG_HOST_DEVICE inline void lrm_term_at(Index e, PositionsView<const S> x,
                                        FrameScalarsView<const S> conf,
                                        NeighborsView<S, I> graph, const LrmKernelArgs<S>& args,
                                        Accumulator<S>* energy_terms, S* gx_edges, S* gu_edges,
                                        TangentsView<S> omega, Index base = 0) {
  const Index T = x.frames(), N = x.nodes(), K = graph.k();
  const Index t = e / N, i = e % N;
  S xs[3 * KMax], us[3 * KMax], a[KMax], gx[3 * KMax], gu[3 * KMax], om[3];
  S scratch[11 * KMax];  // smg::detail::lrm_scratch_size(KMax)
  const VelocityFrames vf = velocity_frames(t, T);
  for (Index k = 0; k < K; ++k) {
    const I jj = graph.indices(i, k);
    const Index j = jj >= 0 ? Index(jj) : i;  // padding: own record, weight 0 (as the CPU)
    const S* xr = x.ptr(t, j);
    const S* pr = x.ptr(vf.plus, j);
    const S* mr = x.ptr(vf.minus, j);
    for (int c = 0; c < 3; ++c) {
      xs[c * K + k] = xr[c];
      us[c * K + k] = vf.moving ? S(pr[c] - mr[c]) : S(0);
    }
    const S cj = conf.data() ? conf.ptr(t, j)[0] : S(1);
    const S wk = jj >= 0 ? graph.weights(i, k) : S(0);
    a[k] = confidence_edge_weight(wk, args.alpha, cj);  // (E7)
  }
  const S ev =
      smg::detail::lrm_neighborhood<S, S>(K, xs, us, a, args.p, scratch, gx, gu, om);
  if (energy_terms) energy_terms[e - base] = Accumulator<S>(ev);
  if (omega.data()) {
    S* o = omega.ptr(t, i);
    for (int c = 0; c < 3; ++c) o[c] = om[c];
  }
  if (!args.p.gradient) return;
  const Literal<S> scale = args.gradient_scale();
  for (Index k = 0; k < K; ++k) {
    if (graph.indices(i, k) < 0) break;
    S* dx = gx_edges + 3 * ((e - base) * K + k);
    S* du = gu_edges + 3 * ((e - base) * K + k);
    for (int c = 0; c < 3; ++c) {
      dx[c] = scale * gx[c * K + k];
      du[c] = scale * gu[c * K + k];
    }
  }
}

template <class S, class I, int KMax>
__global__ void lrm_neighborhood_kernel(PositionsView<const S> x, FrameScalarsView<const S> conf,
                                        NeighborsView<S, I> graph, LrmKernelArgs<S> args,
                                        Accumulator<S>* energy_terms, S* gx_edges, S* gu_edges,
                                        TangentsView<S> omega) {
  const Index e = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (e < x.frames() * x.nodes())
    lrm_term_at<S, I, KMax>(e, x, conf, graph, args, energy_terms, gx_edges, gu_edges, omega);
}

// Step 2, element e = t·N + j: the sum over the in-edges of j in increasing slot order.
template <class S>
SMG_HOST_DEVICE inline void lrm_gather_at(Index e, Index N, Index K, const std::int32_t* offsets,
                                          const std::int64_t* entries, const S* gx_edges,
                                          const S* gu_edges, S* gx_nodes, S* gu_nodes) {
  const Index t = e / N, j = e % N;
  S ax[3] = {S(0), S(0), S(0)}, au[3] = {S(0), S(0), S(0)};
  const S* bx = gx_edges + 3 * t * N * K;
  const S* bu = gu_edges + 3 * t * N * K;
  for (std::int32_t s = offsets[j]; s < offsets[j + 1]; ++s) {
    const Index slot = entries[s];
    for (int c = 0; c < 3; ++c) {
      ax[c] += bx[3 * slot + c];
      au[c] += bu[3 * slot + c];
    }
  }
  for (int c = 0; c < 3; ++c) {
    gx_nodes[3 * e + c] = ax[c];
    gu_nodes[3 * e + c] = au[c];
  }
}

template <class S>
__global__ void lrm_gather_kernel(Index T, Index N, Index K, const std::int32_t* offsets,
                                  const std::int64_t* entries, const S* gx_edges,
                                  const S* gu_edges, S* gx_nodes, S* gu_nodes) {
  const Index e = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (e < T * N) lrm_gather_at(e, N, K, offsets, entries, gx_edges, gu_edges, gx_nodes, gu_nodes);
}

// Step 3 for the frames [c0, c1) (the whole sequence, or one chunk of the fused step,
// cuda/regularizers.cuh), element (s, j) for the frames s they reach, c0 − 1 ≤ s ≤ c1 (within
// [0, T)): adds to grad(s, j) ∂L/∂x^s_j (s in the chunk) and the velocity parts of the chunk's
// frames t: u^t = x^{t+1} − x^t for t < T − 1 and u^{T−1} = x^{T−1} − x^{T−2} (E1, E16), in the
// CPU pass's order. gx_nodes, gu_nodes: [c1 − c0][N][3].
template <class S>
SMG_HOST_DEVICE inline void lrm_velocity_chunk_at(Index s, Index j, Index c0, Index c1, Index T,
                                                  Index N, const S* gx_nodes, const S* gu_nodes,
                                                  PositionsView<S> grad) {
  S* dst = grad.ptr(s, j);
  const auto in = [&](Index t) { return t >= c0 && t < c1; };
  const auto at = [&](const S* a, Index t, int c) { return a[3 * ((t - c0) * N + j) + c]; };
  for (int c = 0; c < 3; ++c) {
    S v = dst[c];
    if (in(s)) v += at(gx_nodes, s, c);
    if (T >= 2) {
      if (s >= 1 && in(s - 1) && s - 1 < T - 1) v += at(gu_nodes, s - 1, c);
      if (in(s) && s < T - 1) v -= at(gu_nodes, s, c);
      if (in(T - 1) && s == T - 1) v += at(gu_nodes, T - 1, c);
      if (in(T - 1) && s == T - 2) v -= at(gu_nodes, T - 1, c);
    }
    dst[c] = v;
  }
}

// Step 3 over the whole sequence, element e = s·N + j.
template <class S>
SMG_HOST_DEVICE inline void lrm_velocity_at(Index e, Index T, Index N, const S* gx_nodes,
                                            const S* gu_nodes, PositionsView<S> grad) {
  lrm_velocity_chunk_at(e / N, e % N, Index(0), T, T, N, gx_nodes, gu_nodes, grad);
}

template <class S>
__global__ void lrm_velocity_kernel(Index T, Index N, const S* gx_nodes, const S* gu_nodes,
                                    PositionsView<S> grad) {
  const Index e = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (e < T * N) lrm_velocity_at(e, T, N, gx_nodes, gu_nodes, grad);
}

template <class S, class I, int KMax>
Status lrm_launch(PositionsView<const S> positions, FrameScalarsView<const S> confidence,
                  const NeighborsView<S, I>& graph, const LrmKernelArgs<S>& args,
                  Accumulator<S>* energy_terms, S* gx_edges, S* gu_edges, TangentsView<S> omega,
                  cudaStream_t stream) {
  const Index n = positions.frames() * positions.nodes();
  lrm_neighborhood_kernel<S, I, KMax><<<grid_for(n), kThreads, 0, stream>>>(
      positions, confidence, graph, args, energy_terms, gx_edges, gu_edges, omega);
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::lrm: neighbourhood kernel launch");
  return Status::ok();
}

// Checks K against kLrmMaxK: the kernel's neighbour arrays are sized at compile time, so a wider
// graph cannot run. Shared by smg::cuda::lrm and smg::cuda::regularizers (with LRM on), so that
// both refuse it in the same words.
inline Status check_lrm_max_k(Index k) {
  if (k <= kLrmMaxK) return Status::ok();
  std::ostringstream s;
  s << "graph: K=" << k << " neighbours per node exceeds the CUDA LRM kernel's maximum of "
    << kLrmMaxK;
  return Status::error(s.str());
}

// Checks that `reverse` was built for a graph of shape [nodes][k] and holds its offsets: the
// launchers gather edge gradients and read edge counts through it, so one built for another
// graph (or without offsets) would read out of bounds. Shared by smg::cuda::lrm and
// smg::cuda::regularizers.
inline Status check_reverse_graph(const ReverseGraph& reverse, Index nodes, Index k) {
  if (reverse.nodes == nodes && reverse.k == k &&
      !(reverse.entries.size() > 0 && reverse.offsets.get() == nullptr))
    return Status::ok();
  std::ostringstream s;
  s << "reverse: built for a graph of shape [N=" << reverse.nodes << "][K=" << reverse.k
    << "], this graph is [N=" << nodes << "][K=" << k
    << "] (build_reverse_graph(graph.indices.data(), N, K, stream, reverse))";
  return Status::error(s.str());
}

}  // namespace detail

// Checks the shapes and options of smg::cuda::lrm on the host (the views are over device memory,
// so their contents — finiteness, confidences in [0, 1], graph indices — are not read: they are
// the caller's precondition, as validate_lrm checks them on the CPU). Same messages as
// validate_lrm for what it checks; in addition K <= kLrmMaxK and a ReverseGraph built for this
// graph's [N][K].
template <class S, class I>
Status validate_lrm_cuda(PositionsView<const S> positions, FrameScalarsView<const S> confidence,
                         const NeighborsView<S, I>& graph, const LrmOptions& options,
                         const ReverseGraph& reverse, PositionsView<S> grad_positions = {},
                         TangentsView<S> omega = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  if (Status s = smg::detail::check_shape("positions", positions.data(), T, N, positions.dim(), -1,
                                          -1, 3, "T", "N");
      !s)
    return s;
  if (confidence.data() != nullptr)
    if (Status s = smg::detail::check_shape("confidence", confidence.data(), confidence.frames(),
                                            confidence.nodes(), -1, T, N, -1, "T", "N");
        !s)
      return s;
  if (Status s = smg::detail::check_neighbors_shape(graph, N, "graph"); !s) return s;
  if (N * graph.k() > 0 && (graph.indices.data() == nullptr || graph.weights.data() == nullptr))
    return Status::error("graph: null data pointer for a non-empty array");
  if (Status s = detail::check_lrm_max_k(graph.k()); !s) return s;
  if (Status s = validate_options(options); !s) return s;
  if (Status s = validate_optional_output(grad_positions, T, N, "grad_positions"); !s) return s;
  if (Status s = validate_optional_output(omega, T, N, "omega"); !s) return s;
  return detail::check_reverse_graph(reverse, N, graph.k());
}

// LRM energy (E14) and gradient (E15)-(E16) on the GPU: the same quantity as smg::lrm() with the
// same options (α, δ_H, detach_omega, normalisation, weight; μ = c_μ trace(A) with lrm_mu_factor).
// All views are over DEVICE memory:
//   positions [T][N][3] (world units), confidence [T][N] in [0, 1] or empty (all 1),
//   graph indices [N][K] (int32 or int64, −1 padded) and weights [N][K] (K <= kLrmMaxK),
//   reverse: build_reverse_graph(graph.indices.data(), N, K, stream, reverse) for this graph,
//   energy_device: one Accumulator<S> (double for float), overwritten with the energy; may be null,
//   grad_positions [T][N][3]: the gradient is ADDED (as the CPU version); empty = not computed,
//   omega [T][N][3]: ω_i^t written (radians per frame, world frame); empty = not written.
// Stream-ordered on `stream`; nothing is synchronised (read the energy after the stream).
// Deterministic: same bits on every run on a given device. Shapes and options are validated on
// the host first (validate_lrm_cuda); CUDA errors come back as the Status.
template <class S, class I>
Status lrm(smg::detail::NonDeducedT<PositionsView<const S>> positions,
           smg::detail::NonDeducedT<FrameScalarsView<const S>> confidence,
           NeighborsView<S, I> graph, const LrmOptions& options, const ReverseGraph& reverse,
           Accumulator<S>* energy_device, smg::detail::NonDeducedT<PositionsView<S>> grad_positions,
           smg::detail::NonDeducedT<TangentsView<S>> omega, cudaStream_t stream) {
  using L = Literal<S>;
  using Acc = Accumulator<S>;
  if (Status s = validate_lrm_cuda(positions, confidence, graph, options, reverse, grad_positions,
                                   omega);
      !s)
    return s;
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  const bool mean = options.normalization == Normalization::mean;
  if (T == 0 || N == 0 || K == 0) {
    // Energy 0 and no gradient, as the CPU version; omega untouched there too.
    if (energy_device)
      SMG_CUDA_TRY(cudaMemsetAsync(energy_device, 0, sizeof(Acc), stream),
                   "smg::cuda::lrm: energy");
    return Status::ok();
  }
  detail::LrmKernelArgs<S> args;
  args.p = smg::detail::lrm_params<S>(options, grad_positions.data() != nullptr);
  args.alpha = L(options.alpha);
  args.scale = L(options.weight);
  args.weight = options.weight;
  args.frames = T;
  args.edge_count = mean ? reverse.edge_count() : nullptr;

  const Index n = T * N;
  DeviceBuffer<Acc> terms;
  DeviceBuffer<S> edge_buf, node_buf;
  if (energy_device)
    if (Status s = terms.allocate(static_cast<std::size_t>(n), stream); !s) return s;
  if (args.p.gradient) {
    if (Status s = edge_buf.allocate(static_cast<std::size_t>(6 * n * K), stream); !s) return s;
    if (Status s = node_buf.allocate(static_cast<std::size_t>(6 * n), stream); !s) return s;
  }
  S* gx_edges = edge_buf.get();
  S* gu_edges = gx_edges ? gx_edges + 3 * n * K : nullptr;
  Status launched = K <= 8    ? detail::lrm_launch<S, I, 8>(positions, confidence, graph, args,
                                                            terms.get(), gx_edges, gu_edges, omega,
                                                            stream)
                    : K <= 16 ? detail::lrm_launch<S, I, 16>(positions, confidence, graph, args,
                                                             terms.get(), gx_edges, gu_edges,
                                                             omega, stream)
                              : detail::lrm_launch<S, I, 32>(positions, confidence, graph, args,
                                                             terms.get(), gx_edges, gu_edges,
                                                             omega, stream);
  if (!launched) return launched;
  if (args.p.gradient) {
    S* gx_nodes = node_buf.get();
    S* gu_nodes = gx_nodes + 3 * n;
    detail::lrm_gather_kernel<S><<<grid_for(n), kThreads, 0, stream>>>(
        T, N, K, reverse.offsets.get(), reverse.entries.get(), gx_edges, gu_edges, gx_nodes,
        gu_nodes);
    SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::lrm: gather kernel launch");
    detail::lrm_velocity_kernel<S>
        <<<grid_for(n), kThreads, 0, stream>>>(T, N, gx_nodes, gu_nodes, grad_positions);
    SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::lrm: velocity kernel launch");
  }
  if (energy_device)
    if (Status s = deterministic_sum(terms.get(), n, energy_device, stream, Acc(options.weight),
                                     false, mean ? reverse.edge_count() : nullptr, T);
        !s)
      return s;
  return Status::ok();
}

}  // namespace smg::cuda
