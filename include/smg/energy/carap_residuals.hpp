// smg/energy/carap_residuals.hpp — C-ARAP (and plain ARAP) as residuals with dense Jacobian
// blocks, for Gauss-Newton / Levenberg-Marquardt and Ceres users (docs/math/energy.md (E17)).
//
// Each term (δ, t, i, j) of (E9) is one residual block of 4 rows, square-root weighted so that
// the energy is the plain sum of squares (times options.weight / term count like carap()):
//   r = [ √(k λc) (d^s − d^t) ;  √(k λl) (‖d^s‖ − ‖d^t‖) ],  k = scale · γ_δ · w̃_ij^t,  s = t + δ
// with d = Rᵀ(x_j − x_i) (E8). It touches x_i^t, x_j^t, R_i^t, x_i^s, x_j^s, R_i^s; the Jacobians
// are 4x3 blocks, rotations in the right tangent (R <- R Exp(φ)):
//   ∂r/∂x_j = [±√(kλc) Rᵀ ; ±√(kλl) e/‖e‖ ᵀ],  ∂r/∂x_i = −∂r/∂x_j,  ∂r/∂φ_i = [±√(kλc) [d]× ; 0]
// (+ at the later frame s, − at the earlier t; the derivative of ‖d‖ at 0 is 0). The gradient
// of the energy is Σ 2 Jᵀ r — the same numbers carap() accumulates (tested).
//
// Two ways in: carap_residual_block() evaluates one block by its address (gap, t, i, k) — what
// a Ceres CostFunction calls; for_each_carap_residual() streams every block through a visitor in
// a deterministic order, chunk by chunk in parallel (a GN/LM normal-equation builder).
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/quaternion.hpp"
#include "smg/core/so3.hpp"
#include "smg/energy/carap.hpp"
#include "smg/energy/elements/carap.hpp"

namespace smg {

template <class S>
struct CarapResidualBlock {
  Index gap = 0;     // index into CarapOptions::gaps
  Index t = 0;       // earlier frame
  Index s = 0;       // later frame, t + δ
  Index i = 0;       // node
  Index j = 0;       // neighbour (graph.indices(i, k))
  Index k = 0;       // neighbour slot
  Vector4<S> r;      // residual; energy contribution r.squaredNorm()
  // Jacobians, rows = r, columns = the 3 coordinates of the variable (world position or right
  // tangent). Filled only when requested.
  Eigen::Matrix<S, 4, 3> J_xi_t, J_xj_t, J_rot_i_t, J_xi_s, J_xj_s, J_rot_i_s;
};

// Number of residual blocks: carap_term_count(graph, T, options.gaps).
template <class S, class I>
inline Index carap_residual_count(const NeighborsView<S, I>& graph, Index frames,
                                  const CarapOptions& options) {
  return carap_term_count(graph, frames, options.gaps);
}

// The factor every term carries: options.weight, divided by the number of terms under
// Normalization::mean (counting them is O(N K): compute it once and pass it to
// carap_residual_block when evaluating many blocks).
// The residual forms (E17) and the directed reading (E20) are of the squared energy only: r
// with ‖r‖² = E exists for penalty=squared, the stop-gradient (E24) is a gradient rule, not a
// residual, and the Jacobians are written for the row's frame (all three are the fused step's
// options).
template <class S, class I>
inline double carap_residual_scale(const NeighborsView<S, I>& graph, Index frames,
                                   const CarapOptions& o) {
  SMG_ASSERT(o.penalty == Penalty::squared && o.stop_gradient == StopGradient::none &&
                 o.frame == RigidFrame::row,
             "carap residuals: penalty=squared, stop_gradient=none and frame=row only (E24)");
  double scale = o.weight;
  if (o.normalization == Normalization::mean) {
    const Index terms = carap_term_count(graph, frames, o.gaps);
    scale = terms > 0 ? scale / static_cast<double>(terms) : 0.0;
  }
  return scale;
}

namespace detail {

// d = Rᵀ e with e = x_j − x_i at one frame, R from q normalised (E8).
template <class S>
struct EdgeFrame {
  Matrix3<S> R;
  Vector3<S> e, d;
  S len;
};
template <class S>
inline EdgeFrame<S> carap_edge_frame(PositionsView<const S> x, QuaternionsView<const S> q,
                                     Index t, Index i, Index j) {
  using std::sqrt;
  EdgeFrame<S> f;
  S R[9];
  rotation_from_wxyz(q.ptr(t, i), R);
  f.R << R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8];
  f.e = x(t, j) - x(t, i);
  f.d = f.R.transpose() * f.e;
  f.len = sqrt(f.e.squaredNorm());
  return f;
}

// The residual of term (E9) in the form (E17), from the edge at t and at s = t + δ with pair
// factor k, and its Jacobians when asked.
template <class S>
inline void carap_block_from(const EdgeFrame<S>& ft, const EdgeFrame<S>& fs, S k,
                             Literal<S> lambda_c, Literal<S> lambda_l, bool jacobians,
                             CarapResidualBlock<S>& out) {
  const Vector3<S> dd = fs.d - ft.d;
  S sc, sl;
  carap_term_residual(k, S(dd(0)), S(dd(1)), S(dd(2)), S(fs.len - ft.len), lambda_c, lambda_l,
                      out.r.data(), sc, sl);
  if (!jacobians) return;
  const Vector3<S> nt = ft.len > S(0) ? Vector3<S>(ft.e / ft.len) : Vector3<S>::Zero();
  const Vector3<S> ns = fs.len > S(0) ? Vector3<S>(fs.e / fs.len) : Vector3<S>::Zero();
  out.J_xj_s.template topRows<3>() = sc * fs.R.transpose();
  out.J_xj_s.row(3) = sl * ns.transpose();
  out.J_xj_t.template topRows<3>() = -sc * ft.R.transpose();
  out.J_xj_t.row(3) = -sl * nt.transpose();
  out.J_xi_s = -out.J_xj_s;
  out.J_xi_t = -out.J_xj_t;
  out.J_rot_i_s.template topRows<3>() = sc * so3::hat(fs.d);
  out.J_rot_i_s.row(3).setZero();
  out.J_rot_i_t.template topRows<3>() = -sc * so3::hat(ft.d);
  out.J_rot_i_t.row(3).setZero();
}
}  // namespace detail

// Evaluates the residual block of term (gap, t, i, k) — gap indexes options.gaps, k a neighbour
// slot of node i — into `out`, with Jacobians when `jacobians`. Returns false (out untouched)
// when the address names no term: k is padding, or t + δ >= T. `scale`: the value of
// carap_residual_scale() (computed here when negative). Precondition: validate_carap.
template <class S, class I>
bool carap_residual_block(PositionsView<const S> positions, QuaternionsView<const S> rotations,
                          FrameScalarsView<const S> confidence, const NeighborsView<S, I>& graph,
                          const CarapOptions& options, Index gap, Index t, Index i, Index k,
                          CarapResidualBlock<S>& out, bool jacobians = true,
                          double scale = -1.0) {
  using L = Literal<S>;
  const Index T = positions.frames();
  const Index delta = options.gaps[static_cast<std::size_t>(gap)].delta;
  const Index j = graph.indices(i, k);
  if (j < 0 || t < 0 || t + delta >= T) return false;
  if (scale < 0) scale = carap_residual_scale(graph, T, options);
  const L alpha(options.alpha);
  const S c = confidence.data() ? confidence(t, j) : S(1);
  const S kw = L(scale * options.gaps[static_cast<std::size_t>(gap)].weight) *
               confidence_edge_weight(graph.weights(i, k), alpha, c);
  out.gap = gap;
  out.t = t;
  out.s = t + delta;
  out.i = i;
  out.j = j;
  out.k = k;
  const auto ft = detail::carap_edge_frame(positions, rotations, t, i, j);
  const auto fs = detail::carap_edge_frame(positions, rotations, t + delta, i, j);
  detail::carap_block_from(ft, fs, kw, L(options.lambda_c), L(options.lambda_l), jacobians, out);
  return true;
}

// Number of chunks for_each_carap_residual uses (to size per-chunk accumulators).
inline Index carap_residual_chunks(Index frames, Index nodes, std::size_t n_gaps) {
  return parallel_chunk_count(static_cast<Index>(n_gaps) * frames * nodes);
}

// Calls visit(block, chunk) for every residual block, in the order gap, t, i, k within each
// chunk; chunks (contiguous ranges of (gap, t, i)) may run concurrently, so the visitor must
// only write state owned by its chunk (e.g. per-chunk partial normal equations, combined in
// chunk order afterwards for a thread-count-independent result). Precondition: validate_carap.
template <class S, class I, class Visitor>
void for_each_carap_residual(detail::NonDeducedT<PositionsView<const S>> positions,
                             detail::NonDeducedT<QuaternionsView<const S>> rotations,
                             detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                             const NeighborsView<S, I>& graph,
                             const CarapOptions& options, Visitor&& visit, bool jacobians = true,
                             ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  const Index G = static_cast<Index>(options.gaps.size());
  const double scale = carap_residual_scale(graph, T, options);
  parallel_for_chunks(
      G * T * N,
      [&](Index chunk, Index begin, Index end) {
        CarapResidualBlock<S> block;
        for (Index item = begin; item < end; ++item) {
          const Index g = item / (T * N), t = (item / N) % T, i = item % N;
          for (Index k = 0; k < graph.k(); ++k) {
            if (graph.indices(i, k) < 0) break;
            if (carap_residual_block(positions, rotations, confidence, graph, options, g, t, i, k,
                                     block, jacobians, scale))
              visit(static_cast<const CarapResidualBlock<S>&>(block), chunk);
          }
        }
      },
      parallel);
}

// Adds a C-ARAP block's gradient 2 Jᵀ r to the position and (right-tangent) rotation gradients.
template <class S>
void add_carap_block_gradient(const CarapResidualBlock<S>& b, PositionsView<S> grad_positions,
                              TangentsView<S> grad_rotations = {}) {
  if (grad_positions.data()) {
    grad_positions(b.t, b.i) += S(2) * b.J_xi_t.transpose() * b.r;
    grad_positions(b.t, b.j) += S(2) * b.J_xj_t.transpose() * b.r;
    grad_positions(b.s, b.i) += S(2) * b.J_xi_s.transpose() * b.r;
    grad_positions(b.s, b.j) += S(2) * b.J_xj_s.transpose() * b.r;
  }
  if (grad_rotations.data()) {
    grad_rotations(b.t, b.i) += S(2) * b.J_rot_i_t.transpose() * b.r;
    grad_rotations(b.s, b.i) += S(2) * b.J_rot_i_s.transpose() * b.r;
  }
}

}  // namespace smg
