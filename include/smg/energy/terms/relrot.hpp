// smg/energy/terms/relrot.hpp — relative-rotation consistency along the graph's edges, the "rot"
// regulariser of Dynamic 3D Gaussians (train.py get_loss: quat_mult(fg_rot, prev_inv_rot_fg) of
// neighbours compared as raw 4-vectors), as a term of the regulariser driver (energy/block.hpp
// has the concept; docs/math/terms/relrot.md (E25)):
//   r_i^t = q̂_i^{t+1} ⊗ q̂_i^{t*}   (the quaternion of R_i^{t+1} R_i^{tT}, q̂ = q / ‖q‖)
//   Q = Σ_{t=0}^{T−2} Σ_i Σ_{j ∈ N(i)} P(w_ij, r_j^t − r_i^t)
// with P the penalty (E22) on the 4-vector (sqrt_weighted by default, D3DGS's; the weight inside
// the root) and factor k = the weight (divided by (T − 1) · edges with Normalization::mean).
// No sign canonicalisation: q and −q at one frame flip r, as in D3DGS. The gradient goes to the
// rotations of both ends (right tangent, or raw quaternions through (Q5)); positions get none.
// Each term is indexed by its earlier frame, which the block owns; its later frame may be in
// the block's overlap (reach 1) and reaches the caller through the rotation spill. On the CPU a
// block forms each node's r once and sums ∂E/∂r over its edges before one tangent conversion per
// (frame, node) (RelrotTerm); the GPU's element recomputes its neighbours' (RelrotElement).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "smg/core/rotation_gradient.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/penalty.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

// Relative-rotation consistency (E25, docs/math/terms/relrot.md), Dynamic 3D Gaussians' "rot"
// loss: along every edge (i, j) of the graph and every pair of consecutive frames, the relative
// rotations r^t = q̂^{t+1} ⊗ q̂^{t*} of the two nodes compared as raw 4-vectors, ‖r_j^t − r_i^t‖,
// under a penalty (E22) with the edge weight w_ij. The default is D3DGS's: sqrt(w ‖·‖² + ε).
struct RelrotOptions {
  Normalization normalization = Normalization::sum;  // mean: over (T − 1) · edges terms
  double weight = 1.0;  // overall factor (dimensionless, r is a unit quaternion's difference)
  Penalty penalty = Penalty::sqrt_weighted;  // (E22); D3DGS's weighted_l2_loss_v2
  double penalty_eps = 1e-20;  // ε of sqrt_weighted, finite and > 0; read by it only
};

template <class O, class F, detail::IfOptions<O, RelrotOptions> = 0>
void for_each_option(O& o, F&& f) {
  detail::for_each_penalty_option(o, f);
}

inline Status validate_options(const RelrotOptions& o) {
  return detail::check_penalty_options("RelrotOptions", o);
}

// Checks the inputs and outputs of relrot(): rotations [T][N][4], graph [N][K]; the gradient may
// be empty (not computed).
template <class S, class I>
Status validate_relrot(detail::NonDeducedT<QuaternionsView<const S>> rotations,
                       const NeighborsView<S, I>& graph, const RelrotOptions& options,
                       detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  return detail::validate_rotation_term<S>(rotations, validate_neighbors(graph, rotations.nodes(), "graph"),
                                           validate_options(options), grad_rotations);
}

// r = â ⊗ b̂* of (E25) from the raw quaternions b = q^t and a = q^{t+1} (w, x, y, z; nonzero
// norm), with the unit quaternions â, b̂ written out for relrot_tangent.
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE void relative_rotation(const S* qb, const S* qa, S* r, S* a,
                                                        S* b) {
  using std::sqrt;
  const S sa = S(1) / sqrt(qa[0] * qa[0] + qa[1] * qa[1] + qa[2] * qa[2] + qa[3] * qa[3]);
  const S sb = S(1) / sqrt(qb[0] * qb[0] + qb[1] * qb[1] + qb[2] * qb[2] + qb[3] * qb[3]);
  for (int c = 0; c < 4; ++c) {
    a[c] = qa[c] * sa;
    b[c] = qb[c] * sb;
  }
  // a ⊗ b* = (a_w b_w + a_v·b_v, b_w a_v − a_w b_v − a_v × b_v)
  r[0] = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
  r[1] = b[0] * a[1] - a[0] * b[1] - (a[2] * b[3] - a[3] * b[2]);
  r[2] = b[0] * a[2] - a[0] * b[2] - (a[3] * b[1] - a[1] * b[3]);
  r[3] = b[0] * a[3] - a[0] * b[3] - (a[1] * b[2] - a[2] * b[1]);
}

// The right-tangent gradient h (3 values) of the later rotation a of r = â ⊗ b̂*, given
// G = ∂E/∂r (4 values): h = ½ vec(â* ⊗ G ⊗ b̂); the earlier rotation b gets −h (E25).
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE void relrot_tangent(const S* a, const S* b, const S* G, S* h) {
  // P = G ⊗ b̂
  const S pw = G[0] * b[0] - (G[1] * b[1] + G[2] * b[2] + G[3] * b[3]);
  const S px = G[0] * b[1] + b[0] * G[1] + (G[2] * b[3] - G[3] * b[2]);
  const S py = G[0] * b[2] + b[0] * G[2] + (G[3] * b[1] - G[1] * b[3]);
  const S pz = G[0] * b[3] + b[0] * G[3] + (G[1] * b[2] - G[2] * b[1]);
  // vec(â* ⊗ P) = a_w P_v − P_w a_v − a_v × P_v
  h[0] = S(0.5) * (a[0] * px - pw * a[1] - (a[2] * pz - a[3] * py));
  h[1] = S(0.5) * (a[0] * py - pw * a[2] - (a[3] * px - a[1] * pz));
  h[2] = S(0.5) * (a[0] * pz - pw * a[3] - (a[1] * py - a[2] * px));
}

// One term of (E25) on the edge weight w and the difference d = r_j − r_i (4 values): returns
// P(w, d) (E22 with factor k) and writes G = ∂P/∂d, so ∂/∂r_j = G and ∂/∂r_i = −G.
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S relrot_pair(Penalty p, S k, S w, S eps, const S* d, S* G) {
  S h;
  const S e =
      penalty_of_square<S, L>(p, k, w, eps, d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + d[3] * d[3], h);
  for (int c = 0; c < 4; ++c) G[c] = h * d[c];
  return e;
}

// Whether an edge of weight w has a term: positive weights, and zero weights under sqrt_weighted
// (a term of k sqrt(ε) without gradient, as D3DGS's far neighbours have; the other penalties give
// exactly 0 there).
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE bool relrot_edge_on(Penalty p, S w) {
  return w > S(0) || (p == Penalty::sqrt_weighted && w == S(0));
}

// The number of terms of (E25) (Normalization::mean divides by it).
inline Index relrot_term_count(Index frames, Index edges) {
  return std::max<Index>(0, frames - 1) * edges;
}
inline double relrot_scale(const RelrotOptions& o, Index frames, Index edges) {
  return o.normalization == Normalization::mean
             ? detail::scale_over_terms(o.weight, relrot_term_count(frames, edges))
             : o.weight;
}

// (E25) as one element (frame t, node n) of the CUDA driver's element pass (cuda/driver.cuh):
// the energy of node n's out-edges at the pair (t, t + 1) into `energy`, and R_n^t's gradient
// from every term containing it (pairs t − 1 and t; out-edges and, through the in-edge lists,
// in-edges) added to grad_tangent [T][N][3] or grad_raw [T][N][4] (either or both null).
// kReadsGraph: the driver passes the graph and its in-edges. With Normalization::mean the factor
// is k / ((T − 1) · edge count), the count read from the in-edge offsets (device memory).
// Host values: RelrotTerm::element().
template <class S>
struct RelrotElement {
  static constexpr bool kReadsRotations = true;
  static constexpr bool kReadsGraph = true;
  Literal<S> k = Literal<S>(0);
  Literal<S> eps = Literal<S>(0);
  Penalty penalty = Penalty::sqrt_weighted;
  bool mean = false;

  bool reads_confidence() const { return false; }

  template <class I>
  SMG_HOST_DEVICE void at(Index t, Index n, QuaternionsView<const S> q, const detail::ElementGraph<S, I>& eg,
                          S* grad_tangent, S* grad_raw, S& energy) const {
    const Index T = q.frames(), N = q.nodes(), K = eg.graph.k();
    if (T < 2) return;
    S f = S(k);
    if (mean) {
      if (eg.in_offsets[N] == 0) return;
      f = S(detail::scale_over_count(double(k), T - 1, &eg.in_offsets[N]));  // as relrot_scale
    }
    const S ep = S(eps);
    const bool want_r = grad_tangent != nullptr || grad_raw != nullptr;
    S g[3] = {S(0), S(0), S(0)};
    for (Index u = t - 1; u <= t; ++u) {
      if (u < 0 || u + 1 >= T) continue;
      const bool own = u == t;  // the pair whose energy this element sums
      if (!own && !want_r) continue;
      S rn[4], an[4], bn[4], G[4] = {S(0), S(0), S(0), S(0)};
      relative_rotation(q.ptr(u, n), q.ptr(u + 1, n), rn, an, bn);
      for (Index s = 0; s < K; ++s) {  // out-edges (n, j): d = r_j − r_n, ∂/∂r_n = −G
        const Index j = eg.graph.indices(n, s);
        if (j < 0) break;
        const S w = eg.graph.weights(n, s);
        if (!relrot_edge_on(penalty, w)) continue;
        S rj[4], aj[4], bj[4], d[4], Gd[4];
        relative_rotation(q.ptr(u, j), q.ptr(u + 1, j), rj, aj, bj);
        for (int c = 0; c < 4; ++c) d[c] = rj[c] - rn[c];
        const S e = relrot_pair<S, Literal<S>>(penalty, f, w, ep, d, Gd);
        if (own) energy += e;
        for (int c = 0; c < 4; ++c) G[c] -= Gd[c];
      }
      if (!want_r) continue;
      for (std::int32_t a = eg.in_offsets[n]; a < eg.in_offsets[n + 1]; ++a) {  // in-edges (m, n)
        const Index slot = static_cast<Index>(eg.in_entries[a]), m = slot / K;
        const S w = eg.graph.weights(m, slot - m * K);
        if (!relrot_edge_on(penalty, w)) continue;
        S rm[4], am[4], bm[4], d[4], Gd[4];
        relative_rotation(q.ptr(u, m), q.ptr(u + 1, m), rm, am, bm);
        for (int c = 0; c < 4; ++c) d[c] = rn[c] - rm[c];
        relrot_pair<S, Literal<S>>(penalty, f, w, ep, d, Gd);
        for (int c = 0; c < 4; ++c) G[c] += Gd[c];
      }
      S h[3];
      relrot_tangent(an, bn, G, h);
      // Frame t is the later rotation of pair t − 1 (+h) and the earlier one of pair t (−h).
      for (int c = 0; c < 3; ++c) g[c] += own ? S(-h[c]) : h[c];
    }
    if (!want_r) return;
    add_rotation_gradient(q.ptr(t, n), t * N + n, g, grad_tangent, grad_raw);
  }
};

namespace detail {

template <class S, class I>
struct RelrotTerm : TermDefaults {
  using L = Literal<S>;
  using Acc = Accumulator<S>;

  bool enabled = false, mean = false, want_rotations = false;
  Penalty penalty = Penalty::sqrt_weighted;
  double weight_d = 0, scale_d = 0, eps_d = 0;
  Index T = 0;

  // edges: the graph's valid edges (the count Normalization::mean divides by, with T − 1).
  void configure(const RelrotOptions& o, Index frames, Index edges) {
    T = frames;
    penalty = o.penalty;
    eps_d = o.penalty_eps;
    mean = o.normalization == Normalization::mean;
    weight_d = o.weight;
    scale_d = relrot_scale(o, frames, edges);
    enabled = relrot_term_count(frames, edges) > 0 && o.weight != 0.0;
  }

  // The list's entry "relrot"; nothing without a graph.
  template <class RO>
  void setup(const RO& o, const TermShape& s) {
    if (o.terms.relrot && s.K > 0) configure(o.relrot, s.T, s.edges);
    want_rotations = s.want_r;
  }

  bool on() const { return enabled; }
  Index reach() const { return 1; }
  bool reads_rotations() const { return true; }
  bool position_gradient() const { return false; }
  bool rotation_gradient() const { return want_rotations; }

  using Element = RelrotElement<S>;
  // The GPU reads the edge count on the device: with mean, k is the weight and the element
  // divides (RelrotElement::at).
  Element element() const {
    Element e;
    e.k = L(mean ? weight_d : scale_d);
    e.eps = L(eps_d);
    e.penalty = penalty;
    e.mean = mean;
    return e;
  }
  static Acc& energy_of(RegularizerResult<S>& r) { return r.relrot; }

  // Per block, for its pairs (t, t + 1) of owned t: every node's relative rotation r [pairs][N][4]
  // (formed once, where each edge formed its neighbour's again), and with a gradient G = ∂E/∂r
  // [pairs][N][4] summed over the node's edges, turned into rotation gradients once per
  // (pair, node) in end() (where each edge converted its neighbour's: a tangent product and, for
  // raw quaternions, a conversion per edge).
  static Index max_pairs(const BlockPlan& p) { return std::max<Index>(0, std::min(p.B, p.T - 1)); }
  Index slot_scalars(const BlockPlan& p) const {
    return BlockPlan::chunk(4 * p.N * max_pairs(p)) * (p.want_r ? 2 : 1);
  }
  void bind(const BlockPlan&, S*, const NeighborsView<S, I>&) {}
  struct Block {
    S* r = nullptr;  // [pairs][N][4]
    S* g = nullptr;  // [pairs][N][4], null without a rotation gradient
    Index pairs = 0;
  };
  Block begin(BlockView<S, I>& v, S* slot) const {
    Block b;
    const Index N = v.plan->N;
    b.pairs = std::max<Index>(0, std::min(v.nown, T - 1 - v.t0));
    SlotCursor<S> cur{slot};
    b.r = cur.take(4 * N * max_pairs(*v.plan));
    if (v.want_r) {
      b.g = cur.take(4 * N * max_pairs(*v.plan));
      std::fill(b.g, b.g + 4 * N * b.pairs, S(0));
    }
    for (Index l = 0; l < b.pairs; ++l)
      for (Index n = 0; n < N; ++n) {
        S a[4], bq[4];
        relative_rotation(v.q.ptr(v.t0 + l, n), v.q.ptr(v.t0 + l + 1, n), b.r + 4 * (l * N + n), a, bq);
      }
    return b;
  }

  // The terms of node i's out-edges whose earlier frame the block owns; ∂E/∂r of both ends into
  // the block's G (the node's own after its row, in a fixed order: deterministic).
  template <class E>
  void node(const BlockView<S, I>& v, Block& blk, Index i, E& energy) const {
    const Index K = v.plan->K, N = v.plan->N;
    if (blk.pairs <= 0) return;
    const S k = S(L(scale_d)), ep = S(L(eps_d));
    Acc e(0);
    for (Index l = 0; l < blk.pairs; ++l) {
      const S* r = blk.r + 4 * l * N;
      const S* ri = r + 4 * i;
      S Gi[4] = {S(0), S(0), S(0), S(0)};
      for (Index kk = 0; kk < K; ++kk) {
        const Index j = v.graph.indices(i, kk);
        if (j < 0) break;
        const S w = v.graph.weights(i, kk);
        if (!relrot_edge_on(penalty, w)) continue;
        const S* rj = r + 4 * j;
        S d[4], G[4];
        for (int c = 0; c < 4; ++c) d[c] = rj[c] - ri[c];
        e += Acc(relrot_pair<S, L>(penalty, k, w, ep, d, G));
        if (!blk.g) continue;
        S* gj = blk.g + 4 * (l * N + j);
        for (int c = 0; c < 4; ++c) {
          Gi[c] -= G[c];
          gj[c] += G[c];
        }
      }
      if (blk.g) {
        S* gi = blk.g + 4 * (l * N + i);
        for (int c = 0; c < 4; ++c) gi[c] += Gi[c];
      }
    }
    energy.relrot += e;
  }

  // After the block's nodes: each (pair, node)'s ∂E/∂r to the right tangents of its two
  // rotations (E25: +h to the later, −h to the earlier), through the block's rotation sink.
  void end(const BlockView<S, I>& v, Block& blk) const {
    if (!blk.g) return;
    const Index N = v.plan->N;
    for (Index l = 0; l < blk.pairs; ++l)
      for (Index n = 0; n < N; ++n) {
        S r[4], a[4], b[4], h[3];
        relative_rotation(v.q.ptr(v.t0 + l, n), v.q.ptr(v.t0 + l + 1, n), r, a, b);
        relrot_tangent(a, b, blk.g + 4 * (l * N + n), h);
        v.add_rotation(l + 1, n, h);
        for (S& c : h) c = -c;
        v.add_rotation(l, n, h);
      }
  }
};

}  // namespace detail
}  // namespace smg
