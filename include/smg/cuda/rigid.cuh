// smg/cuda/rigid.cuh — C-ARAP (E7)-(E10) and plain ARAP as one element (frame t, node n) of the
// CUDA regulariser driver (cuda/driver.cuh; docs/math/energy.md "The fused regulariser pass"):
// the thread evaluates each out-edge n -> j of frame t (d^t, the d^{t±δ} of every gap of both
// energies, their pair terms (E9) and one back-propagation (E10)): −F into x_n^t's gradient, the
// rotation part into R_n^t's; then each in-edge i -> n again (from the ReverseGraph, in
// increasing slot order) for its +F into x_n^t's gradient. With the neighbour's frame (E24) an
// edge's rotation part belongs to its head, so R_n^t's comes from the in-edges instead. Every
// (frame, edge) is evaluated twice, by its tail and by its head, instead of keeping the 11·T·N·K scalars of per-slot
// scratch the separate carap kernels keep: on a GPU the arithmetic is cheap and the scratch
// traffic is not. Every equation is the CPU's element functions' (elements/carap.hpp, common.hpp's
// confidence_edge_weight). Host-device: a host loop runs the same steps (the CUDA host suite).
#pragma once

#include "smg/cuda/common.cuh"

#include <algorithm>
#include <cstdint>

#include "smg/core/quaternion.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/elements/carap.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/term_list.hpp"  // RegularizerOptions
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
  Penalty penalty[2] = {Penalty::squared, Penalty::squared};  // per energy (E24)
  double eps[2] = {0.0, 0.0};                                 // penalty_eps per energy
  StopGradient stop = StopGradient::none;  // one for both (validate_options(RegularizerOptions))
  RigidFrame frame = RigidFrame::row;      // one for both, as stop
  bool keep_zero = false;  // sqrt_weighted: a zero-weight edge still adds m λ sqrt(ε)
  int n_gaps = 0;
  int delta[2 * GapList::kCapacity] = {};
  double gap_weight[2][2 * GapList::kCapacity] = {};
  Index pairs[2] = {0, 0};       // Σ_δ max(0, T − δ) over every listed gap of the energy
  bool mean[2] = {false, false};  // Normalization::mean
  const std::int32_t* edge_count = nullptr;  // Σ_i |N(i)| (device memory in kernels)

  // γ_δ · weight / (number of terms with Normalization::mean) of gap g for energy en.
  SMG_HOST_DEVICE Literal<S> gamma(int en, int g) const {
    double scale = gap_weight[en][g];
    if (mean[en]) scale = scale_over_count(scale, pairs[en], edge_count);
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

// The rotated edge vector of edge i -> j at frame s (E8): R (row-major, from q_f^s, f the frame
// owner: i, or j with the neighbour's frame, E24), e = x_j − x_i, d = Rᵀ e and ‖e‖ (= ‖d‖).
template <class S>
struct RigidEdge {
  S R[9];
  S ex, ey, ez, dx, dy, dz, len;
};

template <class S>
SMG_HOST_DEVICE inline void fused_rigid_edge_at(PositionsView<const S> x,
                                                QuaternionsView<const S> q, Index s, Index i,
                                                Index j, Index f, RigidEdge<S>& r) {
  using std::sqrt;
  smg::detail::rotation_from_wxyz(q.ptr(s, f), r.R);
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
// writes F = ∂E/∂x_j^t (−F is ∂E/∂x_i^t) and Rg, the right-tangent gradient of the frame
// owner's R^t (R_i^t, or R_j^t with the neighbour's frame), from every
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
  const Index f = c.frame == RigidFrame::neighbor ? j : i;
  RigidEdge<S> e0;
  fused_rigid_edge_at(x, q, t, i, j, f, e0);
  // w̃ (E7) of this edge at frame u, per energy.
  auto weight = [&](Index u, int en) {
    return en == 0 ? confidence_edge_weight(w, c.alpha, conf ? conf[u * N + j] : S(1))
                   : confidence_edge_weight(w, L(1), S(1));
  };
  // The pair term of energy en (E9) under its penalty (E24): squared through carap_term with
  // k = γ w̃ (the CPU's arithmetic), the others with γ and w̃ apart.
  auto term = [&](int en, L gm, S wt, S ax, S ay, S az, S al, S& px, S& py, S& pz, S& pq) {
    if (c.penalty[en] == Penalty::squared)
      return carap_term(S(gm * wt), ax, ay, az, al, c.lambda_c[en], c.lambda_l[en], px, py, pz,
                        pq);
    return carap_term_penalty(c.penalty[en], S(gm), wt, S(c.eps[en]), ax, ay, az, al,
                              c.lambda_c[en], c.lambda_l[en], px, py, pz, pq);
  };
  S gx(0), gy(0), gz(0), h(0);
  for (int g = 0; g < c.n_gaps; ++g) {
    const Index delta = c.delta[g];
    S px, py, pz, pq;
    if (t + delta < T) {  // pair (t, t + δ), weighted at t: its energy belongs to frame t
      RigidEdge<S> es;
      fused_rigid_edge_at(x, q, t + delta, i, j, f, es);
      for (int en = 0; en < 2; ++en) {
        const L gm = gamma.v[en][g];
        if (gm == L(0)) continue;
        const S ev = term(en, gm, weight(t, en), es.dx - e0.dx, es.dy - e0.dy, es.dz - e0.dz,
                          es.len - e0.len, px, py, pz, pq);  // (E9, E24)
        if (energy != nullptr) energy[en] += ev;
        gx -= px;
        gy -= py;
        gz -= pz;
        h -= pq;
      }
    }
    if (grad && t - delta >= 0) {  // pair (t − δ, t), weighted at t − δ
      RigidEdge<S> ep;
      fused_rigid_edge_at(x, q, t - delta, i, j, f, ep);
      for (int en = 0; en < 2; ++en) {
        const L gm = gamma.v[en][g];
        if (gm == L(0)) continue;
        term(en, gm, weight(t - delta, en), e0.dx - ep.dx, e0.dy - ep.dy, e0.dz - ep.dz,
             e0.len - ep.len, px, py, pz, pq);
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

// Element (t, n): node n at frame t as the tail of its out-edges (their energies into
// energy[2], −F and, in the row's frame, the rotation parts) and, when the position gradient
// or (in the neighbour's frame) the rotation gradient is wanted, as the head of its in-edges
// (+F, the rotation parts; in the ReverseGraph's increasing slot order). Adds x_n^t's gradient to
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
  const bool nbr_frame = c.frame == RigidFrame::neighbor;
  S g[3] = {S(0), S(0), S(0)}, r[3] = {S(0), S(0), S(0)};
  for (Index k = 0; k < K; ++k) {
    const Index j = graph.indices(n, k);
    if (j < 0) break;
    const S w = graph.weights(n, k);
    // A zero weight contributes exactly nothing, except sqrt_weighted's m λ sqrt(ε) (E24).
    if (!(w > S(0)) && !(c.keep_zero && w == S(0))) continue;
    S F[3], Rg[3];
    fused_rigid_edge(c, gamma, x, q, conf, t, n, j, w, grad, energy, F, Rg);
    if (!grad) continue;
    for (int a = 0; a < 3; ++a) {
      if (c.stop != StopGradient::row) g[a] -= F[a];  // a held row gets no position gradient
      if (!nbr_frame) r[a] += Rg[a];
    }
  }
  // As a neighbour: +F (a held neighbour gets none) and, in the neighbour's frame, the rotation
  // part.
  const bool in_x = grad_x != nullptr && c.stop != StopGradient::neighbor;
  const bool in_r = want_r && nbr_frame;
  if (in_x || in_r)
    for (std::int32_t a = rev_offsets[n]; a < rev_offsets[n + 1]; ++a) {
      const Index slot = rev_entries[a], i = slot / K, k = slot - i * K;
      const S w = graph.weights(i, k);
      if (!(w > S(0)) && !(c.keep_zero && w == S(0))) continue;
      S F[3], Rg[3];
      fused_rigid_edge(c, gamma, x, q, conf, t, i, n, w, true, static_cast<S*>(nullptr), F, Rg);
      for (int b = 0; b < 3; ++b) {
        if (in_x) g[b] += F[b];
        if (in_r) r[b] += Rg[b];
      }
    }
  if (grad_x != nullptr) {
    S* dst = grad_x + (t * N + n) * 3;
    for (int b = 0; b < 3; ++b) dst[b] += g[b];
  }
  add_rotation_gradient(q.ptr(t, n), t * N + n, r, grad_tangent, grad_raw);
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
  c.penalty[0] = o.carap.penalty;
  c.penalty[1] = o.arap.penalty;
  c.eps[0] = o.carap.penalty_eps;
  c.eps[1] = o.arap.penalty_eps;
  c.stop = o.terms.carap ? o.carap.stop_gradient : o.arap.stop_gradient;
  c.frame = o.terms.carap ? o.carap.frame : o.arap.frame;
  for (int en = 0; en < 2; ++en) {
    if (!on[en]) continue;
    if (c.penalty[en] == Penalty::sqrt_weighted) c.keep_zero = true;
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

}  // namespace detail
}  // namespace smg::cuda
