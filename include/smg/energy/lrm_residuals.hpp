// smg/energy/lrm_residuals.hpp — LRM as residuals with dense Jacobian blocks, for Gauss-Newton /
// Levenberg-Marquardt and Ceres users (docs/math/energy.md (E18)).
//
// One block per (t, i) neighbourhood: ω couples all of node i's neighbours, so every residual
// of the block depends on every neighbour's position x_m^t and velocity u_m^t (3n x 3n dense
// blocks). The Huber loss is handled as iteratively reweighted least squares, stated honestly:
//   raw residuals   r_k = ũ_k − ω × x̃_k                                   (E13)
//   IRLS residuals  f_k = √(scale ŵ_k ψ_k / 2) r_k,  ψ_k = ρ'(‖r_k‖)/‖r_k‖ (1 where ‖r_k‖ <= δ_H)
// with ψ_k frozen at the current point (a constant of the Jacobian). Then Σ‖f‖² equals the LRM
// term wherever every residual is in Huber's quadratic zone, and 2 J_fᵀ f is the exact gradient
// everywhere (ω differentiated through the solve unless options.detach_omega) — so a GN/LM step
// on these residuals is an IRLS step on LRM. The exact energy of the block is in `energy`. A
// Ceres user who prefers Ceres's own robustifier takes the raw residuals r_k and ŵ_k and wraps
// them in ScaledLoss(HuberLoss(δ_H), scale ŵ_k) per neighbour (docs/math/energy.md).
//
// Jacobians (E18), with M = A + μI and [·]× the cross-product matrix:
//   ∂ω/∂u_m = M⁻¹ ŵ_m [x̃_m]×
//   ∂ω/∂x_m = M⁻¹ ŵ_m (−[ũ_m]× − (2 + 4c_μ) ω x̃_mᵀ + (x̃_m·ω) I + x̃_m ωᵀ)
//   ∂r_k/∂u_m = (δ_km − ŵ_m) I + [x̃_k]× ∂ω/∂u_m
//   ∂r_k/∂x_m = −(δ_km − ŵ_m) [ω]× + [x̃_k]× ∂ω/∂x_m
// (ω is invariant to a common translation of the positions or velocities, so the centring does
// not enter ∂ω.) Velocities are frame differences: u^t = x^plus − x^minus (E1), so the block
// touches frames t, plus and minus; add_lrm_block_gradient() applies that chain rule.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "smg/core/so3.hpp"
#include "smg/energy/lrm.hpp"

namespace smg {

template <class S>
struct LrmResidualBlock {
  using VectorX = Eigen::Matrix<S, Eigen::Dynamic, 1>;
  using MatrixX = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  Index t = 0, i = 0;
  VelocityFrames frames;        // u^t = x^plus − x^minus (frames.moving false: u = 0)
  std::vector<Index> neighbors; // the n neighbours j_k (padding excluded)
  VectorX r;       // 3n: IRLS residuals f_k = √(scale ŵ_k ψ_k / 2) r_k
  VectorX raw;     // 3n: r_k = ũ_k − ω × x̃_k
  VectorX weight;  // n: ŵ_k (normalised confidence-aware weights)
  VectorX irls;    // n: ψ_k
  Vector3<S> omega = Vector3<S>::Zero();
  S energy = S(0);  // scale Σ_k ŵ_k ρ_H(‖r_k‖): the exact LRM term of this block
  MatrixX J_x;      // 3n x 3n: ∂f/∂x_m^t (ψ frozen)
  MatrixX J_u;      // 3n x 3n: ∂f/∂u_m^t
  std::vector<S> scratch;  // reused between evaluations (no allocation once grown)
};

// options.weight, divided by the number of terms under Normalization::mean (O(N K) to count:
// compute once and pass to lrm_residual_block when evaluating many blocks).
template <class S, class I>
inline double lrm_residual_scale(const NeighborsView<S, I>& graph, Index frames,
                                 const LrmOptions& o) {
  double scale = o.weight;
  if (o.normalization == Normalization::mean) {
    const Index terms = lrm_term_count(graph, frames);
    scale = terms > 0 ? scale / static_cast<double>(terms) : 0.0;
  }
  return scale;
}

// Evaluates the block of node i at frame t. Returns false (and an empty block, energy 0) when
// the node has no neighbour with positive weight. `scale`: lrm_residual_scale() (computed when
// negative). Precondition: validate_lrm.
template <class S, class I>
bool lrm_residual_block(PositionsView<const S> positions, FrameScalarsView<const S> confidence,
                        const NeighborsView<S, I>& graph, const LrmOptions& options, Index t, Index i,
                        LrmResidualBlock<S>& out, bool jacobians = true, double scale = -1.0) {
  using L = Literal<S>;
  using std::sqrt;
  const Index T = positions.frames();
  if (scale < 0) scale = lrm_residual_scale(graph, T, options);
  const Index n = graph.degree(i);
  out.t = t;
  out.i = i;
  out.frames = velocity_frames(t, T);
  out.neighbors.resize(static_cast<std::size_t>(n));
  // The neighbourhood's SoA inputs, as the fast kernel sees them (lane = scalar).
  std::vector<S>& buf = out.scratch;
  buf.resize(static_cast<std::size_t>(8 * n + detail::lrm_scratch_size(n) + 3));
  S* xs = buf.data();
  S* us = xs + 3 * n;
  S* a = us + 3 * n;
  S* scratch = a + n;
  const L alpha(options.alpha);
  for (Index k = 0; k < n; ++k) {
    const Index j = graph.indices(i, k);
    out.neighbors[static_cast<std::size_t>(k)] = j;
    const Vector3<S> xj = positions(t, j);
    const Vector3<S> uj = velocity(positions, t, j);
    for (int c = 0; c < 3; ++c) {
      xs[c * n + k] = xj(c);
      us[c * n + k] = uj(c);
    }
    const S c = confidence.data() ? confidence(t, j) : S(1);
    a[k] = confidence_edge_weight(graph.weights(i, k), alpha, c);
  }
  const detail::LrmParams<S> p = detail::lrm_params<S>(options, false);
  S om[3];
  const S e = detail::lrm_neighborhood<S, S>(n, xs, us, a, p, scratch, nullptr, nullptr, om);
  out.omega = Vector3<S>(om[0], om[1], om[2]);
  out.energy = L(scale) * e;
  // lrm_neighborhood's scratch: ŵ [n], x̃ [3n], ũ [3n], ψ [n], r [3n].
  const S* w = scratch;
  const S* xt = w + n;
  const S* ut = xt + 3 * n;
  const S* psi = ut + 3 * n;
  const S* r = psi + n;
  out.weight.resize(n);
  out.irls.resize(n);
  out.raw.resize(3 * n);
  out.r.resize(3 * n);
  S W(0);
  for (Index k = 0; k < n; ++k) W += a[k];
  if (n == 0 || !(W > S(0))) {
    out.weight.setZero();
    out.irls.setZero();
    out.raw.setZero();
    out.r.setZero();
    out.J_x.setZero(3 * n, 3 * n);
    out.J_u.setZero(3 * n, 3 * n);
    return false;
  }
  S* sk_p = scratch + detail::lrm_scratch_size(n);  // after the neighbourhood's scratch
  auto sk = [sk_p](Index k) -> S& { return sk_p[k]; };
  for (Index k = 0; k < n; ++k) {
    out.weight(k) = w[k];
    out.irls(k) = psi[k];
    sk(k) = sqrt(L(scale) * w[k] * psi[k] * L(0.5));
    for (int c = 0; c < 3; ++c) {
      out.raw(3 * k + c) = r[c * n + k];
      out.r(3 * k + c) = sk(k) * r[c * n + k];
    }
  }
  if (!jacobians) return true;

  auto xt_of = [&](Index k) { return Vector3<S>(xt[k], xt[n + k], xt[2 * n + k]); };
  auto ut_of = [&](Index k) { return Vector3<S>(ut[k], ut[n + k], ut[2 * n + k]); };
  // M = A + μI (E12), recomputed from x̃ and ŵ; ω's sensitivities unless held constant.
  Matrix3<S> A = Matrix3<S>::Zero();
  for (Index k = 0; k < n; ++k) {
    const Vector3<S> v = xt_of(k);
    A += w[k] * (v.squaredNorm() * Matrix3<S>::Identity() - v * v.transpose());
  }
  const S tr = A.trace();
  const bool dynamic_omega = !options.detach_omega && tr > S(0);
  std::vector<Matrix3<S>> Cu(static_cast<std::size_t>(n)), Cx(static_cast<std::size_t>(n));
  if (dynamic_omega) {
    const S mu = p.mu_factor * tr;
    const detail::Ldlt3<S> M(A(0, 0) + mu, A(0, 1), A(0, 2), A(1, 1) + mu, A(1, 2), A(2, 2) + mu);
    Matrix3<S> Minv;
    for (int c = 0; c < 3; ++c) {
      const Vector3<S> ec = Vector3<S>::Unit(c);
      S x0, x1, x2;
      M.solve(ec(0), ec(1), ec(2), x0, x1, x2);
      Minv.col(c) = Vector3<S>(x0, x1, x2);
    }
    const Vector3<S> o = out.omega;
    for (Index m = 0; m < n; ++m) {
      const Vector3<S> xm = xt_of(m), um = ut_of(m);
      Cu[static_cast<std::size_t>(m)] = w[m] * (Minv * so3::hat(xm));
      const Matrix3<S> B = -so3::hat(um) - (L(2) + L(4) * p.mu_factor) * o * xm.transpose() +
                           xm.dot(o) * Matrix3<S>::Identity() + xm * o.transpose();
      Cx[static_cast<std::size_t>(m)] = w[m] * (Minv * B);
    }
  }
  out.J_x.setZero(3 * n, 3 * n);
  out.J_u.setZero(3 * n, 3 * n);
  const Matrix3<S> om_hat = so3::hat(out.omega);
  for (Index k = 0; k < n; ++k) {
    const Matrix3<S> xk_hat = so3::hat(xt_of(k));
    const S s = sk(k);
    for (Index m = 0; m < n; ++m) {
      const S delta = (k == m ? S(1) : S(0)) - w[m];
      Matrix3<S> ju = delta * Matrix3<S>::Identity();
      Matrix3<S> jx = -delta * om_hat;
      if (dynamic_omega) {
        ju += xk_hat * Cu[static_cast<std::size_t>(m)];
        jx += xk_hat * Cx[static_cast<std::size_t>(m)];
      }
      out.J_u.template block<3, 3>(3 * k, 3 * m) = s * ju;
      out.J_x.template block<3, 3>(3 * k, 3 * m) = s * jx;
    }
  }
  return true;
}

// Adds the block's gradient 2 J_fᵀ f to grad_positions [T][N][3], through u = x^plus − x^minus.
template <class S>
void add_lrm_block_gradient(const LrmResidualBlock<S>& b, PositionsView<S> grad_positions) {
  const Index n = static_cast<Index>(b.neighbors.size());
  if (b.J_x.rows() != 3 * n || n == 0) return;
  const Eigen::Matrix<S, Eigen::Dynamic, 1> gx = S(2) * b.J_x.transpose() * b.r;
  const Eigen::Matrix<S, Eigen::Dynamic, 1> gu = S(2) * b.J_u.transpose() * b.r;
  for (Index m = 0; m < n; ++m) {
    const Index j = b.neighbors[static_cast<std::size_t>(m)];
    grad_positions(b.t, j) += gx.template segment<3>(3 * m);
    if (b.frames.moving) {
      grad_positions(b.frames.plus, j) += gu.template segment<3>(3 * m);
      grad_positions(b.frames.minus, j) -= gu.template segment<3>(3 * m);
    }
  }
}

// Number of chunks for_each_lrm_residual uses.
inline Index lrm_residual_chunks(Index frames, Index nodes) {
  return parallel_chunk_count(frames * nodes);
}

// Calls visit(block, chunk) for every node with a neighbour, at every frame, in the order
// (t, i) within each chunk; chunks may run concurrently (the visitor writes only per-chunk
// state). Precondition: validate_lrm.
template <class S, class I, class Visitor>
void for_each_lrm_residual(detail::NonDeducedT<PositionsView<const S>> positions,
                           detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                           const NeighborsView<S, I>& graph, const LrmOptions& options,
                           Visitor&& visit, bool jacobians = true, ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  const double scale = lrm_residual_scale(graph, T, options);
  parallel_for_chunks(
      T * N,
      [&](Index chunk, Index begin, Index end) {
        LrmResidualBlock<S> block;
        for (Index item = begin; item < end; ++item)
          if (lrm_residual_block(positions, confidence, graph, options, item / N, item % N, block,
                                 jacobians, scale))
            visit(static_cast<const LrmResidualBlock<S>&>(block), chunk);
      },
      parallel);
}

}  // namespace smg
