// smg/energy/terms/rigid.hpp — C-ARAP (E7)-(E10) and plain ARAP ((E9) with c ≡ 1, α = 1), each
// under its penalty, stop-gradient and frame (E24), as one term of the regulariser driver (energy/block.hpp has the concept). One term for both because
// they share the expensive part: d_ij^t = R_i^tᵀ (x_j^t − x_i^t) (E8) is computed once per
// (frame, edge) and reused by every gap of both energies, and their d-gradients are summed
// before one back-propagation (E10). The per-element maths is elements/carap.hpp's; the vectorised
// loops over a node's [edge][frame] arrays are below (carap_loops, also used by carap()).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <type_traits>
#include <vector>

#include "smg/core/quaternion.hpp"
#include "smg/core/scalar.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/elements/carap.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/options.hpp"

namespace smg {
namespace detail {

// The loops of the C-ARAP kernel, each over non-overlapping arrays (restrict: with more than
// a few arrays GCC otherwise gives up on run-time alias checks and does not vectorise).
namespace carap_loops {

// e = x_j − x_i and d = Rᵀ e over n frames; xj and xi are [3][n], R is [9][n] (row-major
// 3x3 per frame).
template <class S>
inline void edge_frames(Index n, const S* SMG_RESTRICT R, const S* SMG_RESTRICT xi,
                        const S* SMG_RESTRICT xj, S* SMG_RESTRICT ex, S* SMG_RESTRICT ey,
                        S* SMG_RESTRICT ez, S* SMG_RESTRICT dx, S* SMG_RESTRICT dy,
                        S* SMG_RESTRICT dz) {
  for (Index l = 0; l < n; ++l) {
    const S a = xj[l] - xi[l], b = xj[n + l] - xi[n + l], c = xj[2 * n + l] - xi[2 * n + l];
    ex[l] = a;
    ey[l] = b;
    ez[l] = c;
    const S Rl[9] = {R[0 * n + l], R[1 * n + l], R[2 * n + l], R[3 * n + l], R[4 * n + l],
                     R[5 * n + l], R[6 * n + l], R[7 * n + l], R[8 * n + l]};
    carap_edge_vector(Rl, a, b, c, dx[l], dy[l], dz[l]);
  }
}

// d = Rᵀ e over the n lanes of a short window (RigidTerm::node's frame-major layout, e given):
// row c of lane a's rotation at R[c·rs + a·LS]: LS = 1 one rotation per lane (R [9][rs]), LS = 0
// one rotation R [9] for all n (a frame's run of edges in the row frame; rs = 1). LS is a template
// argument so that the loop is vectorised with R broadcast or loaded per lane.
template <Index LS, class S>
inline void rotate_lanes(Index n, Index rs, const S* SMG_RESTRICT R, const S* SMG_RESTRICT ex,
                         const S* SMG_RESTRICT ey, const S* SMG_RESTRICT ez, S* SMG_RESTRICT dx,
                         S* SMG_RESTRICT dy, S* SMG_RESTRICT dz) {
  for (Index a = 0; a < n; ++a) {
    const S Ra[9] = {R[0 * rs + a * LS], R[1 * rs + a * LS], R[2 * rs + a * LS],
                     R[3 * rs + a * LS], R[4 * rs + a * LS], R[5 * rs + a * LS],
                     R[6 * rs + a * LS], R[7 * rs + a * LS], R[8 * rs + a * LS]};
    carap_edge_vector(Ra, ex[a], ey[a], ez[a], dx[a], dy[a], dz[a]);
  }
}

// dst[k] += a[k] for three consecutive [n] rows (a [3][n] block into a node's [3][n] block).
template <class S>
inline void add3(Index n, S* SMG_RESTRICT dst, const S* SMG_RESTRICT ax,
                 const S* SMG_RESTRICT ay, const S* SMG_RESTRICT az) {
  for (Index l = 0; l < n; ++l) {
    dst[l] += ax[l];
    dst[n + l] += ay[l];
    dst[2 * n + l] += az[l];
  }
}
template <class S>
inline void add(Index n, S* SMG_RESTRICT dst, const S* SMG_RESTRICT a) {
  for (Index l = 0; l < n; ++l) dst[l] += a[l];
}
template <class S>
inline void sub(Index n, S* SMG_RESTRICT dst, const S* SMG_RESTRICT a) {
  for (Index l = 0; l < n; ++l) dst[l] -= a[l];
}

// ‖e‖, 1/‖e‖ (0 at e = 0: the derivative of ‖d‖ at d = 0 is taken as 0, pinned), and clears
// the energy accumulator.
template <class S>
inline void lengths(Index n, const S* SMG_RESTRICT ex, const S* SMG_RESTRICT ey,
                    const S* SMG_RESTRICT ez, S* SMG_RESTRICT len, S* SMG_RESTRICT inv_len,
                    S* SMG_RESTRICT eacc) {
  using L = Literal<S>;
  for (Index a = 0; a < n; ++a) inv_len[a] = ex[a] * ex[a] + ey[a] * ey[a] + ez[a] * ez[a];
  sqrt_array(inv_len, len, n);
  for (Index a = 0; a < n; ++a) {
    // Divide by a safe value, then select: a division under the condition would not be
    // vectorised (it could trap on 0).
    const S safe = len[a] > S(0) ? len[a] : S(1);
    const S inv = L(1) / safe;
    inv_len[a] = len[a] > S(0) ? inv : S(0);
    eacc[a] = S(0);
  }
}

// Energy of the pairs (a, a + δ) of one gap (E9) under penalty P (E24), added to eacc[a]; and,
// with Grad, P = ∂/∂d^{t+δ} (= −∂/∂d^t) of the vector term, Q the same for ‖d‖ of the length
// term. P != squared: the roots of the n terms first (their arguments into ac, al, then one
// vectorised sqrt each into rc, rl: four scratch arrays of n), then the terms.
template <Penalty P, bool Grad, class S>
inline void pair_terms(Index n, Index d, const S* SMG_RESTRICT mk, const S* SMG_RESTRICT wb,
                       const S* SMG_RESTRICT dx, const S* SMG_RESTRICT dy,
                       const S* SMG_RESTRICT dz, const S* SMG_RESTRICT len, Literal<S> lam_c,
                       Literal<S> lam_l, S eps, S* SMG_RESTRICT eacc, S* SMG_RESTRICT px,
                       S* SMG_RESTRICT py, S* SMG_RESTRICT pz, S* SMG_RESTRICT q,
                       S* SMG_RESTRICT ac, S* SMG_RESTRICT al, S* SMG_RESTRICT rc,
                       S* SMG_RESTRICT rl) {
  if constexpr (P == Penalty::squared) {
    for (Index a = 0; a < n; ++a) {
      const S ax = dx[a + d] - dx[a], ay = dy[a + d] - dy[a], az = dz[a + d] - dz[a];
      const S dl = len[a + d] - len[a];
      const S c = mk[a] * wb[a];
      if constexpr (Grad)
        eacc[a] += carap_term(c, ax, ay, az, dl, lam_c, lam_l, px[a], py[a], pz[a], q[a]);
      else
        eacc[a] += carap_term_energy(c, ax, ay, az, dl, lam_c, lam_l);
    }
  } else {
    for (Index a = 0; a < n; ++a)
      carap_penalty_root_args(P, wb[a], eps, S(dx[a + d] - dx[a]), S(dy[a + d] - dy[a]),
                              S(dz[a + d] - dz[a]), S(len[a + d] - len[a]), ac[a], al[a]);
    sqrt_array(ac, rc, n);
    if constexpr (P == Penalty::sqrt_weighted) sqrt_array(al, rl, n);
    for (Index a = 0; a < n; ++a) {
      const S ax = dx[a + d] - dx[a], ay = dy[a + d] - dy[a], az = dz[a + d] - dz[a];
      const S dl = len[a + d] - len[a];
      S qx, qy, qz, qq;
      const S r_l = P == Penalty::sqrt_weighted ? rl[a] : S(0);  // norm reads none (nor fills rl)
      eacc[a] += carap_term_penalty_roots(P, mk[a], wb[a], ax, ay, az, dl, rc[a], r_l, lam_c,
                                          lam_l, qx, qy, qz, qq);
      if constexpr (Grad) {
        px[a] = qx;
        py[a] = qy;
        pz[a] = qz;
        q[a] = qq;
      }
    }
  }
}

// G[a] = Σ_g (P_g[a − δ_g] − P_g[a]) for one component and up to three gaps in one pass:
// ∂/∂d^s collects +P from the pair (s − δ, s) and −P from the pair (s, s + δ) (E10). Each P_g
// is preceded by max(δ) zeros, so a − δ_g < 0 reads 0.
template <class S>
inline void gather_pairs(Index m, S* SMG_RESTRICT G, const S* SMG_RESTRICT p0, Index d0) {
  for (Index a = 0; a < m; ++a) G[a] = p0[a - d0] - p0[a];
}
template <class S>
inline void gather_pairs(Index m, S* SMG_RESTRICT G, const S* SMG_RESTRICT p0, Index d0,
                         const S* SMG_RESTRICT p1, Index d1) {
  for (Index a = 0; a < m; ++a) G[a] = (p0[a - d0] - p0[a]) + (p1[a - d1] - p1[a]);
}
template <class S>
inline void gather_pairs(Index m, S* SMG_RESTRICT G, const S* SMG_RESTRICT p0, Index d0,
                         const S* SMG_RESTRICT p1, Index d1, const S* SMG_RESTRICT p2, Index d2) {
  for (Index a = 0; a < m; ++a)
    G[a] = (p0[a - d0] - p0[a]) + (p1[a - d1] - p1[a]) + (p2[a - d2] - p2[a]);
}
template <class S>
inline void gather_pairs_add(Index m, S* SMG_RESTRICT G, const S* SMG_RESTRICT p0, Index d0) {
  for (Index a = 0; a < m; ++a) G[a] += p0[a - d0] - p0[a];
}

// One edge over n frames: F = R G + (H/‖e‖) e (world-frame gradient of x_j) overwrites G;
// fi += F and ri += G × d (right-tangent gradient of R_i), both [3][n].
template <class S>
inline void backprop(Index n, const S* SMG_RESTRICT R, S* SMG_RESTRICT gx, S* SMG_RESTRICT gy,
                     S* SMG_RESTRICT gz, const S* SMG_RESTRICT h, const S* SMG_RESTRICT il,
                     const S* SMG_RESTRICT ex, const S* SMG_RESTRICT ey,
                     const S* SMG_RESTRICT ez, const S* SMG_RESTRICT dx,
                     const S* SMG_RESTRICT dy, const S* SMG_RESTRICT dz, S* SMG_RESTRICT fi,
                     S* SMG_RESTRICT ri) {
  for (Index l = 0; l < n; ++l) {
    const S Rl[9] = {R[0 * n + l], R[1 * n + l], R[2 * n + l], R[3 * n + l], R[4 * n + l],
                     R[5 * n + l], R[6 * n + l], R[7 * n + l], R[8 * n + l]};
    S fx, fy, fz, rx, ry, rz;
    carap_edge_backprop(Rl, gx[l], gy[l], gz[l], h[l], il[l], ex[l], ey[l], ez[l], dx[l], dy[l],
                        dz[l], fx, fy, fz, rx, ry, rz);
    ri[l] += rx;
    ri[n + l] += ry;
    ri[2 * n + l] += rz;
    gx[l] = fx;
    gy[l] = fy;
    gz[l] = fz;
    fi[l] += fx;
    fi[n + l] += fy;
    fi[2 * n + l] += fz;
  }
}

// backprop over the n lanes of a short window, R, rs and LS as rotate_lanes: F overwrites G, each
// lane's G × d goes to its own rx, ry, rz (the sums over edges are the caller's, in edge order, as
// backprop's).
template <Index LS, class S>
inline void backprop_lanes(Index n, Index rs, const S* SMG_RESTRICT R, S* SMG_RESTRICT gx,
                           S* SMG_RESTRICT gy, S* SMG_RESTRICT gz, const S* SMG_RESTRICT h,
                           const S* SMG_RESTRICT il, const S* SMG_RESTRICT ex,
                           const S* SMG_RESTRICT ey, const S* SMG_RESTRICT ez,
                           const S* SMG_RESTRICT dx, const S* SMG_RESTRICT dy,
                           const S* SMG_RESTRICT dz, S* SMG_RESTRICT rx, S* SMG_RESTRICT ry,
                           S* SMG_RESTRICT rz) {
  for (Index a = 0; a < n; ++a) {
    const S Ra[9] = {R[0 * rs + a * LS], R[1 * rs + a * LS], R[2 * rs + a * LS],
                     R[3 * rs + a * LS], R[4 * rs + a * LS], R[5 * rs + a * LS],
                     R[6 * rs + a * LS], R[7 * rs + a * LS], R[8 * rs + a * LS]};
    S fx, fy, fz;
    carap_edge_backprop(Ra, gx[a], gy[a], gz[a], h[a], il[a], ex[a], ey[a], ez[a], dx[a], dy[a],
                        dz[a], fx, fy, fz, rx[a], ry[a], rz[a]);
    gx[a] = fx;
    gy[a] = fy;
    gz[a] = fz;
  }
}

}  // namespace carap_loops
// One gap of C-ARAP or ARAP: its δ, γ_δ times the energy's scale, and which energy (0: C-ARAP,
// 1: ARAP) it belongs to.
template <class S>
struct RigidGap {
  Index delta = 1;
  Literal<S> gamma = Literal<S>(0);
  int energy = 0;
};

template <class S, class I>
struct RigidTerm : TermDefaults {
  using L = Literal<S>;
  using Acc = Accumulator<S>;

  std::vector<RigidGap<S>> gaps;  // active gaps of both energies (1 <= δ < T, γ != 0)
  bool has_energy[2] = {false, false};
  L alpha_c = L(0), lambda_c_c = L(0), lambda_l_c = L(0);
  L lambda_c_a = L(0), lambda_l_a = L(0);
  Penalty penalty[2] = {Penalty::squared, Penalty::squared};  // per energy (E24)
  S eps[2] = {S(0), S(0)};                                    // penalty_eps per energy
  StopGradient stop = StopGradient::none;  // one for both (validate_options(RegularizerOptions))
  RigidFrame frame = RigidFrame::row;      // one for both, as stop
  bool keep_zero = false;  // sqrt_weighted: a zero-weight edge still adds m λ sqrt(ε)
  Index max_delta = 0;
  bool want_rotations = false;  // the caller wants the rotation gradient

  // The gaps of C-ARAP (carap) and ARAP (arap), each with its overall scale as carap()/arap()
  // compute it (the sum, or the mean over Σ_δ max(0, T − δ) · edges terms).
  void configure(const CarapOptions* carap, const ArapOptions* arap, Index T, Index edges) {
    auto add = [&](const GapList& list, double weight, Normalization n, int energy) {
      Index pairs = 0;
      for (const Gap& g : list) pairs += std::max<Index>(0, T - g.delta);
      double scale = weight;
      if (n == Normalization::mean) {
        // No terms, or a zero weight: nothing (and no reach that would change the partition).
        scale = pairs * edges == 0 ? 0.0 : weight / static_cast<double>(pairs * edges);
        if (scale == 0.0) return;
      }
      for (const Gap& g : list)
        if (g.delta >= 1 && g.delta < T && g.weight != 0.0) {
          gaps.push_back({g.delta, L(g.weight * scale), energy});
          max_delta = std::max<Index>(max_delta, g.delta);
          has_energy[energy] = true;
        }
    };
    auto penalties = [&](const auto& o, int energy) {
      penalty[energy] = o.penalty;
      eps[energy] = S(o.penalty_eps);
      stop = o.stop_gradient;
      frame = o.frame;
      keep_zero = keep_zero || (has_energy[energy] && o.penalty == Penalty::sqrt_weighted);
    };
    if (carap) {
      add(carap->gaps, carap->weight, carap->normalization, 0);
      alpha_c = L(carap->alpha);
      lambda_c_c = L(carap->lambda_c);
      lambda_l_c = L(carap->lambda_l);
      penalties(*carap, 0);
    }
    if (arap) {
      add(arap->gaps, arap->weight, arap->normalization, 1);
      lambda_c_a = L(arap->lambda_c);
      lambda_l_a = L(arap->lambda_l);
      penalties(*arap, 1);
    }
  }

  // The list's entries "carap" and "arap" (one term: both read d, (E8)); nothing without a graph.
  template <class RO>
  void setup(const RO& o, const TermShape& s) {
    if (s.K > 0)
      configure(o.terms.carap ? &o.carap : nullptr, o.terms.arap ? &o.arap : nullptr, s.T, s.edges);
    want_rotations = s.want_r;
  }

  bool on() const { return !gaps.empty(); }
  Index reach() const { return max_delta; }
  bool reads_rotations() const { return true; }
  bool rotation_gradient() const { return want_rotations; }
  Index n_gaps() const { return static_cast<Index>(gaps.size()); }
  // Whether a block of ne stored frames runs the short-window layout, its lanes frame-major
  // (lane l·m_e + e: frame l of the node's e-th active edge) rather than edge-major (e·ne + l). A
  // window of 1–3 frames (stored unpadded, BlockPlan::padded) would leave the per-edge loops fewer
  // lanes than one vector: scalar code, half of a two-frame rigid pass (perf, D3DGS's size). Every
  // lane's arithmetic is the same in both layouts and the gradient's sums over edges keep their
  // order (in double bitwise the same gradients; in float Eigen's packet sqrt, rsqrt + Newton, and
  // the scalar remainder fall on other lanes); the energy's sum over lanes runs in another order.
  static bool lanes_over_edges(Index ne) { return ne < 4; }
  // 16 flattened [edge][frame] arrays, a mask and four P arrays (after max δ zeros, max δ·K in
  // the frame-major layout) per gap, the node's rotations [9][span] and gradient rows [3][span]
  // twice; with the neighbour's frame, each lane's rotation [9][M] instead of the node's.
  Index slot_scalars(const BlockPlan& p) const {
    const Index M = p.M();
    return 16 * BlockPlan::chunk(M) + BlockPlan::chunk(n_gaps() * M) +
           BlockPlan::chunk(n_gaps() * 4 * (M + p.G * p.K)) +
           BlockPlan::chunk(frame == RigidFrame::neighbor ? 9 * M : 9 * p.span) +
           2 * BlockPlan::chunk(3 * p.span);
  }
  void bind(const BlockPlan&, S*, const NeighborsView<S, I>&) {}

  struct Block {
    S *Ex, *Ey, *Ez, *Dx, *Dy, *Dz, *Len, *InvLen, *Wb[2], *Eacc[2], *Gx, *Gy, *Gz, *H;
    S *masks, *pbase, *R, *Fi, *Ri;
    Index M = 0, G = 0;  // G: the zeros before each P array (max δ, or max δ·K when flat)
    bool flat = false;   // frame-major lanes: lanes_over_edges(ne)
    std::vector<Index> active, nbr;
    std::vector<S> wgt, mask_of_frame;  // flat: each gap's mask per frame, [gap][ne]
    S* P(Index g, int c) const { return pbase + (g * 4 + c) * (M + G) + G; }
  };

  Block begin(BlockView<S, I>& v, S* slot) const {
    const BlockPlan& p = *v.plan;
    Block k;
    k.M = p.M();
    k.flat = lanes_over_edges(v.ne);
    k.G = k.flat ? p.G * p.K : p.G;
    SlotCursor<S> cur{slot};
    const Index M = k.M;
    k.Ex = cur.take(M), k.Ey = cur.take(M), k.Ez = cur.take(M);
    k.Dx = cur.take(M), k.Dy = cur.take(M), k.Dz = cur.take(M);
    k.Len = cur.take(M), k.InvLen = cur.take(M), k.Wb[0] = cur.take(M), k.Wb[1] = cur.take(M);
    k.Eacc[0] = cur.take(M), k.Eacc[1] = cur.take(M);
    k.Gx = cur.take(M), k.Gy = cur.take(M), k.Gz = cur.take(M), k.H = cur.take(M);
    k.masks = cur.take(n_gaps() * M);
    k.pbase = cur.take(n_gaps() * 4 * (M + p.G * p.K));
    k.R = cur.take(frame == RigidFrame::neighbor ? 9 * M : 9 * p.span);
    k.Fi = cur.take(3 * p.span), k.Ri = cur.take(3 * p.span);
    if (v.grad()) std::fill(k.pbase, k.pbase + n_gaps() * 4 * (M + k.G), S(0));
    k.mask_of_frame.assign(static_cast<std::size_t>(n_gaps() * v.ne), S(0));
    // γ_δ where the pair's earlier frame is owned and its later frame exists, else 0.
    for (Index g = 0; g < n_gaps(); ++g) {
      const RigidGap<S>& gap = gaps[static_cast<std::size_t>(g)];
      const Index n_d = std::max<Index>(0, std::min(v.t1, p.T - gap.delta) - v.t0);
      S* mk = k.masks + g * M;
      for (Index e = 0; e < p.K; ++e)
        for (Index l = 0; l < v.ne; ++l) mk[e * v.ne + l] = l < n_d ? S(gap.gamma) : S(0);
      for (Index l = 0; l < v.ne; ++l)
        k.mask_of_frame[static_cast<std::size_t>(g * v.ne + l)] = l < n_d ? S(gap.gamma) : S(0);
    }
    k.active.resize(gaps.size());
    k.nbr.resize(static_cast<std::size_t>(p.K));
    k.wgt.resize(static_cast<std::size_t>(p.K));
    return k;
  }

  // C-ARAP and ARAP of node i over the block (E7)-(E10): both weight sets on one set of rotated
  // edge vectors.
  template <class E>
  void node(const BlockView<S, I>& v, Block& k, Index i, E& energy) const {
    const BlockPlan& plan = *v.plan;
    const Index K = plan.K, ne = v.ne, nr = v.nr, nown = v.nown, t0 = v.t0;
    const Index n4 = v.n4(), n3 = v.n3();
    const bool grad = v.grad(), want_x = v.want_x, want_r = v.want_r;
    // Members copied to locals: loads through `this` inside the loops would block
    // vectorisation (they may alias the scratch arrays).
    const L alp_c = alpha_c, lc_c = lambda_c_c, ll_c = lambda_l_c, lc_a = lambda_c_a,
            ll_a = lambda_l_a;
    S *Ex = k.Ex, *Ey = k.Ey, *Ez = k.Ez, *Dx = k.Dx, *Dy = k.Dy, *Dz = k.Dz;
    S *Len = k.Len, *InvLen = k.InvLen, *Gx = k.Gx, *Gy = k.Gy, *Gz = k.Gz, *H = k.H;
    S *R = k.R, *Fi = k.Fi, *Ri = k.Ri;
    S* const* Wb = k.Wb;
    S* const* Eacc = k.Eacc;
    const S* Xb = v.Xb;
    S* GBx = v.GBx;
    // Active edges: positive weight (a zero weight contributes exactly nothing, except
    // sqrt_weighted's m λ sqrt(ε), E24).
    Index m_e = 0;
    const bool zero_ok = keep_zero;
    for (Index kk = 0; kk < K; ++kk) {
      const Index j = v.graph.indices(i, kk);
      if (j < 0) break;
      const S w = v.graph.weights(i, kk);
      if (!(w > S(0)) && !(zero_ok && w == S(0))) continue;
      k.nbr[static_cast<std::size_t>(m_e)] = j;
      k.wgt[static_cast<std::size_t>(m_e)] = w;
      ++m_e;
    }
    if (m_e == 0) return;
    const Index m = m_e * ne;
    // The frame owners' rotations, [9][ne] each (padding frames zero): node i's once (row), or
    // each edge's neighbour's at R + 9·e·ne (neighbor).
    const bool nbr_frame = frame == RigidFrame::neighbor;
    auto rotations_of = [&](Index f, S* dst) {
      for (Index l = 0; l < ne; ++l) {
        S Rl[9] = {S(0), S(0), S(0), S(0), S(0), S(0), S(0), S(0), S(0)};
        if (l < nr) rotation_from_wxyz(v.q.ptr(t0 + l, f), Rl);
        for (int c = 0; c < 9; ++c) dst[c * ne + l] = Rl[c];
      }
    };
    // Lanes: edge-major (lane e·ne + l) or, for a short window (k.flat), frame-major (lane
    // l·m_e + e; a pair (l, l + δ) of one edge is δ·m_e lanes apart). Frame-major rotations: the
    // row frame's node i's [9][ne] (one per frame's run of lanes), the neighbour's frame's every
    // lane's at R [9][m].
    const bool flat = k.flat;
    auto lane = [&](Index e, Index l) { return flat ? l * m_e + e : e * ne + l; };
    const Index step = flat ? m_e : 1;  // lanes between frames l and l + 1 of one edge
    if (!nbr_frame) rotations_of(i, R);
    auto R_of = [&](Index e) { return nbr_frame ? R + 9 * e * ne : R; };
    const S* Xi = Xb + i * n4;
    const bool has[2] = {has_energy[0], has_energy[1]};
    // e = x_j − x_i and d = Rᵀ e (E8) once per (frame, edge); the pair weights w̃ at the earlier
    // frame (E7): C-ARAP's with the confidences, ARAP's with c = 1 and α = 1.
    for (Index e = 0; e < m_e; ++e) {
      const Index j = k.nbr[static_cast<std::size_t>(e)], o = e * ne;
      if (flat) {  // e here, d for all lanes after the loop
        const S* Xj = Xb + j * n4;
        S Rj[9 * 3];
        if (nbr_frame) rotations_of(j, Rj);
        for (Index l = 0; l < ne; ++l) {
          const Index a = l * m_e + e;
          Ex[a] = Xj[l] - Xi[l];
          Ey[a] = Xj[ne + l] - Xi[ne + l];
          Ez[a] = Xj[2 * ne + l] - Xi[2 * ne + l];
          if (nbr_frame)
            for (int c = 0; c < 9; ++c) R[c * m + a] = Rj[c * ne + l];
        }
      } else {
        if (nbr_frame) rotations_of(j, R + 9 * o);
        carap_loops::edge_frames(ne, R_of(e), Xi, Xb + j * n4, Ex + o, Ey + o, Ez + o, Dx + o,
                                 Dy + o, Dz + o);
      }
      const S w = k.wgt[static_cast<std::size_t>(e)];
      const S* cj = Xb + j * n4 + 3 * ne;
      if (has[0])
        for (Index l = 0; l < ne; ++l)
          Wb[0][lane(e, l)] = l < nown ? confidence_edge_weight(w, alp_c, cj[l]) : S(0);
      if (has[1])
        for (Index l = 0; l < ne; ++l)
          Wb[1][lane(e, l)] = l < nown ? confidence_edge_weight(w, L(1), S(1)) : S(0);
    }
    // A frame's rotation for its run of lanes (row frame), or every lane's (neighbour's frame).
    S Rl[9];
    auto frame_rotation = [&](Index l) {
      for (int c = 0; c < 9; ++c) Rl[c] = R[c * ne + l];
      return Rl;
    };
    if (flat) {
      if (nbr_frame)
        carap_loops::rotate_lanes<1>(m, m, R, Ex, Ey, Ez, Dx, Dy, Dz);
      else
        for (Index l = 0, o = 0; l < ne; ++l, o += m_e)
          carap_loops::rotate_lanes<0>(m_e, 1, frame_rotation(l), Ex + o, Ey + o, Ez + o, Dx + o,
                                    Dy + o, Dz + o);
    }
    carap_loops::lengths(m, Ex, Ey, Ez, Len, InvLen, Eacc[0]);
    if (has[1]) std::fill(Eacc[1], Eacc[1] + m, S(0));

    // Pair terms (E9) of every gap of both energies on the same d, and their d-gradients; the
    // mask zeroes pairs whose earlier frame is not this block's, whose later frame is past
    // T − 1, or that would straddle two edges.
    Index n_active = 0;
    for (Index g = 0; g < n_gaps(); ++g) {
      const Index delta = gaps[static_cast<std::size_t>(g)].delta;
      if (delta >= nr) continue;  // no pair of this gap inside the block
      const Index d = delta * step, n = m - d;
      const int en = gaps[static_cast<std::size_t>(g)].energy;
      S* mk = k.masks + g * k.M;
      if (flat)  // frame-major: each frame's run of m_e lanes has its frame's mask
        for (Index l = 0; l < ne; ++l)
          std::fill(mk + l * m_e, mk + (l + 1) * m_e,
                    k.mask_of_frame[static_cast<std::size_t>(g * ne + l)]);
      const L lc = en == 0 ? lc_c : lc_a, ll = en == 0 ? ll_c : ll_a;
      const S ep = eps[en];
      // The penalty is a template argument of the loops (one branch per gap, not per term).
      // Gx, Gy, Gz and H are free until the gather below: the roots' scratch.
      const Penalty pen = penalty[en];
      auto run = [&](auto pc, auto gc) {
        constexpr Penalty Pp = decltype(pc)::value;
        constexpr bool Gg = decltype(gc)::value;
        carap_loops::pair_terms<Pp, Gg>(n, d, mk, Wb[en], Dx, Dy, Dz, Len, lc, ll, ep, Eacc[en],
                                        k.P(g, 0), k.P(g, 1), k.P(g, 2), k.P(g, 3), Gx, Gy, Gz, H);
      };
      auto by_penalty = [&](auto gc) {
        if (pen == Penalty::norm)
          run(std::integral_constant<Penalty, Penalty::norm>{}, gc);
        else if (pen == Penalty::sqrt_weighted)
          run(std::integral_constant<Penalty, Penalty::sqrt_weighted>{}, gc);
        else
          run(std::integral_constant<Penalty, Penalty::squared>{}, gc);
      };
      if (!grad) {
        by_penalty(std::false_type{});
        continue;
      }
      by_penalty(std::true_type{});
      for (int c = 0; c < 4; ++c) std::fill(k.P(g, c) + n, k.P(g, c) + m, S(0));
      k.active[static_cast<std::size_t>(n_active++)] = g;
    }
    if (has[0]) energy.carap += Acc(sum_array(Eacc[0], m));
    if (has[1]) energy.arap += Acc(sum_array(Eacc[1], m));
    if (!grad) return;
    // ∂/∂d^s = Σ_δ (P_δ(s − δ) − P_δ(s)) over every active gap of both energies, up to three
    // per pass.
    S* Gc[4] = {Gx, Gy, Gz, H};
    auto d_of = [&](Index a) {
      return step * gaps[static_cast<std::size_t>(k.active[static_cast<std::size_t>(a)])].delta;
    };
    auto Pa = [&](Index a, int c) { return k.P(k.active[static_cast<std::size_t>(a)], c); };
    for (int c = 0; c < 4; ++c) {
      Index a = 0;
      if (n_active == 0) {
        std::fill(Gc[c], Gc[c] + m, S(0));
      } else if (n_active == 1) {
        carap_loops::gather_pairs(m, Gc[c], Pa(0, c), d_of(0));
        a = 1;
      } else if (n_active == 2) {
        carap_loops::gather_pairs(m, Gc[c], Pa(0, c), d_of(0), Pa(1, c), d_of(1));
        a = 2;
      } else {
        carap_loops::gather_pairs(m, Gc[c], Pa(0, c), d_of(0), Pa(1, c), d_of(1), Pa(2, c),
                                  d_of(2));
        a = 3;
      }
      for (; a < n_active; ++a) carap_loops::gather_pairs_add(m, Gc[c], Pa(a, c), d_of(a));
    }
    // Back to the variables (E10), once for both energies; a held endpoint (stop_gradient,
    // E24) gets no position gradient, the rotation still does.
    const bool x_nbr = want_x && stop != StopGradient::neighbor;
    const bool x_row = want_x && stop != StopGradient::row;
    // A frame owner's rotation gradient Ri [3][ne] into its rows (this block visits nodes in
    // order, so the sums do not depend on threads).
    auto rotation_rows = [&](Index f) {
      for (Index l = 0; l < nr; ++l) v.add_rotation(l, f, Ri + l, ne);
    };
    // Frame-major: F and G × d of every lane first (Wb and Len are free after the pair terms),
    // then their sums over edges in edge order, as backprop adds them.
    S *Rx = Wb[0], *Ry = Wb[1], *Rz = Len;
    if (flat) {
      if (nbr_frame)
        carap_loops::backprop_lanes<1>(m, m, R, Gx, Gy, Gz, H, InvLen, Ex, Ey, Ez, Dx, Dy, Dz, Rx,
                                    Ry, Rz);
      else
        for (Index l = 0, o = 0; l < ne; ++l, o += m_e)
          carap_loops::backprop_lanes<0>(m_e, 1, frame_rotation(l), Gx + o, Gy + o, Gz + o, H + o,
                                      InvLen + o, Ex + o, Ey + o, Ez + o, Dx + o, Dy + o, Dz + o,
                                      Rx + o, Ry + o, Rz + o);
    }
    for (Index l = 0; l < 3 * ne; ++l) Fi[l] = Ri[l] = S(0);
    if (flat && !nbr_frame)  // each frame's sums over its run of edges, in edge order (registers)
      for (Index l = 0, o = 0; l < ne; ++l, o += m_e) {
        S sx = S(0), sy = S(0), sz = S(0), tx = S(0), ty = S(0), tz = S(0);
        for (Index e = 0; e < m_e; ++e) {
          sx += Gx[o + e], sy += Gy[o + e], sz += Gz[o + e];
          tx += Rx[o + e], ty += Ry[o + e], tz += Rz[o + e];
        }
        Fi[l] = sx, Fi[ne + l] = sy, Fi[2 * ne + l] = sz;
        Ri[l] = tx, Ri[ne + l] = ty, Ri[2 * ne + l] = tz;
      }
    for (Index e = 0; e < m_e; ++e) {
      const Index o = e * ne, j = k.nbr[static_cast<std::size_t>(e)];
      if (flat) {
        S* gj = x_nbr ? GBx + j * n3 : nullptr;
        for (Index l = 0; l < ne; ++l) {
          const Index a = l * m_e + e;
          if (nbr_frame) {
            Fi[l] += Gx[a];
            Fi[ne + l] += Gy[a];
            Fi[2 * ne + l] += Gz[a];
            Ri[l] += Rx[a];
            Ri[ne + l] += Ry[a];
            Ri[2 * ne + l] += Rz[a];
          }
          if (x_nbr) {
            gj[l] += Gx[a];
            gj[ne + l] += Gy[a];
            gj[2 * ne + l] += Gz[a];
          }
        }
      } else {
        carap_loops::backprop(ne, R_of(e), Gx + o, Gy + o, Gz + o, H + o, InvLen + o, Ex + o,
                              Ey + o, Ez + o, Dx + o, Dy + o, Dz + o, Fi, Ri);
        if (x_nbr) carap_loops::add3(ne, GBx + j * n3, Gx + o, Gy + o, Gz + o);
      }
      if (nbr_frame && want_r) {  // this edge's rotation part is R_j's (E24)
        rotation_rows(j);
        for (Index l = 0; l < 3 * ne; ++l) Ri[l] = S(0);
      }
    }
    if (x_row) carap_loops::sub(n3, GBx + i * n3, Fi);
    if (want_r && !nbr_frame) rotation_rows(i);  // every edge's rotation part is R_i's
  }
};

}  // namespace detail
}  // namespace smg
