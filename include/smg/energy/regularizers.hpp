// smg/energy/regularizers.hpp — the regulariser step in one pass: node confidences (E2)-(E6),
// C-ARAP (E7)-(E10), plain ARAP ((E9) with c ≡ 1, α = 1) and LRM (E11)-(E16), any subset, with
// the gradients of the energies, from one walk over the graph (docs/math/energy.md "The fused
// regulariser pass").
//
// Why one pass: a trainer calls all four every iteration, and the separate operators each
// gather the same neighbourhoods again and keep their own scratch (LRM a blocked copy of the
// positions, velocities and confidences, confidences a [T][N] edge-change and velocity array).
// Here the frames are cut into blocks exactly as carap.hpp does; per block and node:
//   - the node's neighbourhood over the block's frames is gathered once (node-major copy of the
//     block's positions and confidences, one contiguous record per neighbour);
//   - d_ij^t = R_i^tᵀ (x_j^t − x_i^t) (E8) is computed once per (frame, edge) and reused by every
//     gap of C-ARAP and of ARAP; their d-gradients are summed before one back-propagation (E10);
//   - LRM (E11)-(E15) reads the same gathered records (W frames per SIMD lane group, as lrm());
//   - the confidences (E6) of the block's frames are computed first, by the block itself, into
//     the same records: C-ARAP and LRM use c at the earlier frame t (E7), which the block owns,
//     and treat them as constants (stop-gradient), as the separate operators do.
// Every equation is the element functions' (confidence_term.hpp, carap_term.hpp, lrm_term.hpp,
// common.hpp's confidence_edge_weight): nothing is written twice.
//
// Determinism: a block owns the gradient rows of its frames; contributions to the up to
// max(δ) frames past its end (and LRM's velocity term at the last frame, which reaches frame
// T − 2) go to per-block spill buffers added afterwards in block order. No float atomics: the
// results are bit-identical for any thread count, in float and double.
//
// Memory (what it allocates; all but the last item in the EnergyWorkspace): per scratch slot 4·N·S_b (the block's
// positions and confidences) + 3·N·S_b (the block's position gradient) + 4·N (one frame's
// velocities and edge changes, confidences only) + O(K·S_b · gaps) per-node arrays, with
// S_b = the block's stored frames (at most 32 + max δ, rounded up to 4); plus
// 2·blocks·max(δ)·N·3 spill, N·3 for LRM's last-frame term, N for 1/Σw and 16 scalars of
// alignment slack; outside the workspace, per block (not per node), four vectors of O(K)
// entries (LRM's lanes, the active edges), as carap() and lrm() have. There is no T·N·K
// and no T·N·3 scratch (the raw-quaternion gradient is converted per contribution). The number
// of slots (≤ threads, ≤ blocks) is lowered until the total is at most the bytes of the inputs
// (positions, rotations, visibility, graph); only one slot is left where even that exceeds
// them, which happens for short sequences: one slot (7·N·S_b) plus the spill (about 6·N·max δ
// per block of 8 to 32 frames) against 7·N·T of inputs; with N = 5000, K = 8 or 16, all four
// terms and gradients, float, up to T ≈ 20 frames (measured). regularizers_extra_bytes()
// returns the figure; tests/energy/test_regularizers.cpp checks it against the workspace.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/quaternion.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/carap.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/confidence_term.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/lrm.hpp"
#include "smg/energy/lrm_term.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/energy/workspace.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

// The energies of one fused step, each as the separate operator returns it (0 for a term that
// is off), in Accumulator<S> (double for float).
template <class S>
struct RegularizerResult {
  Accumulator<S> carap = Accumulator<S>(0);
  Accumulator<S> arap = Accumulator<S>(0);
  Accumulator<S> lrm = Accumulator<S>(0);
  Accumulator<S> total() const { return carap + arap + lrm; }
};

// Checks the arguments of regularizers(); one line naming the bad argument. `rotations` may be
// empty when neither C-ARAP nor ARAP is on; `visibility` [T][N] (0/1) may be empty (all
// visible); `confidence` (output [T][N]) may be given only with terms.confidence; the
// gradients may be empty (not computed).
template <class S, class I>
Status validate_regularizers(detail::NonDeducedT<PositionsView<const S>> positions,
                             detail::NonDeducedT<QuaternionsView<const S>> rotations,
                             VisibilityView<const std::uint8_t> visibility,
                             const NeighborsView<S, I>& graph, const RegularizerOptions& options,
                             FrameScalarsView<S> confidence = {},
                             PositionsView<S> grad_positions = {},
                             detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  const RegularizerTerms& on = options.terms;
  if (Status s = validate_positions<S>(positions, -1, -1, "positions"); !s) return s;
  if (on.carap || on.arap || rotations.data() != nullptr)
    if (Status s = validate_quaternions<S>(rotations, T, N, QuaternionNorm::normalize_on_entry,
                                           "rotations");
        !s)
      return s;
  if (visibility.data() != nullptr)
    if (Status s = validate_visibility<std::uint8_t>(visibility, T, N, "visibility"); !s) return s;
  if (Status s = validate_neighbors(graph, N, "graph"); !s) return s;
  if (Status s = validate_options(options); !s) return s;
  if (confidence.data() != nullptr && !on.confidence)
    return Status::error("confidence: an output was given but options.terms.confidence is off");
  if (Status s = validate_optional_output(confidence, T, N, "confidence"); !s) return s;
  if (Status s = validate_optional_output(grad_positions, T, N, "grad_positions"); !s) return s;
  if (grad_rotations.is_raw())
    if (Status s = validate_output(grad_rotations.raw(), T, N, "grad_rotations"); !s) return s;
  if (Status s = validate_optional_output(grad_rotations.tangent(), T, N, "grad_rotations"); !s)
    return s;
  return Status::ok();
}

namespace detail {
inline namespace SMG_ISA_NAMESPACE {

// One gap of C-ARAP or ARAP in the fused pass: its δ, γ_δ times the energy's scale, and which
// energy (0: C-ARAP, 1: ARAP) it belongs to.
template <class S>
struct RigidGap {
  Index delta = 1;
  Literal<S> gamma = Literal<S>(0);
  int energy = 0;
};

// The plan of one fused call: block partition, strides and sizes (a function of the shapes,
// options and slot count only, so that the results never depend on it).
struct RegularizerPlan {
  Index T = 0, N = 0, K = 0;
  Index B = 0, blocks = 0, G = 0;  // frames per block, blocks, frames spilled past a block
  Index W = 1;                     // LRM lanes
  Index span = 0;                  // stored frames per block (stride bound)
  Index n_gaps = 0;                // rigid gaps (C-ARAP and ARAP together)
  bool rigid = false, lrm = false, confidence = false, want_x = false, want_r = false;
  Index slots = 1;

  static Index padded(Index frames) { return (frames + 3) / 4 * 4; }
  static Index round_up(Index v, Index m) { return (v + m - 1) / m * m; }
  // Stored frames of a block with nr frames incl. the overlap and nown owned frames: LRM's
  // velocity lanes read one frame past the last owned lane group.
  Index stride(Index nr, Index nown) const {
    return lrm ? padded(std::max(nr, round_up(nown, W) + 1)) : padded(nr);
  }
  Index M() const { return K * span; }
  // Every scratch array starts on a 64-byte boundary (its size rounded up to 16 scalars, the
  // slots' base aligned): Eigen's packet sums (sum_array) associate an unaligned head
  // differently, so the energies would otherwise depend on where the workspace or the slot
  // lies (with AVX, whose packets are 32 bytes and malloc's alignment 16).
  static constexpr Index kAlign = 16;
  static Index chunk(Index n) { return round_up(n, kAlign); }
  // Scalars of one slot: the block's node-major positions and confidences, its position
  // gradient, one frame's velocities and edge changes, the per-node [edge][frame] arrays (16 of
  // them, a mask and four P arrays per gap), the node's rotation and gradient rows.
  Index slot_scalars() const {
    Index s = chunk(4 * N * span);
    if (want_x) s += chunk(3 * N * span);
    if (confidence) s += chunk(3 * N) + chunk(N);
    if (rigid)
      s += 16 * chunk(M()) + chunk(n_gaps * M()) + chunk(n_gaps * 4 * (M() + G)) +
           chunk(9 * span) + 2 * chunk(3 * span);
    return s;
  }
  Index spill_scalars() const {
    Index s = 0;
    if (want_x) s += blocks * G * N * 3 + (lrm ? N * 3 : 0);
    if (want_r && rigid) s += blocks * G * N * 3;
    return s;
  }
  // Spill, 1/Σw, and the slack that aligns the slots' base.
  Index fixed_scalars() const { return spill_scalars() + (confidence ? N : 0) + kAlign; }
  Index total_scalars() const { return slots * slot_scalars() + fixed_scalars(); }
};

template <class S, class I>
RegularizerPlan regularizer_plan(Index T, Index N, Index K, const RegularizerOptions& options,
                                 bool want_x, bool want_r, Index threads,
                                 std::vector<RigidGap<S>>* gaps_out, double* scale_c,
                                 double* scale_a, double* scale_l, Index edges) {
  using L = Literal<S>;
  RegularizerPlan p;
  p.T = T;
  p.N = N;
  p.K = K;
  const RegularizerTerms& on = options.terms;
  p.confidence = on.confidence;
  p.lrm = on.lrm && K > 0;
  p.W = std::is_floating_point_v<S> ? lrm_lanes<S>() : 1;
  std::vector<RigidGap<S>> gaps;
  // The overall scales as carap()/arap()/lrm() compute them (sum, or mean over their counts).
  auto scale_of = [&](double weight, Normalization n, Index terms) {
    if (n != Normalization::mean) return weight;
    return terms == 0 ? 0.0 : weight / static_cast<double>(terms);
  };
  auto add_gaps = [&](const GapList& list, double weight, Normalization n, int energy,
                      double* scale) {
    Index pairs = 0;
    for (const Gap& g : list) pairs += std::max<Index>(0, T - g.delta);
    *scale = scale_of(weight, n, pairs * edges);
    if (*scale == 0.0 && n == Normalization::mean) return;
    for (const Gap& g : list)
      if (g.delta >= 1 && g.delta < T && g.weight != 0.0) {
        RigidGap<S> r;
        r.delta = g.delta;
        r.gamma = L(g.weight * *scale);
        r.energy = energy;
        gaps.push_back(r);
        p.G = std::max<Index>(p.G, g.delta);
      }
  };
  *scale_c = *scale_a = *scale_l = 0.0;
  if (on.carap && K > 0)
    add_gaps(options.carap.gaps, options.carap.weight, options.carap.normalization, 0, scale_c);
  if (on.arap && K > 0)
    add_gaps(options.arap.gaps, options.arap.weight, options.arap.normalization, 1, scale_a);
  if (p.lrm) {
    *scale_l = scale_of(options.lrm.weight, options.lrm.normalization, T * edges);
    if (options.lrm.normalization == Normalization::mean && T * edges == 0) p.lrm = false;
  }
  p.rigid = !gaps.empty();
  p.n_gaps = static_cast<Index>(gaps.size());
  p.want_x = want_x && (p.rigid || p.lrm);
  p.want_r = want_r && p.rigid;
  // LRM's velocity at a block's last frame reads the next frame (E1), and its gradient reaches
  // it: one frame past the block at least, with or without gradients.
  if (p.lrm) p.G = std::max<Index>(p.G, 1);
  p.B = carap_block_frames(T, p.G);
  // LRM's lane groups start at multiples of W, as lrm()'s do.
  if (p.lrm) p.B = RegularizerPlan::round_up(p.B, p.W);
  p.blocks = T > 0 ? (T + p.B - 1) / p.B : 0;
  p.span = p.lrm ? RegularizerPlan::padded(
                       std::max(p.B + p.G, RegularizerPlan::round_up(p.B, p.W) + 1))
                 : RegularizerPlan::padded(p.B + p.G);
  p.slots = std::max<Index>(1, std::min<Index>(threads, p.blocks));
  if (gaps_out) *gaps_out = gaps;
  return p;
}

// The bytes of the fused step's inputs (the bound its extra memory keeps).
template <class S, class I>
std::size_t regularizer_input_bytes(Index T, Index N, Index K, bool rotations, bool visibility) {
  std::size_t b = sizeof(S) * static_cast<std::size_t>(3 * T * N);
  if (rotations) b += sizeof(S) * static_cast<std::size_t>(4 * T * N);
  if (visibility) b += static_cast<std::size_t>(T * N);
  b += (sizeof(S) + sizeof(I)) * static_cast<std::size_t>(N * K);
  return b;
}

// Lowers the slot count until the extra memory fits in the inputs' bytes (at least one slot).
template <class S, class I>
void fit_slots(RegularizerPlan& p, bool rotations, bool visibility) {
  const std::size_t bound =
      regularizer_input_bytes<S, I>(p.T, p.N, p.K, rotations, visibility);
  while (p.slots > 1 &&
         sizeof(S) * static_cast<std::size_t>(p.total_scalars()) > bound)
    --p.slots;
}

// One fused evaluation over the blocks of frames.
template <class S, class I>
struct RegularizerKernel {
  using L = Literal<S>;
  using Acc = Accumulator<S>;
  using V = std::conditional_t<std::is_floating_point_v<S>, LrmLane<S>, S>;

  struct Energies {
    Acc carap = Acc(0), arap = Acc(0), lrm = Acc(0);
  };

  RegularizerPlan plan;
  PositionsView<const S> x;
  QuaternionsView<const S> q;
  VisibilityView<const std::uint8_t> vis;
  NeighborsView<S, I> graph;
  FrameScalarsView<S> conf_out;  // may be empty
  PositionsView<S> gx;           // may be empty
  TangentsView<S> gr;            // may be empty
  QuaternionsView<S> grq;        // may be empty (raw-quaternion gradient)
  std::vector<RigidGap<S>> gaps;
  L alpha_c = L(0), lambda_c_c = L(0), lambda_l_c = L(0);
  L lambda_c_a = L(0), lambda_l_a = L(0);
  L alpha_l = L(0), scale_l = L(0);
  LrmParams<S> lrm_p;
  ConfidenceConstants<S> conf_p{ConfidenceOptions{}};
  bool has_energy[2] = {false, false};  // C-ARAP, ARAP have a gap
  const S* inv_w = nullptr;  // [N] 1/Σ_k w_ik (confidences)
  S* spill = nullptr;        // [blocks][G][N][3] positions, then rotations (tangent)
  S* tail = nullptr;         // [N][3] LRM's last-frame velocity term on frame T − 2
  S* scratch = nullptr;
  Index scratch_per_slot = 0;

  S* spill_x(Index b) const { return spill + b * plan.G * plan.N * 3; }
  S* spill_r(Index b) const {
    return spill + ((plan.want_x ? plan.blocks : 0) + b) * plan.G * plan.N * 3;
  }

  // Adds one right-tangent contribution g (3 values, stride st) of rotation (t, i) to the
  // caller's rotation gradient: as it is (tangent) or converted (raw, (Q5), linear in g).
  void add_rotation(Index t, Index i, const S* g, Index st) const {
    const S v[3] = {g[0], g[st], g[2 * st]};
    if (grq.data()) {
      add_quaternion_gradient_from_tangent(q.ptr(t, i), v, grq.ptr(t, i));
    } else {
      S* dst = gr.ptr(t, i);
      dst[0] += v[0];
      dst[1] += v[1];
      dst[2] += v[2];
    }
  }

  Energies block(Index b, Index slot) const {
    const Index T = plan.T, N = plan.N, K = plan.K, B = plan.B, G = plan.G, W = plan.W;
    const Index t0 = b * B, t1 = std::min(T, t0 + B), te = std::min(T, t1 + G);
    const Index nr = te - t0, nown = t1 - t0;
    const Index ne = plan.stride(nr, nown);
    const Index M = plan.M();
    const bool grad = plan.want_x || plan.want_r;
    const bool want_x = plan.want_x, want_r = plan.want_r;
    // Members copied to locals: loads through `this` inside the loops would block
    // vectorisation (they may alias the scratch arrays).
    const L alp_c = alpha_c, lc_c = lambda_c_c, ll_c = lambda_l_c, lc_a = lambda_c_a,
            ll_a = lambda_l_a;
    S* p = scratch + slot * scratch_per_slot;
    auto take = [&p](Index n) {
      S* r = p;
      p += RegularizerPlan::chunk(n);
      return r;
    };
    const Index n4 = 4 * ne, n3 = 3 * ne;
    S* Xb = take(4 * N * plan.span);  // per node: x, y, z over the block's frames, c owned
    S* GBx = want_x ? take(3 * N * plan.span) : nullptr;
    S *Vel = nullptr, *Ec = nullptr;
    if (plan.confidence) {
      Vel = take(3 * N);
      Ec = take(N);
    }
    S *Ex = nullptr, *Ey = nullptr, *Ez = nullptr, *Dx = nullptr, *Dy = nullptr, *Dz = nullptr;
    S *Len = nullptr, *InvLen = nullptr, *Wb[2] = {nullptr, nullptr}, *Eacc[2] = {nullptr, nullptr};
    S *Gx = nullptr, *Gy = nullptr, *Gz = nullptr, *H = nullptr, *masks = nullptr, *pbase = nullptr;
    S *R = nullptr, *Fi = nullptr, *Ri = nullptr;
    if (plan.rigid) {
      Ex = take(M), Ey = take(M), Ez = take(M), Dx = take(M), Dy = take(M), Dz = take(M);
      Len = take(M), InvLen = take(M), Wb[0] = take(M), Wb[1] = take(M);
      Eacc[0] = take(M), Eacc[1] = take(M);
      Gx = take(M), Gy = take(M), Gz = take(M), H = take(M);
      masks = take(plan.n_gaps * M);
      pbase = take(plan.n_gaps * 4 * (M + G));
      R = take(9 * plan.span), Fi = take(3 * plan.span), Ri = take(3 * plan.span);
      if (grad) std::fill(pbase, pbase + plan.n_gaps * 4 * (M + G), S(0));
      for (Index g = 0; g < plan.n_gaps; ++g) {
        const Index n_d = std::max<Index>(0, std::min(t1, T - gaps[g].delta) - t0);
        S* mk = masks + g * M;
        for (Index e = 0; e < K; ++e)
          for (Index l = 0; l < ne; ++l) mk[e * ne + l] = l < n_d ? S(gaps[g].gamma) : S(0);
      }
    }
    auto P = [&](Index g, int c) { return pbase + (g * 4 + c) * (M + G) + G; };

    // The block's frames node-major (one contiguous record per neighbour).
    std::fill(Xb, Xb + N * n4, S(0));
    for (Index l = 0; l < nr; ++l) {
      const S* row = x.ptr(t0 + l, 0);
      for (Index j = 0; j < N; ++j) {
        S* dst = Xb + j * n4 + l;
        dst[0] = row[3 * j];
        dst[ne] = row[3 * j + 1];
        dst[2 * ne] = row[3 * j + 2];
      }
    }
    if (want_x) std::fill(GBx, GBx + N * n3, S(0));

    // Confidences of the owned frames (E1)-(E6), frame by frame: e_j^t of every node first
    // (the node's confidence reads its neighbours' values), then c_{t,i}, into the records.
    for (Index l = 0; l < nown; ++l) {
      const Index t = t0 + l;
      if (!plan.confidence) {
        for (Index j = 0; j < N; ++j) Xb[j * n4 + 3 * ne + l] = S(1);
        continue;
      }
      for (Index j = 0; j < N; ++j) {
        const Vector3<S> u = velocity(x, t, j);
        Vel[3 * j] = u(0);
        Vel[3 * j + 1] = u(1);
        Vel[3 * j + 2] = u(2);
        Ec[j] = confidence_edge_change(x, graph, inv_w[j], t, j);
      }
      for (Index i = 0; i < N; ++i) {
        // Frame index 0 of the one-frame arrays Vel [1][N][3] and Ec [1][N].
        const S c = confidence_node<S, I>(Vel, Ec, graph, inv_w[i], 0, i, conf_p, nullptr, nullptr);
        const S v = vis.data() ? S(vis(t, i) ? 1 : 0) : S(1);
        const S ci = v * c;
        Xb[i * n4 + 3 * ne + l] = ci;
        if (conf_out.data()) conf_out(t, i) = ci;
      }
    }

    // Neighbours are random in memory: the next node's data is requested while this node
    // computes.
    auto prefetch_node = [&](Index i) {
      constexpr Index line = 64 / static_cast<Index>(sizeof(S));
      if (plan.rigid)
        for (Index l = 0; l < nr; ++l) SMG_PREFETCH(q.ptr(t0 + l, i), 0);
      for (Index k = 0; k < K; ++k) {
        const Index j = graph.indices(i, k);
        if (j < 0) break;
        for (Index o = 0; o < n4; o += line) SMG_PREFETCH(Xb + j * n4 + o, 0);
        if (want_x)
          for (Index o = 0; o < n3; o += line) SMG_PREFETCH(GBx + j * n3 + o, 1);
      }
    };
    if (N > 0) prefetch_node(0);

    Energies energy;
    std::vector<Index> active(static_cast<std::size_t>(plan.n_gaps));
    std::vector<Index> nbr(static_cast<std::size_t>(K));
    std::vector<S> wgt(static_cast<std::size_t>(K));
    // LRM lanes: x, u, a, gx, gu, ω and the neighbourhood scratch (a few KB).
    std::vector<V> lanes(plan.lrm ? static_cast<std::size_t>((13 + lrm_scratch_size(1)) * K + 3)
                                  : 0);
    const Index n_groups = plan.lrm ? (nown + W - 1) / W : 0;

    for (Index i = 0; i < N; ++i) {
      if (i + 1 < N) prefetch_node(i + 1);
      if (plan.rigid) rigid_node(i, t0, nr, nown, ne, M, grad, want_x, want_r, alp_c, lc_c, ll_c,
                                 lc_a, ll_a, Xb, GBx, Ex, Ey, Ez, Dx, Dy, Dz, Len, InvLen, Wb,
                                 Eacc, Gx, Gy, Gz, H, masks, P, R, Fi, Ri, active, nbr, wgt, b,
                                 energy);
      if (plan.lrm)
        for (Index grp = 0; grp < n_groups; ++grp)
          energy.lrm += lrm_group(i, t0, grp * W, std::min(W, nown - grp * W), ne, Xb, GBx,
                                  lanes.data());
    }

    // Owned frames into the caller's rows, the overlap into this block's spill.
    if (want_x)
      for (Index l = 0; l < nr; ++l) {
        const bool own = l < nown;
        S* row = own ? gx.ptr(t0 + l, 0) : spill_x(b) + (l - nown) * N * 3;
        for (Index j = 0; j < N; ++j) {
          const S* src = GBx + j * n3 + l;
          if (own) {
            row[3 * j] += src[0];
            row[3 * j + 1] += src[ne];
            row[3 * j + 2] += src[2 * ne];
          } else {
            row[3 * j] = src[0];
            row[3 * j + 1] = src[ne];
            row[3 * j + 2] = src[2 * ne];
          }
        }
      }
    return energy;
  }

  // C-ARAP and ARAP of node i over the block (E7)-(E10): carap.hpp's kernel with both weight
  // sets on one set of rotated edge vectors.
  template <class PFn>
  void rigid_node(Index i, Index t0, Index nr, Index nown, Index ne, Index M, bool grad,
                  bool want_x, bool want_r, L alp_c, L lc_c, L ll_c, L lc_a, L ll_a, const S* Xb,
                  S* GBx, S* Ex, S* Ey, S* Ez, S* Dx, S* Dy, S* Dz, S* Len, S* InvLen,
                  S* const* Wb, S* const* Eacc, S* Gx, S* Gy, S* Gz, S* H, const S* masks,
                  const PFn& P, S* R, S* Fi, S* Ri, std::vector<Index>& active,
                  std::vector<Index>& nbr, std::vector<S>& wgt, Index b,
                  Energies& energy) const {
    const Index K = plan.K, N = plan.N;
    const Index n4 = 4 * ne, n3 = 3 * ne;
    (void)M;
    // Active edges: positive weight (a zero weight contributes exactly nothing).
    Index m_e = 0;
    for (Index k = 0; k < K; ++k) {
      const Index j = graph.indices(i, k);
      if (j < 0) break;
      const S w = graph.weights(i, k);
      if (!(w > S(0))) continue;
      nbr[static_cast<std::size_t>(m_e)] = j;
      wgt[static_cast<std::size_t>(m_e)] = w;
      ++m_e;
    }
    if (m_e == 0) return;
    const Index m = m_e * ne;
    for (Index l = 0; l < ne; ++l) {
      S Rl[9] = {S(0), S(0), S(0), S(0), S(0), S(0), S(0), S(0), S(0)};
      if (l < nr) rotation_from_wxyz(q.ptr(t0 + l, i), Rl);
      for (int c = 0; c < 9; ++c) R[c * ne + l] = Rl[c];
    }
    const S* Xi = Xb + i * n4;
    const bool has[2] = {has_energy[0], has_energy[1]};
    // e = x_j − x_i and d = Rᵀ e (E8) once per (frame, edge); the pair weights w̃ at the earlier
    // frame (E7): C-ARAP's with the confidences, ARAP's with c = 1 and α = 1.
    for (Index e = 0; e < m_e; ++e) {
      const Index j = nbr[static_cast<std::size_t>(e)], o = e * ne;
      carap_loops::edge_frames(ne, R, Xi, Xb + j * n4, Ex + o, Ey + o, Ez + o, Dx + o, Dy + o,
                               Dz + o);
      const S w = wgt[static_cast<std::size_t>(e)];
      const S* cj = Xb + j * n4 + 3 * ne;
      if (has[0])
        for (Index l = 0; l < ne; ++l)
          Wb[0][o + l] = l < nown ? confidence_edge_weight(w, alp_c, cj[l]) : S(0);
      if (has[1])
        for (Index l = 0; l < ne; ++l)
          Wb[1][o + l] = l < nown ? confidence_edge_weight(w, L(1), S(1)) : S(0);
    }
    carap_loops::lengths(m, Ex, Ey, Ez, Len, InvLen, Eacc[0]);
    if (has[1]) std::fill(Eacc[1], Eacc[1] + m, S(0));

    // Pair terms (E9) of every gap of both energies on the same d, and their d-gradients.
    Index n_active = 0;
    for (Index g = 0; g < plan.n_gaps; ++g) {
      const Index d = gaps[static_cast<std::size_t>(g)].delta;
      if (d >= nr) continue;  // no pair of this gap inside the block
      const Index n = m - d;
      const int en = gaps[static_cast<std::size_t>(g)].energy;
      const S* mk = masks + g * M;
      const L lc = en == 0 ? lc_c : lc_a, ll = en == 0 ? ll_c : ll_a;
      if (!grad) {
        carap_loops::pair_energy(n, d, mk, Wb[en], Dx, Dy, Dz, Len, lc, ll, Eacc[en]);
        continue;
      }
      carap_loops::pair_gradient(n, d, mk, Wb[en], Dx, Dy, Dz, Len, lc, ll, Eacc[en], P(g, 0),
                                 P(g, 1), P(g, 2), P(g, 3));
      for (int c = 0; c < 4; ++c) std::fill(P(g, c) + n, P(g, c) + m, S(0));
      active[static_cast<std::size_t>(n_active++)] = g;
    }
    if (has[0]) energy.carap += Acc(sum_array(Eacc[0], m));
    if (has[1]) energy.arap += Acc(sum_array(Eacc[1], m));
    if (!grad) return;
    // ∂/∂d^s = Σ_δ (P_δ(s − δ) − P_δ(s)) over every active gap of both energies, up to three
    // per pass as carap() does.
    S* Gc[4] = {Gx, Gy, Gz, H};
    auto d_of = [&](Index k) { return gaps[static_cast<std::size_t>(active[k])].delta; };
    for (int c = 0; c < 4; ++c) {
      Index k = 0;
      if (n_active == 0) {
        std::fill(Gc[c], Gc[c] + m, S(0));
      } else if (n_active == 1) {
        carap_loops::gather_pairs(m, Gc[c], P(active[0], c), d_of(0));
        k = 1;
      } else if (n_active == 2) {
        carap_loops::gather_pairs(m, Gc[c], P(active[0], c), d_of(0), P(active[1], c), d_of(1));
        k = 2;
      } else {
        carap_loops::gather_pairs(m, Gc[c], P(active[0], c), d_of(0), P(active[1], c), d_of(1),
                                  P(active[2], c), d_of(2));
        k = 3;
      }
      for (; k < n_active; ++k) carap_loops::gather_pairs_add(m, Gc[c], P(active[k], c), d_of(k));
    }
    // Back to the variables (E10), once for both energies.
    for (Index l = 0; l < 3 * ne; ++l) Fi[l] = Ri[l] = S(0);
    for (Index e = 0; e < m_e; ++e) {
      const Index o = e * ne;
      carap_loops::backprop(ne, R, Gx + o, Gy + o, Gz + o, H + o, InvLen + o, Ex + o, Ey + o,
                            Ez + o, Dx + o, Dy + o, Dz + o, Fi, Ri);
      if (want_x)
        carap_loops::add3(ne, GBx + nbr[static_cast<std::size_t>(e)] * n3, Gx + o, Gy + o,
                          Gz + o);
    }
    if (want_x) carap_loops::sub(n3, GBx + i * n3, Fi);
    // The rotation gradient of node i reaches only node i's rows: owned frames straight into
    // the caller's rows (no other block writes them), the overlap into the spill.
    if (want_r)
      for (Index l = 0; l < nr; ++l) {
        if (l < nown) {
          add_rotation(t0 + l, i, Ri + l, ne);
        } else {
          S* dst = spill_r(b) + (l - nown) * N * 3 + 3 * i;
          dst[0] = Ri[l];
          dst[1] = Ri[ne + l];
          dst[2] = Ri[2 * ne + l];
        }
      }
  }

  // LRM (E11)-(E16) of node i at the nl (<= W) frames t0 + l0 … of one lane group, from the
  // gathered records; ∂L/∂x and ∂L/∂u (scaled) added to the block's position gradient. Returns
  // the unscaled energy (lrm() scales the sum at the end).
  Acc lrm_group(Index i, Index t0, Index l0, Index nl, Index ne, const S* Xb, S* GBx,
                V* lanes) const {
    const Index K = plan.K, T = plan.T, W = plan.W, n4 = 4 * ne, n3 = 3 * ne;
    V* xs = lanes;
    V* us = xs + 3 * K;
    V* a = us + 3 * K;
    V* gxl = a + K;
    V* gul = gxl + 3 * K;
    V* om = gul + 3 * K;
    V* nb_scratch = om + 3;
    V valid;  // 1 for the group's frames, 0 for padding lanes
    for (Index l = 0; l < W; ++l) lane_ref<V, S>(valid, l) = l < nl ? S(1) : S(0);
    const I* idx = graph.indices.ptr(i);
    const S* wrow = graph.weights.ptr(i);
    // The lane of frame T − 1 (if in this group): its velocity is the backward difference (E1).
    const Index last = (T >= 2 && t0 + l0 + nl == T) ? nl - 1 : -1;
    for (Index k = 0; k < K; ++k) {
      const Index j = idx[k] >= 0 ? idx[k] : i;  // padding: own record, weight 0
      const S* rec = Xb + j * n4 + l0;
      for (int c = 0; c < 3; ++c) {
        V xn;
        lane_load(xs[c * K + k], rec + c * ne);
        lane_load(xn, rec + c * ne + 1);
        us[c * K + k] = xn - xs[c * K + k];  // u^t = x^{t+1} − x^t (E1)
        if (T < 2) us[c * K + k] = lane_constant<V>(L(0));
      }
      if (last >= 0) {
        const Vector3<S> u = velocity(x, t0 + l0 + last, j);
        for (int c = 0; c < 3; ++c) lane_ref<V, S>(us[c * K + k], last) = u(c);
      }
      V cj;
      lane_load(cj, rec + 3 * ne);
      const S wk = idx[k] >= 0 ? wrow[k] : S(0);
      a[k] = confidence_edge_weight(V(wk * valid), alpha_l, cj);
    }
    V ev = lrm_neighborhood<V, S>(K, xs, us, a, lrm_p, nb_scratch, gxl, gul, om);
    Acc e(0);
    for (Index l = 0; l < nl; ++l) e += Acc(lane_ref<V, S>(ev, l));
    // With one frame u ≡ 0 is a constant (E1): no velocity term reaches the positions.
    if (!lrm_p.gradient) return e;
    const bool moving = T >= 2;
    const L s_scale = scale_l;
    for (Index k = 0; k < K; ++k) {
      const Index j = idx[k];
      if (j < 0) break;
      S* rec = GBx + j * n3 + l0;
      for (int c = 0; c < 3; ++c) {
        V gxs = s_scale * gxl[c * K + k], gus = s_scale * gul[c * K + k];
        S* dst = rec + c * ne;
        for (Index l = 0; l < nl; ++l) {
          const S vx = lane_ref<V, S>(gxs, l), vu = lane_ref<V, S>(gus, l);
          dst[l] += vx;
          if (!moving) continue;
          if (l == last) {
            // u^{T−1} = x^{T−1} − x^{T−2}: x^{T−2} is the previous frame, or the previous
            // block's (then through `tail`, added after the spills).
            dst[l] += vu;
            if (l0 + l >= 1)
              dst[l - 1] -= vu;
            else
              tail[3 * j + c] -= vu;
          } else {
            dst[l + 1] += vu;
            dst[l] -= vu;
          }
        }
      }
    }
    return e;
  }
};

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace detail

inline namespace SMG_ISA_NAMESPACE {

// The extra bytes regularizers() allocates for these shapes, options, outputs and thread count
// (the workspace it fills; see the header comment), and the input bytes it keeps under.
template <class S, class I>
std::size_t regularizers_extra_bytes(Index frames, Index nodes, Index k,
                                     const RegularizerOptions& options, bool grad_positions,
                                     bool grad_rotations, bool rotations_given,
                                     bool visibility_given, ParallelOptions parallel = {}) {
  double sc = 0, sa = 0, sl = 0;
  const Index threads = parallel.threads > 0 ? parallel.threads : num_threads();
  // Edges are counted for Normalization::mean only; the sizes do not depend on them.
  detail::RegularizerPlan p = detail::regularizer_plan<S, I>(
      frames, nodes, k, options, grad_positions, grad_rotations, threads, nullptr, &sc, &sa, &sl,
      nodes * k);
  if (p.T == 0 || p.N == 0) return 0;
  detail::fit_slots<S, I>(p, rotations_given, visibility_given);
  return sizeof(S) * static_cast<std::size_t>(p.total_scalars());
}

// The fused regulariser step: any subset of confidences (E6), C-ARAP (E9), ARAP and LRM (E14)
// (options.terms) in one pass over the graph; returns the energies, each equal to what
// node_confidences + carap()/arap()/lrm() give on the same inputs (to rounding: the sums are
// associated differently, see tests/energy/test_regularizers.cpp).
//   positions [T][N][3]; rotations [T][N][4] (w, x, y, z; normalised on entry), may be empty
//   without C-ARAP and ARAP; visibility [T][N] (0/1) multiplies the confidences (E6), empty =
//   all visible; confidence (output [T][N]) receives c_{t,i} when given.
//   grad_positions [T][N][3] and grad_rotations (right tangent [T][N][3] or raw quaternion
//   [T][N][4], (Q5)) receive the gradient of carap + arap + lrm, *added* to their contents.
// Confidences are constants for the gradient (stop-gradient), as in the separate operators.
// Bit-identical for any thread count. Precondition: validate_regularizers.
template <class S, class I>
RegularizerResult<S> regularizers(
    detail::NonDeducedT<PositionsView<const S>> positions,
    detail::NonDeducedT<QuaternionsView<const S>> rotations,
    VisibilityView<const std::uint8_t> visibility, const NeighborsView<S, I>& graph,
    const RegularizerOptions& options, FrameScalarsView<S> confidence = {},
    PositionsView<S> grad_positions = {},
    detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
    EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  static_assert(std::is_floating_point_v<S>, "regularizers: float or double");
  using L = Literal<S>;
  using Acc = Accumulator<S>;
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  SMG_ASSERT(!(options.terms.carap || options.terms.arap) || (rotations.frames() == T && rotations.nodes() == N),
             "regularizers: rotations shape");
  SMG_ASSERT(graph.nodes() == N && graph.weights.rows() == N && graph.weights.cols() == K,
             "regularizers: graph shape");
  SMG_ASSERT(visibility.data() == nullptr || (visibility.frames() == T && visibility.nodes() == N),
             "regularizers: visibility shape");
  SMG_ASSERT(confidence.data() == nullptr || (confidence.frames() == T && confidence.nodes() == N),
             "regularizers: confidence shape");
  SMG_ASSERT(grad_positions.data() == nullptr ||
                 (grad_positions.frames() == T && grad_positions.nodes() == N),
             "regularizers: grad_positions shape");
  SMG_ASSERT(grad_rotations.empty() ||
                 (grad_rotations.frames() == T && grad_rotations.nodes() == N),
             "regularizers: grad_rotations shape");
  RegularizerResult<S> result;
  if (T == 0 || N == 0) return result;

  detail::RegularizerKernel<S, I> k;
  double sc = 0, sa = 0, sl = 0;
  const Index threads = parallel.threads > 0 ? parallel.threads : num_threads();
  k.plan = detail::regularizer_plan<S, I>(T, N, K, options, grad_positions.data() != nullptr,
                                          !grad_rotations.empty(), threads, &k.gaps, &sc, &sa,
                                          &sl, edge_count(graph));
  detail::fit_slots<S, I>(k.plan, rotations.data() != nullptr, visibility.data() != nullptr);
  const detail::RegularizerPlan& p = k.plan;
  for (const detail::RigidGap<S>& g : k.gaps) k.has_energy[g.energy] = true;
  if (!p.rigid && !p.lrm && !p.confidence) return result;
  k.x = positions;
  k.q = rotations;
  k.vis = visibility;
  k.graph = graph;
  k.conf_out = confidence;
  k.gx = p.want_x ? grad_positions : PositionsView<S>();
  if (p.want_r) {
    k.gr = grad_rotations.tangent();
    k.grq = grad_rotations.raw();
  }
  k.alpha_c = L(options.carap.alpha);
  k.lambda_c_c = L(options.carap.lambda_c);
  k.lambda_l_c = L(options.carap.lambda_l);
  k.lambda_c_a = L(options.arap.lambda_c);
  k.lambda_l_a = L(options.arap.lambda_l);
  k.alpha_l = L(options.lrm.alpha);
  k.scale_l = L(sl);
  k.lrm_p = detail::lrm_params<S>(options.lrm, p.want_x);
  k.conf_p = ConfidenceConstants<S>(options.confidence);

  detail::WorkspaceRef<S> ws(workspace);
  if (p.confidence) {
    S* iw = ws->velocity(static_cast<std::size_t>(N));
    for (Index i = 0; i < N; ++i) iw[i] = inverse_row_weight(graph, i);
    k.inv_w = iw;
  }
  k.scratch_per_slot = p.slot_scalars();
  // The slots' base on a 64-byte boundary (see RegularizerPlan::chunk; its kAlign slack covers
  // the workspace's).
  k.scratch = ws->scratch_aligned(static_cast<std::size_t>(p.slots * k.scratch_per_slot));
  if (p.spill_scalars() > 0) {
    k.spill = ws->spill(static_cast<std::size_t>(p.spill_scalars()));
    if (p.want_x && p.lrm) {
      k.tail = k.spill + p.spill_scalars() - 3 * N;
      std::fill(k.tail, k.tail + 3 * N, S(0));
    }
  }

  using Energies = typename detail::RegularizerKernel<S, I>::Energies;
  std::vector<Energies> partial(static_cast<std::size_t>(p.blocks));
  detail::SlotPool pool(p.slots);
  ParallelOptions po = parallel;
  po.grain = 1;
  po.threads = static_cast<int>(p.slots);
  parallel_for_chunks(
      p.blocks,
      [&](Index b, Index, Index) {
        const Index slot = pool.acquire();
        struct Release {
          detail::SlotPool& pl;
          Index s;
          ~Release() { pl.release(s); }
        } release{pool, slot};
        partial[static_cast<std::size_t>(b)] = k.block(b, slot);
      },
      po);
  for (const Energies& e : partial) {
    result.carap += e.carap;
    result.arap += e.arap;
    result.lrm += e.lrm;
  }
  result.lrm *= Acc(sl);

  if (p.want_x || p.want_r) {
    // Spills into the frames past each block, in block order (deterministic); LRM's last-frame
    // term on frame T − 2 after them.
    parallel_for(
        T,
        [&](Index begin, Index end) {
          for (Index s = begin; s < end; ++s) {
            for (Index b = 0; b < p.blocks; ++b) {
              const Index t1 = std::min(T, b * p.B + p.B);
              const Index te = std::min(T, t1 + p.G);
              if (s < t1 || s >= te) continue;
              if (p.want_x) {
                const S* src = k.spill_x(b) + (s - t1) * N * 3;
                S* dst = grad_positions.ptr(s, 0);
                for (Index c = 0; c < 3 * N; ++c) dst[c] += src[c];
              }
              if (p.want_r) {
                const S* src = k.spill_r(b) + (s - t1) * N * 3;
                for (Index j = 0; j < N; ++j) k.add_rotation(s, j, src + 3 * j, 1);
              }
            }
            if (k.tail && s == T - 2) {
              S* dst = grad_positions.ptr(s, 0);
              for (Index c = 0; c < 3 * N; ++c) dst[c] += k.tail[c];
            }
          }
        },
        parallel);
  }
  return result;
}

}  // inline namespace SMG_ISA_NAMESPACE

}  // namespace smg
