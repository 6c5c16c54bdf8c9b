// smg/cuda/carap.cuh — C-ARAP and plain ARAP energies with their exact gradients on the GPU
// (docs/math/energy.md (E7)-(E10)), from the per-element functions of smg/energy/elements/carap.hpp
// that the CPU kernel (smg/energy/carap.hpp) calls too.
//
// Three kernels over the edge slots (t, i, k) and nodes (t, n):
//   1. edges:   d_ij^t = (R_i^t)ᵀ (x_j^t − x_i^t) and ‖e‖ (E8), the pair weight w̃_ij^t (E7);
//   2. terms:   the energy of the pairs (t, t + δ) (E9), and ∂E/∂d^t, ∂E/∂‖e^t‖ from the pairs
//               (t − δ, t) and (t, t + δ); back to F = ∂E/∂x_j and the tangent gradient of R_i
//               (E10), stored per slot;
//   3. gather:  per node and frame, −Σ_k F of its out-edges plus Σ F of its in-edges (in the
//               fixed order of the ReverseGraph) and Σ_k of its rotation parts.
// No atomics: the result is bit-identical run to run on a given device.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>

#include "smg/core/quaternion.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/views.hpp"
#include "smg/cuda/common.cuh"
#include "smg/energy/elements/carap.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/options.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg::cuda {

namespace detail {

// The per-call constants of the kernels (plain values, passed by value).
template <class S>
struct CarapConstants {
  Literal<S> alpha, lambda_c, lambda_l;
  int n_gaps;
  int delta[GapList::kCapacity];
  double gap_weight[GapList::kCapacity];  // γ_δ
  double weight;                          // the overall factor
  Index pairs;                            // Σ_δ max(0, T − δ) over every listed gap
  const std::int32_t* edge_count;         // Normalization::mean: Σ_i |N(i)| (device); else null

  // γ_δ times the overall scale, as the CPU computes it (in double, then rounded to S).
  __device__ Literal<S> gamma(int g) const {
    double scale = weight;
    if (edge_count != nullptr) scale = scale_over_count(scale, pairs, edge_count);
    return Literal<S>(gap_weight[g] * scale);
  }
};

// Slot s = i·K + k of frame t: the edge i -> indices(i, k).
template <class S, class I>
__global__ void carap_edges_kernel(PositionsView<const S> x, QuaternionsView<const S> q,
                                   FrameScalarsView<const S> conf, NeighborsView<S, I> graph,
                                   CarapConstants<S> c, Vec4<S>* edge, S* weight) {
  const Index N = x.nodes(), NK = N * graph.k();
  const int s = frame_item(NK);
  if (s < 0) return;
  const int K = static_cast<int>(graph.k()), i = s / K, k = s - i * K;
  const Index j = graph.indices(i, k);
  const S w = j >= 0 ? graph.weights(i, k) : S(0);
  SMG_CUDA_FOR_FRAMES(t, x.frames()) {
    const Index slot = t * NK + s;
    if (!(w > S(0))) {  // padding or weight 0: the edge adds exactly nothing
      edge[slot] = Vec4<S>{S(0), S(0), S(0), S(0)};
      weight[slot] = S(0);
      continue;
    }
    S R[9];
    smg::detail::rotation_from_wxyz(q.ptr(t, i), R);
    const S* xi = x.ptr(t, i);
    const S* xj = x.ptr(t, j);
    const S ex = xj[0] - xi[0], ey = xj[1] - xi[1], ez = xj[2] - xi[2];
    Vec4<S> d;
    carap_edge_vector(R, ex, ey, ez, d.x, d.y, d.z);  // (E8)
    using std::sqrt;
    d.w = sqrt(ex * ex + ey * ey + ez * ez);
    edge[slot] = d;
    weight[slot] = confidence_edge_weight(w, c.alpha, conf.data() ? conf(t, j) : S(1));  // (E7)
  }
}

template <class S, class I>
__global__ void carap_terms_kernel(PositionsView<const S> x, QuaternionsView<const S> q,
                                   NeighborsView<S, I> graph, CarapConstants<S> c,
                                   const Vec4<S>* edge, const S* weight, S* energy, S* f_out,
                                   S* r_out) {
  const Index T = x.frames(), N = x.nodes(), NK = N * graph.k();
  const int s = frame_item(NK);
  if (s < 0) return;
  const int K = static_cast<int>(graph.k()), i = s / K, k = s - i * K;
  Literal<S> gamma[GapList::kCapacity];
  for (int g = 0; g < c.n_gaps; ++g) gamma[g] = c.gamma(g);
  SMG_CUDA_FOR_FRAMES(t, T) {
    const Index slot = t * NK + s;
    const S wt = weight[slot];
    if (!(wt > S(0))) {  // the edge is active at every frame or at none
      energy[slot] = S(0);
      if (f_out != nullptr) {
        S* F = f_out + slot * 3;
        S* Rg = r_out + slot * 3;
        F[0] = F[1] = F[2] = Rg[0] = Rg[1] = Rg[2] = S(0);
      }
      continue;
    }
    const Vec4<S> d = edge[slot];
    S e(0), gx(0), gy(0), gz(0), h(0);
    for (int g = 0; g < c.n_gaps; ++g) {
      const Index delta = c.delta[g];
      S px, py, pz, pq;
      if (t + delta < T) {  // pair (t, t + δ), weighted at t: its energy belongs to this slot
        const Vec4<S> ds = edge[slot + delta * NK];
        e += carap_term(S(gamma[g] * wt), ds.x - d.x, ds.y - d.y, ds.z - d.z, ds.w - d.w,
                        c.lambda_c, c.lambda_l, px, py, pz, pq);  // (E9)
        gx -= px;
        gy -= py;
        gz -= pz;
        h -= pq;
      }
      if (t - delta >= 0 && f_out != nullptr) {  // pair (t − δ, t), weighted at t − δ
        const Index s0 = slot - delta * NK;
        const Vec4<S> d0 = edge[s0];
        carap_term(S(gamma[g] * weight[s0]), d.x - d0.x, d.y - d0.y, d.z - d0.z, d.w - d0.w,
                   c.lambda_c, c.lambda_l, px, py, pz, pq);
        gx += px;
        gy += py;
        gz += pz;
        h += pq;
      }
    }
    energy[slot] = e;
    if (f_out == nullptr) continue;
    S* F = f_out + slot * 3;
    S* Rg = r_out + slot * 3;
    const Index j = graph.indices(i, k);
    S R[9];
    smg::detail::rotation_from_wxyz(q.ptr(t, i), R);
    const S* xi = x.ptr(t, i);
    const S* xj = x.ptr(t, j);
    const S ex = xj[0] - xi[0], ey = xj[1] - xi[1], ez = xj[2] - xi[2];
    const S inv_len = d.w > S(0) ? S(1) / d.w : S(0);
    carap_edge_backprop(R, gx, gy, gz, h, inv_len, ex, ey, ez, d.x, d.y, d.z, F[0], F[1], F[2],
                        Rg[0], Rg[1], Rg[2]);  // (E10)
  }
}

// The per-slot values of a block's nodes at frame t, [nodes of the block][K][3], copied to
// shared memory with coalesced loads (each thread's K·3 values are contiguous but 12·K bytes
// apart from its neighbour's, so direct reads touch a cache line per thread and value).
template <class S>
__device__ inline const S* carap_stage_tile(const S* src, Index n0, Index nb, Index K, S* tile) {
  const Index count = nb * K * 3;
  const S* from = src + n0 * K * 3;
  for (Index a = threadIdx.x; a < count; a += blockDim.x) tile[a] = from[a];
  __syncthreads();
  return tile;
}

// Per node n and frame t: −Σ_k F of its out-edges plus Σ F of its in-edges (ReverseGraph order)
// into grad_x, and Σ_k of its rotation parts into the tangent or raw gradient (E10, Q5). With
// staged = true the out-edge values come through shared memory (blockDim.x · K · 3 scalars);
// the sums are the same, in the same order, either way.
template <class S, bool kStaged>
__global__ void carap_gather_kernel(Index T, Index N, Index K, const std::int32_t* rev_offsets,
                                    const std::int64_t* rev_entries, const S* f, const S* r,
                                    QuaternionsView<const S> q, S* grad_x, S* grad_tangent,
                                    S* grad_raw) {
  extern __shared__ unsigned char smg_shared[];
  S* tile = reinterpret_cast<S*>(smg_shared);
  const Index n0 = static_cast<Index>(blockIdx.x) * blockDim.x;
  const Index nb = N - n0 < static_cast<Index>(blockDim.x) ? N - n0 : static_cast<Index>(blockDim.x);
  const int n = frame_item(N);  // -1 past the end (still takes part in the block's copies)
  SMG_CUDA_FOR_FRAMES(t, T) {
    const Index item = t * N + n;
    const S* f_t = f + t * N * K * 3;
    if (grad_x != nullptr) {
      const S* own = kStaged ? carap_stage_tile(f_t, n0, nb, K, tile) - n0 * K * 3 : f_t;
      if (n >= 0) {
        S gx(0), gy(0), gz(0);
        for (Index k = 0; k < K; ++k) {  // x_n as the tail of its out-edges: −F
          const S* F = own + (n * K + k) * 3;
          gx -= F[0];
          gy -= F[1];
          gz -= F[2];
        }
        for (std::int32_t a = rev_offsets[n]; a < rev_offsets[n + 1]; ++a) {  // as a head: +F
          const S* F = f_t + rev_entries[a] * 3;
          gx += F[0];
          gy += F[1];
          gz += F[2];
        }
        grad_x[item * 3 + 0] += gx;
        grad_x[item * 3 + 1] += gy;
        grad_x[item * 3 + 2] += gz;
      }
      if (kStaged) __syncthreads();  // the tile is reused below and at the next frame
    }
    if (grad_tangent != nullptr || grad_raw != nullptr) {
      const S* r_t = r + t * N * K * 3;
      const S* own = kStaged ? carap_stage_tile(r_t, n0, nb, K, tile) - n0 * K * 3 : r_t;
      if (n >= 0) {
        S g[3] = {S(0), S(0), S(0)};
        for (Index k = 0; k < K; ++k)
          for (int c = 0; c < 3; ++c) g[c] += own[(n * K + k) * 3 + c];
        add_rotation_gradient(q.ptr(t, n), item, g, grad_tangent, grad_raw);
      }
      if (kStaged) __syncthreads();
    }
  }
}

}  // namespace detail

// C-ARAP (E9) on device memory: *energy_device (device memory, Accumulator<S>: double for float)
// receives the energy; when given, the gradients (E10) are added to grad_positions [T][N][3] and
// grad_rotations (right tangent [T][N][3] or raw quaternion coordinates [T][N][4], Q5), as in the
// CPU carap(). `reverse` is build_reverse_graph of graph's indices (build it once per graph).
// confidence [T][N] may be empty (all 1). Queued on `stream`; nothing is synchronised. Shapes and
// options are checked on the host before launch; contents are not read (run smg::cuda::validate_carap
// (smg/cuda/validate.cuh) on untrusted input first). Scratch: 5 T·N·K scalars, 11 with gradients.
template <class S, class I>
Status carap(smg::detail::NonDeducedT<PositionsView<const S>> positions, smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
             smg::detail::NonDeducedT<FrameScalarsView<const S>> confidence, const NeighborsView<S, I>& graph,
             const CarapOptions& options, const ReverseGraph& reverse,
             Accumulator<S>* energy_device, smg::detail::NonDeducedT<PositionsView<S>> grad_positions,
             smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations,
             cudaStream_t stream) {
  using Acc = Accumulator<S>;
  using L = Literal<S>;
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  if (Status s = validate_options(options); !s) return s;
  // The separate kernels compute (E9) as the paper writes it; the other penalties and the
  // stop-gradient and the neighbour's frame (E24) are the fused step's (smg::cuda::regularizers,
  // cuda/rigid.cuh).
  if (options.penalty != Penalty::squared || options.stop_gradient != StopGradient::none ||
      options.frame != RigidFrame::row)
    return Status::error(
        "options: the separate CUDA carap/arap compute penalty=squared, stop_gradient=none, "
        "frame=row only; use smg::cuda::regularizers for the others");
  if (rotations.frames() != T || rotations.nodes() != N)
    return Status::error("rotations: expected shape [T][N][4] of positions");
  if (confidence.data() && (confidence.frames() != T || confidence.nodes() != N))
    return Status::error("confidence: expected shape [T][N] of positions");
  if (graph.nodes() != N || graph.weights.rows() != N || graph.weights.cols() != K)
    return Status::error("graph: expected indices and weights of shape [N][K] with N of positions");
  if (reverse.nodes != N || reverse.k != K)
    return Status::error("reverse: not built from this graph (build_reverse_graph)");
  if (grad_positions.data() && (grad_positions.frames() != T || grad_positions.nodes() != N))
    return Status::error("grad_positions: expected shape [T][N][3] of positions");
  if (!grad_rotations.empty() && (grad_rotations.frames() != T || grad_rotations.nodes() != N))
    return Status::error("grad_rotations: expected shape [T][N][3 or 4] of positions");
  if (energy_device == nullptr) return Status::error("energy_device: null pointer");

  detail::CarapConstants<S> c{};
  c.alpha = L(options.alpha);
  c.lambda_c = L(options.lambda_c);
  c.lambda_l = L(options.lambda_l);
  c.weight = options.weight;
  c.pairs = 0;
  for (const Gap& g : options.gaps) c.pairs += std::max<Index>(0, T - g.delta);
  c.edge_count = options.normalization == Normalization::mean ? reverse.edge_count() : nullptr;
  for (const Gap& g : options.gaps)
    if (g.delta >= 1 && g.delta < T && g.weight != 0.0) {
      c.delta[c.n_gaps] = g.delta;
      c.gap_weight[c.n_gaps] = g.weight;
      ++c.n_gaps;
    }
  const Index slots = T * N * K;
  if (c.n_gaps == 0 || slots == 0) {
    SMG_CUDA_TRY(cudaMemsetAsync(energy_device, 0, sizeof(Acc), stream), "smg::cuda::carap");
    return Status::ok();
  }
  if (Status s = check_frame_items(N * K, "graph"); !s) return s;
  const bool grad = grad_positions.data() != nullptr || !grad_rotations.empty();
  DeviceBuffer<Vec4<S>> edge;
  DeviceBuffer<S> weight, energy, f, r;
  if (Status s = edge.allocate(static_cast<std::size_t>(slots), stream); !s) return s;
  if (Status s = weight.allocate(static_cast<std::size_t>(slots), stream); !s) return s;
  if (Status s = energy.allocate(static_cast<std::size_t>(slots), stream); !s) return s;
  if (grad) {
    if (Status s = f.allocate(static_cast<std::size_t>(slots * 3), stream); !s) return s;
    if (Status s = r.allocate(static_cast<std::size_t>(slots * 3), stream); !s) return s;
  }
  const dim3 grid = frame_grid(N * K, T);
  detail::carap_edges_kernel<S, I><<<grid, kThreads, 0, stream>>>(
      positions, rotations, confidence, graph, c, edge.get(), weight.get());
  detail::carap_terms_kernel<S, I><<<grid, kThreads, 0, stream>>>(
      positions, rotations, graph, c, edge.get(), weight.get(), energy.get(), f.get(), r.get());
  SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::carap launch");
  if (Status s = deterministic_sum<S, Acc>(energy.get(), slots, energy_device, stream); !s) return s;
  if (grad) {
    // Out-edge values through shared memory when a block's tile fits the default 48 KiB.
    constexpr int kGatherThreads = 128;
    const std::size_t tile = static_cast<std::size_t>(kGatherThreads * K * 3) * sizeof(S);
    S* const gt = grad_rotations.is_raw() ? nullptr : grad_rotations.tangent().data();
    S* const graw = grad_rotations.is_raw() ? grad_rotations.raw().data() : nullptr;
    dim3 grid = frame_grid(N, T);
    grid.x = static_cast<unsigned>((N + kGatherThreads - 1) / kGatherThreads);
    if (tile <= 48 * 1024)
      detail::carap_gather_kernel<S, true><<<grid, kGatherThreads, tile, stream>>>(
          T, N, K, reverse.offsets.get(), reverse.entries.get(), f.get(), r.get(), rotations,
          grad_positions.data(), gt, graw);
    else
      detail::carap_gather_kernel<S, false><<<grid, kGatherThreads, 0, stream>>>(
          T, N, K, reverse.offsets.get(), reverse.entries.get(), f.get(), r.get(), rotations,
          grad_positions.data(), gt, graw);
    SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::carap gather launch");
  }
  return Status::ok();
}

// Plain ARAP (docs/design.md "Plain ARAP"): C-ARAP with every confidence 1 and α = 1.
template <class S, class I>
Status arap(smg::detail::NonDeducedT<PositionsView<const S>> positions, smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
            const NeighborsView<S, I>& graph, const ArapOptions& options,
            const ReverseGraph& reverse, Accumulator<S>* energy_device,
            smg::detail::NonDeducedT<PositionsView<S>> grad_positions,
            smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations, cudaStream_t stream) {
  if (Status s = validate_options(options); !s) return s;
  return carap<S, I>(positions, rotations, {}, graph, carap_options_for_arap(options), reverse,
                     energy_device, grad_positions, grad_rotations, stream);
}

}  // namespace smg::cuda
