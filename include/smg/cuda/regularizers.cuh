// smg/cuda/regularizers.cuh — the fused regulariser step on the GPU: any subset of node
// confidences (E2)-(E6), C-ARAP (E7)-(E10), plain ARAP and LRM (E11)-(E16) with the gradients,
// the same quantities, options and result struct as the CPU smg::regularizers()
// (smg/energy/regularizers.hpp; docs/math/energy.md "The fused regulariser pass").
//
// Scheme (deterministic: no float atomics, every sum in a fixed order), three phases on one
// stream:
//   1. confidences (when on): per chunk of frames, the velocities (E1) and edge changes (E4) of
//      the chunk's frames, then c_{t,i} (E6) into [T][N] (the caller's output, or scratch);
//   2. C-ARAP and ARAP together, one thread per (frame t, node n), with NO per-edge scratch:
//      the thread evaluates each out-edge n -> j of frame t (d^t, the d^{t±δ} of every gap of
//      both energies, their pair terms (E9) and one back-propagation (E10)): −F into x_n^t's
//      gradient, the rotation part into R_n^t's; then each in-edge i -> n again (from the
//      ReverseGraph, in increasing slot order) for its +F into x_n^t's gradient. Every (frame,
//      edge) is evaluated twice, by its tail and by its head, instead of keeping the 11·T·N·K
//      scalars of per-slot scratch the separate carap kernels keep: on a GPU the arithmetic is
//      cheap and the scratch traffic is not. The energies of the pairs (t, t + δ) are summed per
//      thread, then per block in a fixed tree, then over the blocks (deterministic_sum);
//   3. LRM (when on): per chunk of frames, the separate lrm kernels' per-element steps
//      (cuda/lrm.cuh: lrm_term_at, lrm_gather_at) on the chunk's frames, and a velocity step that
//      adds each chunk's velocity parts to the frames they reach (one frame either side).
// The chunks bound the scratch: their length is the most frames whose scratch, with the [T][N]
// confidences, stays within the bytes of the inputs (positions, rotations, visibility, graph);
// at least one frame, so short sequences can exceed it (regularizers_extra_bytes says by how
// much). Every equation is the element functions' (confidence_term.hpp, carap_term.hpp,
// lrm_term.hpp, common.hpp's confidence_edge_weight), as on the CPU.
//
// The per-element steps are host-device functions (fused_rigid_node_at here; confidence_inputs_at
// and confidence_at in cuda/confidence.cuh; lrm_term_at, lrm_gather_at and lrm_velocity_chunk_at
// in cuda/lrm.cuh, shared with the separate launchers): the kernels are thin wrappers,
// and tests/cuda/test_cuda_regularizers.cu runs the same steps in host loops against the CPU
// smg::regularizers() on machines without a GPU.
#pragma once

#include "smg/cuda/common.cuh"

#include <algorithm>
#include <cstdint>
#include <sstream>
#include <string>
#include <utility>

#include "smg/core/quaternion.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/views.hpp"
#include "smg/cuda/confidence.cuh"
#include "smg/cuda/lrm.cuh"
#include "smg/cuda/validate.cuh"
#include "smg/energy/carap_term.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/confidence_term.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg::cuda {

namespace detail {

// The rigid terms of one call as plain values (kernels take them by value): the distinct gaps δ
// of C-ARAP and ARAP together, and per energy (0: C-ARAP, 1: ARAP) γ_δ times the weight (0 where
// that energy has no such gap). Normalization::mean divides by the number of terms, known only
// on the device (the ReverseGraph's edge count), so the factor is formed where it is used, in
// double and then rounded, as the CPU forms it.
template <class S>
struct FusedRigidConstants {
  Literal<S> alpha = Literal<S>(1);  // C-ARAP's α (E7); ARAP's is 1 with c ≡ 1
  Literal<S> lambda_c[2] = {Literal<S>(0), Literal<S>(0)};
  Literal<S> lambda_l[2] = {Literal<S>(0), Literal<S>(0)};
  int n_gaps = 0;
  int delta[2 * GapList::kCapacity] = {};
  double gap_weight[2][2 * GapList::kCapacity] = {};
  Index pairs[2] = {0, 0};       // Σ_δ max(0, T − δ) over every listed gap of the energy
  bool mean[2] = {false, false};  // Normalization::mean
  const std::int32_t* edge_count = nullptr;  // Σ_i |N(i)| (device memory in kernels)

  // γ_δ · weight / (number of terms with Normalization::mean) of gap g for energy en.
  SMG_HOST_DEVICE Literal<S> gamma(int en, int g) const {
    double scale = gap_weight[en][g];
    if (mean[en]) {
      const Index terms = pairs[en] * static_cast<Index>(*edge_count);
      scale = terms > 0 ? scale / static_cast<double>(terms) : 0.0;
    }
    return Literal<S>(scale);
  }
};

// gamma(en, g) of every gap and energy, formed once per thread (it reads the device edge count
// and divides in double) instead of once per edge, gap and direction.
template <class S>
struct RigidGammas {
  Literal<S> v[2][2 * GapList::kCapacity];
  SMG_HOST_DEVICE explicit RigidGammas(const FusedRigidConstants<S>& c) {
    for (int en = 0; en < 2; ++en)
      for (int g = 0; g < c.n_gaps; ++g) v[en][g] = c.gamma(en, g);
  }
};

// The rotated edge vector of edge i -> j at frame s (E8): R (row-major, from q_i^s), e = x_j − x_i,
// d = Rᵀ e and ‖e‖ (= ‖d‖).
template <class S>
struct RigidEdge {
  S R[9];
  S ex, ey, ez, dx, dy, dz, len;
};

template <class S>
SMG_HOST_DEVICE inline void fused_rigid_edge_at(PositionsView<const S> x,
                                                QuaternionsView<const S> q, Index s, Index i,
                                                Index j, RigidEdge<S>& r) {
  using std::sqrt;
  smg::detail::rotation_from_wxyz(q.ptr(s, i), r.R);
  const S* xi = x.ptr(s, i);
  const S* xj = x.ptr(s, j);
  r.ex = xj[0] - xi[0];
  r.ey = xj[1] - xi[1];
  r.ez = xj[2] - xi[2];
  carap_edge_vector(r.R, r.ex, r.ey, r.ez, r.dx, r.dy, r.dz);
  r.len = sqrt(r.ex * r.ex + r.ey * r.ey + r.ez * r.ez);
}

// One edge i -> j (graph weight w > 0) at frame t in both rigid energies: adds to energy[en] the
// terms of the pairs (t, t + δ) (the pairs frame t owns) when energy is not null; with `grad`,
// writes F = ∂E/∂x_j^t (−F is ∂E/∂x_i^t) and Rg, the right-tangent gradient of R_i^t, from every
// pair containing frame t: (t, t + δ) weighted at t and (t − δ, t) weighted at t − δ (E7, E9,
// E10). conf: c [T][N] (row-major) or null (c ≡ 1).
template <class S>
SMG_HOST_DEVICE inline void fused_rigid_edge(const FusedRigidConstants<S>& c,
                                             const RigidGammas<S>& gamma,
                                             PositionsView<const S> x, QuaternionsView<const S> q,
                                             const S* conf, Index t, Index i, Index j, S w,
                                             bool grad, S* energy, S* F, S* Rg) {
  using L = Literal<S>;
  const Index T = x.frames(), N = x.nodes();
  RigidEdge<S> e0;
  fused_rigid_edge_at(x, q, t, i, j, e0);
  // w̃ (E7) of this edge at frame u, per energy.
  auto weight = [&](Index u, int en) {
    return en == 0 ? confidence_edge_weight(w, c.alpha, conf ? conf[u * N + j] : S(1))
                   : confidence_edge_weight(w, L(1), S(1));
  };
  S gx(0), gy(0), gz(0), h(0);
  for (int g = 0; g < c.n_gaps; ++g) {
    const Index delta = c.delta[g];
    S px, py, pz, pq;
    if (t + delta < T) {  // pair (t, t + δ), weighted at t: its energy belongs to frame t
      RigidEdge<S> es;
      fused_rigid_edge_at(x, q, t + delta, i, j, es);
      for (int en = 0; en < 2; ++en) {
        const L gm = gamma.v[en][g];
        if (gm == L(0)) continue;
        const S ev = carap_term(S(gm * weight(t, en)), es.dx - e0.dx, es.dy - e0.dy,
                                es.dz - e0.dz, es.len - e0.len, c.lambda_c[en], c.lambda_l[en],
                                px, py, pz, pq);  // (E9)
        if (energy != nullptr) energy[en] += ev;
        gx -= px;
        gy -= py;
        gz -= pz;
        h -= pq;
      }
    }
    if (grad && t - delta >= 0) {  // pair (t − δ, t), weighted at t − δ
      RigidEdge<S> ep;
      fused_rigid_edge_at(x, q, t - delta, i, j, ep);
      for (int en = 0; en < 2; ++en) {
        const L gm = gamma.v[en][g];
        if (gm == L(0)) continue;
        carap_term(S(gm * weight(t - delta, en)), e0.dx - ep.dx, e0.dy - ep.dy, e0.dz - ep.dz,
                   e0.len - ep.len, c.lambda_c[en], c.lambda_l[en], px, py, pz, pq);
        gx += px;
        gy += py;
        gz += pz;
        h += pq;
      }
    }
  }
  if (!grad) return;
  const S inv_len = e0.len > S(0) ? S(1) / e0.len : S(0);
  carap_edge_backprop(e0.R, gx, gy, gz, h, inv_len, e0.ex, e0.ey, e0.ez, e0.dx, e0.dy, e0.dz,
                      F[0], F[1], F[2], Rg[0], Rg[1], Rg[2]);  // (E10)
}

// Phase 2, element (t, n): node n at frame t as the tail of its out-edges (their energies into
// energy[2], −F and the rotation parts) and, when the position gradient is wanted, as the head
// of its in-edges (+F, in the ReverseGraph's increasing slot order). Adds x_n^t's gradient to
// grad_x [T][N][3] and R_n^t's to grad_tangent [T][N][3] or grad_raw [T][N][4] (Q5); each may be
// null. Only this element writes those rows.
template <class S, class I>
SMG_HOST_DEVICE inline void fused_rigid_node_at(
    Index t, Index n, const FusedRigidConstants<S>& c, PositionsView<const S> x,
    QuaternionsView<const S> q, const S* conf, const NeighborsView<S, I>& graph,
    const std::int32_t* rev_offsets, const std::int64_t* rev_entries, S* grad_x,
    S* grad_tangent, S* grad_raw, S* energy) {
  const Index N = x.nodes(), K = graph.k();
  const bool want_r = grad_tangent != nullptr || grad_raw != nullptr;
  const bool grad = grad_x != nullptr || want_r;
  const RigidGammas<S> gamma(c);
  S g[3] = {S(0), S(0), S(0)}, r[3] = {S(0), S(0), S(0)};
  for (Index k = 0; k < K; ++k) {
    const Index j = graph.indices(n, k);
    if (j < 0) break;
    const S w = graph.weights(n, k);
    if (!(w > S(0))) continue;  // a zero weight contributes exactly nothing
    S F[3], Rg[3];
    fused_rigid_edge(c, gamma, x, q, conf, t, n, j, w, grad, energy, F, Rg);
    if (!grad) continue;
    for (int a = 0; a < 3; ++a) {
      g[a] -= F[a];
      r[a] += Rg[a];
    }
  }
  if (grad_x != nullptr) {
    for (std::int32_t a = rev_offsets[n]; a < rev_offsets[n + 1]; ++a) {
      const Index slot = rev_entries[a], i = slot / K, k = slot - i * K;
      const S w = graph.weights(i, k);
      if (!(w > S(0))) continue;
      S F[3], Rg[3];
      fused_rigid_edge(c, gamma, x, q, conf, t, i, n, w, true, static_cast<S*>(nullptr), F, Rg);
      for (int b = 0; b < 3; ++b) g[b] += F[b];
    }
    S* dst = grad_x + (t * N + n) * 3;
    for (int b = 0; b < 3; ++b) dst[b] += g[b];
  }
  if (grad_tangent != nullptr)
    for (int b = 0; b < 3; ++b) grad_tangent[(t * N + n) * 3 + b] += r[b];
  if (grad_raw != nullptr)
    add_quaternion_gradient_from_tangent(q.ptr(t, n), r, grad_raw + (t * N + n) * 4);  // (Q5)
}

// Phase 2: one thread per node, frames along y; per-block energy partials [2][blocks] (C-ARAP,
// ARAP), each the block's fixed tree sum of its threads' sums.
template <class S, class I>
__global__ void fused_rigid_kernel(FusedRigidConstants<S> c, PositionsView<const S> x,
                                   QuaternionsView<const S> q, const S* conf,
                                   NeighborsView<S, I> graph, const std::int32_t* rev_offsets,
                                   const std::int64_t* rev_entries, S* grad_x, S* grad_tangent,
                                   S* grad_raw, Accumulator<S>* partials) {
  using Acc = Accumulator<S>;
  __shared__ Acc shared[kThreads];
  const int n = frame_item(x.nodes());
  Acc sum[2] = {Acc(0), Acc(0)};
  SMG_CUDA_FOR_FRAMES(t, x.frames()) {
    if (n < 0) continue;
    S e[2] = {S(0), S(0)};
    fused_rigid_node_at(t, Index(n), c, x, q, conf, graph, rev_offsets, rev_entries, grad_x,
                        grad_tangent, grad_raw, e);
    sum[0] += Acc(e[0]);
    sum[1] += Acc(e[1]);
  }
  const unsigned blocks = gridDim.x * gridDim.y, block = blockIdx.y * gridDim.x + blockIdx.x;
  for (int en = 0; en < 2; ++en) {
    const Acc s = block_tree_sum(sum[en], shared);
    if (threadIdx.x == 0) partials[en * blocks + block] = s;
    __syncthreads();  // every thread has read shared[0] before the next sum overwrites it
  }
}

// KMax sizes lrm_term_at's local arrays (8, 16 or 32), picked at launch from K as cuda::lrm
// does: a runtime choice inside one kernel would give every K the 32-entry stack frame.
template <class S, class I, int KMax>
__global__ void fused_lrm_term_kernel(Index c0, Index frames, PositionsView<const S> x,
                                      FrameScalarsView<const S> conf, NeighborsView<S, I> graph,
                                      LrmKernelArgs<S> args, Accumulator<S>* terms, S* gx_edges,
                                      S* gu_edges) {
  const Index n = frames * x.nodes();
  const Index e = blockIdx.x * static_cast<Index>(blockDim.x) + threadIdx.x;
  if (e >= n) return;
  const Index base = c0 * x.nodes();
  lrm_term_at<S, I, KMax>(base + e, x, conf, graph, args, terms, gx_edges, gu_edges, {}, base);
}

template <class S>
__global__ void fused_lrm_velocity_kernel(Index s0, Index frames, Index c0, Index c1, Index T,
                                          Index N, const S* gx, const S* gu,
                                          PositionsView<S> grad) {
  const int j = frame_item(N);
  if (j < 0) return;
  SMG_CUDA_FOR_FRAMES(l, frames) lrm_velocity_chunk_at(s0 + l, Index(j), c0, c1, T, N, gx, gu, grad);
}

// The rigid constants of a call over T frames; edge_count: Σ_i |N(i)| where the kernels read it
// (device memory in the launcher, host memory in a host loop).
template <class S>
FusedRigidConstants<S> fused_rigid_constants(const RegularizerOptions& o, Index T,
                                             const std::int32_t* edge_count) {
  using L = Literal<S>;
  FusedRigidConstants<S> c;
  c.alpha = L(o.carap.alpha);
  c.edge_count = edge_count;
  const bool on[2] = {o.terms.carap, o.terms.arap};
  const GapList* lists[2] = {&o.carap.gaps, &o.arap.gaps};
  const double weights[2] = {o.carap.weight, o.arap.weight};
  const Normalization norms[2] = {o.carap.normalization, o.arap.normalization};
  c.lambda_c[0] = L(o.carap.lambda_c);
  c.lambda_l[0] = L(o.carap.lambda_l);
  c.lambda_c[1] = L(o.arap.lambda_c);
  c.lambda_l[1] = L(o.arap.lambda_l);
  for (int en = 0; en < 2; ++en) {
    if (!on[en]) continue;
    c.mean[en] = norms[en] == Normalization::mean;
    for (const Gap& g : *lists[en]) c.pairs[en] += std::max<Index>(0, T - g.delta);
    for (const Gap& g : *lists[en]) {
      if (!(g.delta >= 1 && g.delta < T && g.weight != 0.0)) continue;
      // One slot per distinct δ: both energies share its rotated edge vectors.
      int slot = 0;
      while (slot < c.n_gaps && c.delta[slot] != g.delta) ++slot;
      if (slot == c.n_gaps) c.delta[c.n_gaps++] = static_cast<int>(g.delta);
      c.gap_weight[en][slot] += g.weight * weights[en];
    }
  }
  return c;
}

// LRM's kernel arguments for a call over T frames (as cuda::lrm forms them); edge_count as above.
template <class S>
LrmKernelArgs<S> fused_lrm_args(const RegularizerOptions& o, Index T, bool gradient,
                                const std::int32_t* edge_count) {
  using L = Literal<S>;
  LrmKernelArgs<S> args;
  args.p = smg::detail::lrm_params<S>(o.lrm, gradient);
  args.alpha = L(o.lrm.alpha);
  args.scale = L(o.lrm.weight);
  args.weight = o.lrm.weight;
  args.frames = T;
  args.edge_count = o.lrm.normalization == Normalization::mean ? edge_count : nullptr;
  return args;
}

// The plan of one call (host): which phases run, the chunk lengths, the scratch.
struct FusedPlan {
  bool confidence = false, rigid = false, lrm = false, want_x = false, want_r = false;
  bool conf_scratch = false;  // c [T][N] in scratch (no caller output)
  Index conf_chunk = 1, lrm_chunk = 1;
  std::size_t extra_bytes = 0;  // peak scratch bytes
};

template <class S, class I>
FusedPlan fused_plan(Index T, Index N, Index K, const RegularizerOptions& o, bool want_x,
                     bool want_r, bool rotations, bool visibility, bool conf_out) {
  using Acc = Accumulator<S>;
  FusedPlan p;
  const RegularizerTerms& on = o.terms;
  bool any_gap = false;
  for (const auto& [listed, list] : {std::pair{on.carap, &o.carap.gaps}, std::pair{on.arap, &o.arap.gaps}})
    if (listed)
      for (const Gap& g : *list) any_gap = any_gap || (g.delta >= 1 && g.delta < T && g.weight != 0.0);
  p.rigid = any_gap && K > 0;
  p.lrm = on.lrm && K > 0;
  p.confidence = on.confidence && (conf_out || p.rigid || p.lrm);
  p.want_x = want_x && (p.rigid || p.lrm);
  p.want_r = want_r && p.rigid;
  p.conf_scratch = p.confidence && !conf_out;
  if (T == 0 || N == 0) return p;
  const std::size_t bound =
      smg::detail::regularizer_input_bytes<S, I>(T, N, K, rotations, visibility);
  std::size_t fixed = p.conf_scratch ? sizeof(S) * static_cast<std::size_t>(T * N) : 0;
  if (p.confidence) fixed += sizeof(S) * static_cast<std::size_t>(N);  // 1/Σw
  // Energy partials: the rigid kernel's blocks, and deterministic_sum's.
  const std::size_t blocks =
      static_cast<std::size_t>(grid_for(N)) * std::min<Index>(T, 65535);
  if (p.rigid) fixed += 2 * blocks * sizeof(Acc);
  fixed += kSumBlocks * sizeof(Acc);
  const std::size_t left = bound > fixed ? bound - fixed : 0;
  auto frames_within = [&](std::size_t per_frame) {
    const Index f = per_frame > 0 ? static_cast<Index>(left / per_frame) : T;
    return std::max<Index>(1, std::min<Index>(T, f));
  };
  std::size_t peak = 0;
  if (p.confidence) {
    const std::size_t per = sizeof(S) * static_cast<std::size_t>(4 * N);
    p.conf_chunk = frames_within(per);
    peak = std::max(peak, per * static_cast<std::size_t>(p.conf_chunk));
  }
  if (p.lrm) {
    std::size_t per = sizeof(Acc) * static_cast<std::size_t>(N);
    if (p.want_x) per += sizeof(S) * static_cast<std::size_t>(6 * N * K + 6 * N);
    p.lrm_chunk = frames_within(per);
    peak = std::max(peak, per * static_cast<std::size_t>(p.lrm_chunk));
  }
  p.extra_bytes = fixed + peak;
  return p;
}

}  // namespace detail

// The peak scratch bytes smg::cuda::regularizers allocates for these shapes, options and outputs
// (the energy partials, the [T][N] confidences unless the caller takes them, and the largest
// chunk's scratch); at most regularizer_input_bytes (the inputs' bytes) except where one frame's
// chunk alone exceeds what is left (short sequences). The ReverseGraph, built once per graph by
// the caller, is not counted.
template <class S, class I>
std::size_t regularizers_extra_bytes(Index frames, Index nodes, Index k,
                                     const RegularizerOptions& options, bool grad_positions,
                                     bool grad_rotations, bool rotations_given,
                                     bool visibility_given, bool confidence_out) {
  return detail::fused_plan<S, I>(frames, nodes, k, options, grad_positions, grad_rotations,
                                  rotations_given, visibility_given, confidence_out)
      .extra_bytes;
}

// Checks the shapes and options of smg::cuda::regularizers on the host (the views are over
// device memory: contents are not read; run validate_regularizers below on untrusted data
// first). Same messages as the CPU validate_regularizers for what it checks; in addition
// K <= kLrmMaxK with LRM on, no smoothness term (not on CUDA yet) and a ReverseGraph built
// for this graph.
template <class S, class I>
Status validate_regularizers_shapes(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                                    smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
                                    VisibilityView<const std::uint8_t> visibility,
                                    const NeighborsView<S, I>& graph,
                                    const RegularizerOptions& options,
                                    const ReverseGraph& reverse,
                                    smg::detail::NonDeducedT<FrameScalarsView<S>> confidence = {},
                                    smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {},
                                    smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  const RegularizerTerms& on = options.terms;
  auto shape = [&](Index t, Index n, const char* name, const char* what) -> Status {
    if (t == T && n == N) return Status::ok();
    std::ostringstream s;
    s << name << ": expected shape [T=" << T << "][N=" << N << "]" << what << ", got [" << t
      << "][" << n << "]";
    return Status::error(s.str());
  };
  if (positions.size() > 0 && positions.data() == nullptr)
    return Status::error("positions: null data pointer for a non-empty array");
  if ((on.carap || on.arap) && !(rotations.data() == nullptr && T * N == 0))
    if (Status s = shape(rotations.frames(), rotations.nodes(), "rotations", "[4]"); !s) return s;
  if (visibility.data() != nullptr)
    if (Status s = shape(visibility.frames(), visibility.nodes(), "visibility", ""); !s) return s;
  if (graph.indices.rows() != N || graph.weights.rows() != N || graph.weights.cols() != K) {
    std::ostringstream s;
    s << "graph: expected indices and weights of shape [N=" << N << "][K], got ["
      << graph.indices.rows() << "][" << K << "] and [" << graph.weights.rows() << "]["
      << graph.weights.cols() << "]";
    return Status::error(s.str());
  }
  if (on.lrm && K > kLrmMaxK) {
    std::ostringstream s;
    s << "graph: K=" << K << " neighbours per node exceeds the CUDA LRM kernel's maximum of "
      << kLrmMaxK;
    return Status::error(s.str());
  }
  if (Status s = validate_options(options); !s) return s;
  // The CUDA fused step has no smoothness term yet (the CPU driver's terms/accel.hpp).
  if (on.accel)
    return Status::error("options.terms.accel: the smoothness term is not on CUDA yet");
  if (confidence.data() != nullptr) {
    if (!on.confidence)
      return Status::error("confidence: an output was given but options.terms.confidence is off");
    if (Status s = shape(confidence.frames(), confidence.nodes(), "confidence", ""); !s) return s;
  }
  if (grad_positions.data() != nullptr)
    if (Status s = shape(grad_positions.frames(), grad_positions.nodes(), "grad_positions", "[3]");
        !s)
      return s;
  if (!grad_rotations.empty())
    if (Status s = shape(grad_rotations.frames(), grad_rotations.nodes(), "grad_rotations",
                         grad_rotations.is_raw() ? "[4]" : "[3]");
        !s)
      return s;
  if (reverse.nodes != N || reverse.k != K) {
    std::ostringstream s;
    s << "reverse: built for a graph of shape [N=" << reverse.nodes << "][K=" << reverse.k
      << "], this graph is [N=" << N << "][K=" << K
      << "] (build_reverse_graph(graph.indices.data(), N, K, stream, reverse))";
    return Status::error(s.str());
  }
  return Status::ok();
}

// The CPU validate_regularizers on device inputs (copied to the host once; synchronises
// `stream`): the same messages as the CPU. For untrusted data, once, not in a training loop.
template <class S, class I>
Status validate_regularizers(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                             smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
                             VisibilityView<const std::uint8_t> visibility,
                             const NeighborsView<S, I>& graph, const RegularizerOptions& options,
                             smg::detail::NonDeducedT<FrameScalarsView<S>> confidence = {},
                             smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {},
                             smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                             cudaStream_t stream = nullptr) {
  detail::HostInputs<S, I> h;
  if (Status s = h.copy(positions, rotations, {}, visibility, graph, stream); !s) return s;
  return smg::validate_regularizers<S, I>(h.like(positions, h.x), h.like(rotations, h.q),
                                          h.like(visibility, h.vis), h.graph(graph), options,
                                          confidence, grad_positions, grad_rotations);
}

// The fused regulariser step on the GPU: the same energies and gradients as the CPU
// smg::regularizers() with the same options (to rounding: sums are associated differently).
// Every view is over DEVICE memory:
//   positions [T][N][3]; rotations [T][N][4] (w, x, y, z; normalised on use), may be empty
//   without C-ARAP and ARAP; visibility [T][N] (0/1) or empty; graph indices [N][K] (int32 or
//   int64, −1 padded; K <= kLrmMaxK with LRM) and weights [N][K];
//   reverse: build_reverse_graph(graph.indices.data(), N, K, stream, reverse), once per graph;
//   result_device: one RegularizerResult<S> (energies in Accumulator<S>), overwritten;
//   confidence [T][N]: receives c (E6) when given (terms.confidence on);
//   grad_positions [T][N][3], grad_rotations (right tangent [T][N][3] or raw [T][N][4], Q5): the
//   gradient of carap + arap + lrm is ADDED; empty = not computed.
// Confidences are constants for the gradient (stop-gradient), as on the CPU. Queued on
// `stream`; nothing is synchronised; bit-identical run to run on a given device. Shapes and
// options are checked on the host first (validate_regularizers_shapes); contents are the
// caller's precondition (validate_regularizers). Scratch: regularizers_extra_bytes.
template <class S, class I>
Status regularizers(smg::detail::NonDeducedT<PositionsView<const S>> positions,
                    smg::detail::NonDeducedT<QuaternionsView<const S>> rotations,
                    VisibilityView<const std::uint8_t> visibility,
                    const NeighborsView<S, I>& graph, const RegularizerOptions& options,
                    const ReverseGraph& reverse, RegularizerResult<S>* result_device,
                    smg::detail::NonDeducedT<FrameScalarsView<S>> confidence = {},
                    smg::detail::NonDeducedT<PositionsView<S>> grad_positions = {},
                    smg::detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
                    cudaStream_t stream = nullptr) {
  using L = Literal<S>;
  using Acc = Accumulator<S>;
  if (Status s = validate_regularizers_shapes<S, I>(positions, rotations, visibility, graph,
                                                    options, reverse, confidence,
                                                    grad_positions, grad_rotations);
      !s)
    return s;
  if (result_device == nullptr) return Status::error("result_device: null pointer");
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  SMG_CUDA_TRY(cudaMemsetAsync(result_device, 0, sizeof(RegularizerResult<S>), stream),
               "smg::cuda::regularizers: result");
  const detail::FusedPlan p = detail::fused_plan<S, I>(
      T, N, K, options, grad_positions.data() != nullptr, !grad_rotations.empty(),
      rotations.data() != nullptr, visibility.data() != nullptr, confidence.data() != nullptr);
  if (T == 0 || N == 0 || !(p.confidence || p.rigid || p.lrm)) return Status::ok();
  if (Status s = check_frame_items(N, "positions"); !s) return s;

  // Phase 1: confidences into the caller's output or [T][N] scratch.
  DeviceBuffer<S> conf_buf;
  S* conf = confidence.data();
  if (p.conf_scratch) {
    if (Status s = conf_buf.allocate(static_cast<std::size_t>(T * N), stream); !s) return s;
    conf = conf_buf.get();
  }
  if (p.confidence) {
    DeviceBuffer<S> inv_w, u, e;
    if (Status s = inv_w.allocate(static_cast<std::size_t>(N), stream); !s) return s;
    if (Status s = u.allocate(static_cast<std::size_t>(3 * N * p.conf_chunk), stream); !s) return s;
    if (Status s = e.allocate(static_cast<std::size_t>(N * p.conf_chunk), stream); !s) return s;
    detail::inverse_row_weight_kernel<S, I><<<grid_for(N), kThreads, 0, stream>>>(graph, inv_w.get());
    const ConfidenceConstants<S> cp(options.confidence);
    for (Index c0 = 0; c0 < T; c0 += p.conf_chunk) {
      const Index nf = std::min(p.conf_chunk, T - c0);
      const dim3 grid = frame_grid(N, nf);
      detail::confidence_inputs_kernel<S, I><<<grid, kThreads, 0, stream>>>(
          c0, nf, positions, graph, inv_w.get(), u.get(), e.get());
      detail::confidence_kernel<S, I><<<grid, kThreads, 0, stream>>>(
          c0, nf, graph, inv_w.get(), u.get(), e.get(), cp, visibility.data(), conf,
          static_cast<S*>(nullptr), static_cast<S*>(nullptr));
    }
    SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::regularizers: confidence kernel launch");
  }
  const S* conf_in = (p.confidence && (p.rigid || p.lrm)) ? conf : nullptr;
  S* const gx = p.want_x ? grad_positions.data() : nullptr;

  // Phase 2: C-ARAP and ARAP, one thread per (frame, node), no per-edge scratch.
  if (p.rigid) {
    const detail::FusedRigidConstants<S> c =
        detail::fused_rigid_constants<S>(options, T, reverse.edge_count());
    S* const gt = p.want_r && !grad_rotations.is_raw() ? grad_rotations.tangent().data() : nullptr;
    S* const graw = p.want_r && grad_rotations.is_raw() ? grad_rotations.raw().data() : nullptr;
    const dim3 grid = frame_grid(N, T);
    const Index blocks = static_cast<Index>(grid.x) * grid.y;
    DeviceBuffer<Acc> partials;
    if (Status s = partials.allocate(static_cast<std::size_t>(2 * blocks), stream); !s) return s;
    detail::fused_rigid_kernel<S, I><<<grid, kThreads, 0, stream>>>(
        c, positions, rotations, conf_in, graph, reverse.offsets.get(), reverse.entries.get(), gx,
        gt, graw, partials.get());
    SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::regularizers: rigid kernel launch");
    if (Status s = deterministic_sum(partials.get(), blocks, &result_device->carap, stream); !s)
      return s;
    if (Status s = deterministic_sum(partials.get() + blocks, blocks, &result_device->arap, stream);
        !s)
      return s;
  }

  // Phase 3: LRM by chunks of frames.
  if (p.lrm) {
    const bool mean = options.lrm.normalization == Normalization::mean;
    const detail::LrmKernelArgs<S> args =
        detail::fused_lrm_args<S>(options, T, p.want_x, reverse.edge_count());
    const Index chunk = p.lrm_chunk;
    DeviceBuffer<Acc> terms;
    DeviceBuffer<S> edges, nodes;
    if (Status s = terms.allocate(static_cast<std::size_t>(N * chunk), stream); !s) return s;
    if (p.want_x) {
      if (Status s = edges.allocate(static_cast<std::size_t>(6 * N * K * chunk), stream); !s)
        return s;
      if (Status s = nodes.allocate(static_cast<std::size_t>(6 * N * chunk), stream); !s) return s;
    }
    const FrameScalarsView<const S> cv = conf_in ? FrameScalarsView<const S>(conf_in, T, N)
                                                 : FrameScalarsView<const S>();
    for (Index c0 = 0; c0 < T; c0 += chunk) {
      const Index nf = std::min(chunk, T - c0), c1 = c0 + nf, n = nf * N;
      S* gxe = edges.get();
      S* gue = gxe ? gxe + 3 * n * K : nullptr;
      if (K <= 8)
        detail::fused_lrm_term_kernel<S, I, 8><<<grid_for(n), kThreads, 0, stream>>>(
            c0, nf, positions, cv, graph, args, terms.get(), gxe, gue);
      else if (K <= 16)
        detail::fused_lrm_term_kernel<S, I, 16><<<grid_for(n), kThreads, 0, stream>>>(
            c0, nf, positions, cv, graph, args, terms.get(), gxe, gue);
      else
        detail::fused_lrm_term_kernel<S, I, 32><<<grid_for(n), kThreads, 0, stream>>>(
            c0, nf, positions, cv, graph, args, terms.get(), gxe, gue);
      SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::regularizers: LRM kernel launch");
      if (Status s = deterministic_sum(terms.get(), n, &result_device->lrm, stream,
                                       Acc(options.lrm.weight), c0 > 0,
                                       mean ? reverse.edge_count() : nullptr, T);
          !s)
        return s;
      if (!p.want_x) continue;
      S* gxn = nodes.get();
      S* gun = gxn + 3 * n;
      detail::lrm_gather_kernel<S><<<grid_for(n), kThreads, 0, stream>>>(
          nf, N, K, reverse.offsets.get(), reverse.entries.get(), gxe, gue, gxn, gun);
      const Index s0 = c0 > 0 ? c0 - 1 : 0, s1 = std::min(T, c1 + 1);
      detail::fused_lrm_velocity_kernel<S><<<frame_grid(N, s1 - s0), kThreads, 0, stream>>>(
          s0, s1 - s0, c0, c1, T, N, gxn, gun, grad_positions);
      SMG_CUDA_TRY(cudaGetLastError(), "smg::cuda::regularizers: LRM gradient kernel launch");
    }
  }
  return Status::ok();
}

}  // namespace smg::cuda
