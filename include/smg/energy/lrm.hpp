// smg/energy/lrm.hpp — local rigid motion energy (LRM) with its exact gradient, including the
// dependence of the local angular velocity ω on the positions through the regularised 3x3 solve
// (docs/design.md "LRM"; paper section 3.2; docs/math/energy.md (E11)-(E16)).
//
// Per node i and frame t, over the neighbours j ∈ N(i) with weights ŵ_j = w̃_ij^t / Σ_k w̃_ik^t
// (E7, normalised; constants for the gradient):
//   v̄ = Σ ŵ_j u_j,  g = Σ ŵ_j x_j,  ũ_j = u_j − v̄,  x̃_j = x_j − g                      (E11)
//   A = Σ ŵ_j (‖x̃_j‖² I − x̃_j x̃_jᵀ),  b = Σ ŵ_j x̃_j × ũ_j,
//   ω = (A + μ I)⁻¹ b,  μ = c_μ trace(A)  (c_μ = 1e-10 double, 1e-5 float; ω = 0 if trace 0) (E12)
//   r_j = ũ_j − ω × x̃_j,  L_{t,i} = Σ_j ŵ_j ρ_H(‖r_j‖)                                  (E13)
//   L = Σ_t Σ_i L_{t,i}                                                                   (E14)
// with the Huber ρ_H(r) = r²/2 for r <= δ_H, δ_H (r − δ_H/2) beyond. Node i's own position does
// not enter its term; a node with no neighbour (or zero total weight) adds 0.
//
// The gradient (E15) differentiates everything except the weights: the centring, ω through
// the solve (by the adjoint λ = (A + μI)⁻¹ ∂L/∂ω), and μ through trace(A) as well, so it is the
// exact gradient of the function above. LrmOptions::detach_omega holds ω constant instead.
// Velocities are frame differences (E1), so the gradient w.r.t. u reaches two frames of x.
//
// Parallel scheme: frames are independent except through u^t = x^{t+1} − x^t, so each chunk
// owns whole frames: it adds ∂L/∂x^t straight into the caller's rows of its frames and ∂L/∂u^t
// into a workspace array [T][N][3]; a second pass adds the velocity part to the two frames of
// each difference. Deterministic for any thread count.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/carap.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/velocity.hpp"
#include "smg/energy/workspace.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

// Checks the inputs and outputs of lrm(). `confidence` may be empty (all 1); the gradient and
// omega outputs may be empty (not computed).
template <class S, class I>
Status validate_lrm(detail::NonDeducedT<PositionsView<const S>> positions,
                    detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                    const NeighborsView<S, I>& graph, const LrmOptions& options,
                    PositionsView<S> grad_positions = {}, TangentsView<S> omega = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  if (Status s = validate_positions<S>(positions, -1, -1, "positions"); !s) return s;
  if (Status s = validate_optional_confidence<S>(confidence, T, N); !s) return s;
  if (Status s = validate_neighbors(graph, N, "graph"); !s) return s;
  if (Status s = validate_options(options); !s) return s;
  if (grad_positions.data() != nullptr)
    if (Status s = validate_output(grad_positions, T, N, "grad_positions"); !s) return s;
  if (omega.data() != nullptr)
    if (Status s = validate_output(omega, T, N, "omega"); !s) return s;
  return Status::ok();
}

// Number of terms of (E14): T · Σ_i |N(i)|. Normalization::mean divides by this.
template <class S, class I>
inline Index lrm_term_count(const NeighborsView<S, I>& graph, Index frames) {
  return frames * edge_count(graph);
}

namespace detail {

// LDLᵀ of a symmetric positive definite 3x3 matrix (no pivoting, no square root: stable for
// SPD, and AutoDiffScalar-friendly).
template <class V>
struct Ldlt3 {
  V d0, d1, d2, l10, l20, l21;
  SMG_HOST_DEVICE Ldlt3(const V& m00, const V& m01, const V& m02, const V& m11, const V& m12, const V& m22)
      : d0(m00) {
    l10 = m01 / d0;
    l20 = m02 / d0;
    d1 = m11 - l10 * l10 * d0;
    l21 = (m12 - l20 * l10 * d0) / d1;
    d2 = m22 - l20 * l20 * d0 - l21 * l21 * d1;
  }
  SMG_HOST_DEVICE void solve(const V& b0, const V& b1, const V& b2, V& x0, V& x1, V& x2) const {
    const V y1 = b1 - l10 * b0, y2 = b2 - l20 * b0 - l21 * y1;
    x2 = y2 / d2;
    x1 = y1 / d1 - l21 * x2;
    x0 = b0 / d0 - l10 * x1 - l20 * x2;
  }
};

template <class S>
struct LrmParams {
  Literal<S> huber_delta;
  Literal<S> mu_factor;  // c_μ
  bool detach_omega = false;
  bool gradient = false;
};

// Scratch lanes per neighbourhood of K entries.
inline Index lrm_scratch_size(Index K) { return 11 * K; }

// One neighbourhood (or W of them, lane-wise) over K entries: energy L_{t,i} (E11)-(E13) and,
// with p.gradient, ∂L/∂x_k into gx[3K] and ∂L/∂u_k into gu[3K] (E15). Inputs, [component][k]:
// positions x[3K], velocities u[3K], raw weights a[K] (entries with a = 0, e.g. padding, add
// nothing). scratch: lrm_scratch_size(K) lanes. omega (3 lanes, optional) receives ω.
template <class V, class S>
SMG_HOST_DEVICE V lrm_neighborhood(Index K, const V* x, const V* u, const V* a, const LrmParams<S>& p,
                   V* scratch, V* gx, V* gu, V* omega = nullptr) {
  using L = Literal<S>;
  const V zero = lane_constant<V>(L(0)), one = lane_constant<V>(L(1));
  V* w = scratch;
  V* xt = w + K;
  V* ut = xt + 3 * K;
  V* psi = ut + 3 * K;
  V* r = psi + K;  // 3K: residuals, then q = ŵ ψ r

  // Normalised weights; an empty neighbourhood gets ŵ = 0 and so contributes 0 throughout.
  V W = zero;
  for (Index k = 0; k < K; ++k) W += a[k];
  const auto active = lane_greater(W, zero);
  const V inv_w = lane_select(active, V(one / lane_select(active, W, one)), zero);
  for (Index k = 0; k < K; ++k) w[k] = a[k] * inv_w;
  // Centring (E11).
  for (int c = 0; c < 3; ++c) {
    V gs = zero, vs = zero;
    for (Index k = 0; k < K; ++k) {
      gs += w[k] * x[c * K + k];
      vs += w[k] * u[c * K + k];
    }
    for (Index k = 0; k < K; ++k) {
      xt[c * K + k] = x[c * K + k] - gs;
      ut[c * K + k] = u[c * K + k] - vs;
    }
  }
  // Normal equations (E12): S = Σ ŵ x̃ x̃ᵀ, A = trace(S) I − S, b = Σ ŵ x̃ × ũ.
  const V *X = xt, *Y = xt + K, *Z = xt + 2 * K, *U0 = ut, *U1 = ut + K, *U2 = ut + 2 * K;
  V sxx = zero, sxy = zero, sxz = zero, syy = zero, syz = zero, szz = zero;
  V b0 = zero, b1 = zero, b2 = zero;
  for (Index k = 0; k < K; ++k) {
    const V wx = w[k] * X[k], wy = w[k] * Y[k], wz = w[k] * Z[k];
    sxx += wx * X[k];
    sxy += wx * Y[k];
    sxz += wx * Z[k];
    syy += wy * Y[k];
    syz += wy * Z[k];
    szz += wz * Z[k];
    b0 += wy * U2[k] - wz * U1[k];
    b1 += wz * U0[k] - wx * U2[k];
    b2 += wx * U1[k] - wy * U0[k];
  }
  const V tr = sxx + syy + szz;  // trace(A) = 2 tr
  const auto solved = lane_greater(tr, zero);
  const V mu = (L(2) * p.mu_factor) * tr;
  // Unsolved lanes (trace 0) factor I instead and are then masked to ω = 0.
  const V diag = mu + lane_select(solved, zero, one);
  const Ldlt3<V> M(tr - sxx + diag, -sxy, -sxz, tr - syy + diag, -syz, tr - szz + diag);
  V o0, o1, o2;
  M.solve(b0, b1, b2, o0, o1, o2);
  o0 = lane_select(solved, o0, zero);
  o1 = lane_select(solved, o1, zero);
  o2 = lane_select(solved, o2, zero);
  if (omega) {
    omega[0] = o0;
    omega[1] = o1;
    omega[2] = o2;
  }
  // Residuals and Huber (E13).
  const L delta = p.huber_delta, delta2 = p.huber_delta * p.huber_delta;
  V energy = zero;
  for (Index k = 0; k < K; ++k) {
    const V x0 = X[k], x1 = Y[k], x2 = Z[k];
    const V r0 = U0[k] - (o1 * x2 - o2 * x1);
    const V r1 = U1[k] - (o2 * x0 - o0 * x2);
    const V r2 = U2[k] - (o0 * x1 - o1 * x0);
    r[k] = r0;
    r[K + k] = r1;
    r[2 * K + k] = r2;
    const V n2 = r0 * r0 + r1 * r1 + r2 * r2;
    const auto linear = lane_greater(n2, lane_constant<V>(delta2));
    const V nr = lane_sqrt(lane_select(linear, n2, lane_constant<V>(delta2)));
    const V rho = lane_select(linear, V(delta * (nr - L(0.5) * delta)), V(L(0.5) * n2));
    psi[k] = lane_select(linear, V(delta / nr), one);  // ρ'(r)/r
    energy += w[k] * rho;
  }
  if (!p.gradient) return energy;

  // q = ŵ ψ r = ∂L/∂r; Q = Σ q; z = ∂L/∂ω = Σ q × x̃.
  V Q0 = zero, Q1 = zero, Q2 = zero, z0 = zero, z1 = zero, z2 = zero;
  for (Index k = 0; k < K; ++k) {
    const V s = w[k] * psi[k];
    const V q0 = s * r[k], q1 = s * r[K + k], q2 = s * r[2 * K + k];
    r[k] = q0;
    r[K + k] = q1;
    r[2 * K + k] = q2;
    Q0 += q0;
    Q1 += q1;
    Q2 += q2;
    z0 += q1 * Z[k] - q2 * Y[k];
    z1 += q2 * X[k] - q0 * Z[k];
    z2 += q0 * Y[k] - q1 * X[k];
  }
  // Adjoint of ω = (A + μI)⁻¹ b: λ = (A + μI)⁻¹ z (0 when ω is held constant or not solved).
  // ∂L/∂x̃ gains ŵ [ũ × λ + (λωᵀ + ωλᵀ − (2 + 4c_μ)(λ·ω) I) x̃] and ∂L/∂ũ gains ŵ λ × x̃ (E15).
  V l0 = zero, l1 = zero, l2 = zero;
  if (!p.detach_omega) {
    M.solve(z0, z1, z2, l0, l1, l2);
    l0 = lane_select(solved, l0, zero);
    l1 = lane_select(solved, l1, zero);
    l2 = lane_select(solved, l2, zero);
  }
  const V kappa = (L(2) + L(4) * p.mu_factor) * (l0 * o0 + l1 * o1 + l2 * o2);
  const V m00 = L(2) * l0 * o0 - kappa, m11 = L(2) * l1 * o1 - kappa,
          m22 = L(2) * l2 * o2 - kappa;
  const V m01 = l0 * o1 + o0 * l1, m02 = l0 * o2 + o0 * l2, m12 = l1 * o2 + o1 * l2;
  // Centring back (E15): ∂/∂x_k = ∂/∂x̃_k − ŵ_k Σ_m ∂/∂x̃_m, where the ŵ-linear parts sum to 0
  // (Σ ŵ x̃ = Σ ŵ ũ = 0), leaving ŵ_k Q and ŵ_k ω × Q.
  for (Index k = 0; k < K; ++k) {
    const V wk = w[k];
    const V p0 = r[k] - wk * Q0, p1 = r[K + k] - wk * Q1, p2 = r[2 * K + k] - wk * Q2;
    const V x0 = X[k], x1 = Y[k], x2 = Z[k];
    const V u0 = U0[k], u1 = U1[k], u2 = U2[k];
    gu[k] = p0 + wk * (l1 * x2 - l2 * x1);
    gu[K + k] = p1 + wk * (l2 * x0 - l0 * x2);
    gu[2 * K + k] = p2 + wk * (l0 * x1 - l1 * x0);
    gx[k] = (o1 * p2 - o2 * p1) + wk * (m00 * x0 + m01 * x1 + m02 * x2 + (u1 * l2 - u2 * l1));
    gx[K + k] =
        (o2 * p0 - o0 * p2) + wk * (m01 * x0 + m11 * x1 + m12 * x2 + (u2 * l0 - u0 * l2));
    gx[2 * K + k] =
        (o0 * p1 - o1 * p0) + wk * (m02 * x0 + m12 * x1 + m22 * x2 + (u0 * l1 - u1 * l0));
  }
  return energy;
}

// Lanes of the fast kernel: one SIMD register of the target (16 bytes with SSE, 32 with AVX),
// so that no lane value is wider than the ABI's vector registers. They follow __AVX__, hence the
// ISA-specific namespace (smg/core/config.hpp), as has lrm() below, which uses them.
inline namespace SMG_ISA_NAMESPACE {
template <class S>
constexpr int lrm_lanes() {
#if defined(__AVX__)
  return static_cast<int>(32 / sizeof(S));
#else
  return static_cast<int>(16 / sizeof(S));
#endif
}
template <class S>
using LrmLane = Lanes<S, lrm_lanes<S>()>;
}  // inline namespace SMG_ISA_NAMESPACE

}  // namespace detail

namespace detail {
// Lane v (W scalars) from / to memory; W = 1 for scalar lanes.
template <class V, class S>
SMG_LANE_INLINE void lane_load(V& v, const S* p) {
  if constexpr (LaneTraits<V>::is_lanes) {
    std::memcpy(&v, p, sizeof(V));
  } else {
    v = *p;
  }
}
template <class V, class S>
SMG_LANE_INLINE void lane_store(const V& v, S* p) {
  if constexpr (LaneTraits<V>::is_lanes) {
    std::memcpy(p, &v, sizeof(V));
  } else {
    *p = v;
  }
}
template <class V, class S>
SMG_LANE_INLINE S& lane_ref(V& v, Index l) {
  if constexpr (LaneTraits<V>::is_lanes) {
    return v[static_cast<int>(l)];
  } else {
    (void)l;
    return v;
  }
}
}  // namespace detail

inline namespace SMG_ISA_NAMESPACE {

// LRM energy (E14), returned in Accumulator<S> (double for float). When given, adds the
// gradient w.r.t. positions to grad_positions [T][N][3] (E15-E16) and writes the local angular
// velocities ω_i^t (radians per frame, world frame) into omega [T][N][3]. confidence [T][N] may
// be empty (all 1). Precondition: validate_lrm.
//
// Layout: the lanes of the SIMD kernel are W consecutive frames of one node (its neighbour set
// does not change with t). Inputs are first copied into frame-blocked node records
// [T/W][N][3][W] so that a neighbour's positions, velocities and confidences over the W frames
// are single vector loads, and gradients go to the same layout, owned by the frame block; a
// last pass adds them to the caller's [T][N][3] rows.
template <class S, class I>
Accumulator<S> lrm(detail::NonDeducedT<PositionsView<const S>> positions,
                   detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                   const NeighborsView<S, I>& graph, const LrmOptions& options,
                   PositionsView<S> grad_positions = {}, EnergyWorkspace<S>* workspace = nullptr,
                   ParallelOptions parallel = {}, TangentsView<S> omega = {}) {
  using L = Literal<S>;
  using Acc = Accumulator<S>;
  // W frames at once for float/double; one at a time for other scalars (autodiff).
  using V = std::conditional_t<std::is_floating_point_v<S>, detail::LrmLane<S>, S>;
  constexpr Index W = std::is_floating_point_v<S> ? detail::lrm_lanes<S>() : 1;
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  SMG_ASSERT(confidence.data() == nullptr || (confidence.frames() == T && confidence.nodes() == N),
             "lrm: confidence shape");
  SMG_ASSERT(graph.nodes() == N && graph.weights.rows() == N && graph.weights.cols() == K,
             "lrm: graph shape");
  SMG_ASSERT(grad_positions.data() == nullptr ||
                 (grad_positions.frames() == T && grad_positions.nodes() == N),
             "lrm: grad_positions shape");
  SMG_ASSERT(omega.data() == nullptr || (omega.frames() == T && omega.nodes() == N),
             "lrm: omega shape");
  if (T == 0 || N == 0 || K == 0) return Acc(0);
  double scale = options.weight;
  if (options.normalization == Normalization::mean) {
    const Index terms = lrm_term_count(graph, T);
    if (terms == 0) return Acc(0);
    scale /= static_cast<double>(terms);
  }
  const L s_scale(scale);
  detail::LrmParams<S> p;
  p.huber_delta = L(options.huber_delta);
  p.mu_factor = lrm_mu_factor<S>();
  p.detach_omega = options.detach_omega;
  p.gradient = grad_positions.data() != nullptr;
  const L alpha(options.alpha);
  const bool want_omega = omega.data() != nullptr;

  const Index blocks = (T + W - 1) / W;
  const Index rec = 3 * W;  // scalars of one node's 3-vector record in a block
  detail::WorkspaceRef<S> ws(workspace);
  // [blocks][N][3][W] positions and velocities, [blocks][N][W] confidences, and (gradient)
  // [blocks][N][3][W] for ∂L/∂x and ∂L/∂u.
  S* xb = ws->velocity(static_cast<std::size_t>(2 * blocks * N * rec + blocks * N * W));
  S* ub = xb + blocks * N * rec;
  S* cb = ub + blocks * N * rec;
  S* gb = p.gradient ? ws->velocity_grad(static_cast<std::size_t>(2 * blocks * N * rec)) : nullptr;
  S* gub = gb ? gb + blocks * N * rec : nullptr;

  ParallelOptions po = parallel;
  po.grain = 1;
  // Transpose into the blocked layout (E1 for the velocities). Lanes past T − 1 repeat the last
  // frame; their weight is 0 below, so they add nothing.
  parallel_for_chunks(
      blocks,
      [&](Index b, Index, Index) {
        for (Index l = 0; l < W; ++l) {
          const Index t = std::min(T - 1, b * W + l);
          const VelocityFrames vf = velocity_frames(t, T);
          const S* xr = positions.ptr(t, 0);
          const S* pr = positions.ptr(vf.plus, 0);
          const S* mr = positions.ptr(vf.minus, 0);
          const S* cr = confidence.data() ? confidence.ptr(t, 0) : nullptr;
          S* xd = xb + b * N * rec + l;
          S* ud = ub + b * N * rec + l;
          S* cd = cb + b * N * W + l;
          for (Index j = 0; j < N; ++j) {
            for (int c = 0; c < 3; ++c) {
              xd[j * rec + c * W] = xr[3 * j + c];
              ud[j * rec + c * W] = vf.moving ? pr[3 * j + c] - mr[3 * j + c] : S(0);
            }
            cd[j * W] = cr ? cr[j] : S(1);
          }
        }
      },
      po);

  std::vector<Acc> partial(static_cast<std::size_t>(blocks), Acc(0));
  parallel_for_chunks(
      blocks,
      [&](Index b, Index, Index) {
        // Per-chunk lane scratch (a few KB): x, u, a, gx, gu, ω and the neighbourhood scratch.
        std::vector<V> lanes(static_cast<std::size_t>((13 + detail::lrm_scratch_size(1)) * K + 3));
        V* xs = lanes.data();
        V* us = xs + 3 * K;
        V* a = us + 3 * K;
        V* gx = a + K;
        V* gu = gx + 3 * K;
        V* om = gu + 3 * K;
        V* nb_scratch = om + 3;
        const Index t0 = b * W, nl = std::min(W, T - t0);
        V valid;  // 1 for frames < T, 0 for padding lanes
        for (Index l = 0; l < W; ++l) detail::lane_ref<V, S>(valid, l) = l < nl ? S(1) : S(0);
        const S* xblk = xb + b * N * rec;
        const S* ublk = ub + b * N * rec;
        const S* cblk = cb + b * N * W;
        S* gblk = gb ? gb + b * N * rec : nullptr;
        S* gublk = gub ? gub + b * N * rec : nullptr;
        if (gblk) {
          std::fill(gblk, gblk + N * rec, S(0));
          std::fill(gublk, gublk + N * rec, S(0));
        }
        Acc e(0);
        for (Index i = 0; i < N; ++i) {
          const I* idx = graph.indices.ptr(i);
          const S* wrow = graph.weights.ptr(i);
          for (Index k = 0; k < K; ++k) {
            const Index j = idx[k] >= 0 ? idx[k] : i;  // padding: own record, weight 0
            for (int c = 0; c < 3; ++c) {
              detail::lane_load(xs[c * K + k], xblk + j * rec + c * W);
              detail::lane_load(us[c * K + k], ublk + j * rec + c * W);
            }
            V cj;
            detail::lane_load(cj, cblk + j * W);
            const S wk = idx[k] >= 0 ? wrow[k] : S(0);
            a[k] = confidence_edge_weight(V(wk * valid), alpha, cj);
          }
          V ev = detail::lrm_neighborhood<V, S>(K, xs, us, a, p, nb_scratch, gx, gu, om);
          for (Index l = 0; l < nl; ++l) e += Acc(detail::lane_ref<V, S>(ev, l));
          if (want_omega)
            for (Index l = 0; l < nl; ++l)
              for (int c = 0; c < 3; ++c) omega(t0 + l, i)(c) = detail::lane_ref<V, S>(om[c], l);
          if (!p.gradient) continue;
          for (Index k = 0; k < K; ++k) {
            const Index j = idx[k];
            if (j < 0) break;
            for (int c = 0; c < 3; ++c) {
              V acc;
              S* dst = gblk + j * rec + c * W;
              detail::lane_load(acc, dst);
              acc += s_scale * gx[c * K + k];
              detail::lane_store(acc, dst);
              dst = gublk + j * rec + c * W;
              detail::lane_load(acc, dst);
              acc += s_scale * gu[c * K + k];
              detail::lane_store(acc, dst);
            }
          }
        }
        partial[static_cast<std::size_t>(b)] = e;
      },
      po);
  Acc energy(0);
  for (const Acc& v : partial) energy += v;
  energy *= Acc(scale);

  if (p.gradient) {
    // ∂L/∂x^s from its block, plus the velocity parts: u^t = x^{t+1} − x^t (t < T − 1) and
    // u^{T−1} = x^{T−1} − x^{T−2} (E1, E16).
    auto at = [&](const S* base, Index t, Index j, int c) {
      return base[(t / W) * N * rec + j * rec + c * W + (t % W)];
    };
    parallel_for(
        T,
        [&](Index begin, Index end) {
          for (Index s = begin; s < end; ++s) {
            S* dst = grad_positions.ptr(s, 0);
            for (Index j = 0; j < N; ++j)
              for (int c = 0; c < 3; ++c) {
                S v = dst[3 * j + c] + at(gb, s, j, c);
                if (T >= 2) {
                  if (s >= 1) v += at(gub, s - 1, j, c);
                  if (s < T - 1) v -= at(gub, s, j, c);
                  if (s == T - 1) v += at(gub, T - 1, j, c);
                  if (s == T - 2) v -= at(gub, T - 1, j, c);
                }
                dst[3 * j + c] = v;
              }
          }
        },
        parallel);
  }
  return energy;
}

}  // inline namespace SMG_ISA_NAMESPACE

}  // namespace smg
