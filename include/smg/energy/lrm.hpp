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
#include <type_traits>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/lrm_term.hpp"
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
  if (Status s = validate_optional_output(grad_positions, T, N, "grad_positions"); !s) return s;
  if (Status s = validate_optional_output(omega, T, N, "omega"); !s) return s;
  return Status::ok();
}

// Number of terms of (E14): T · Σ_i |N(i)|. Normalization::mean divides by this.
template <class S, class I>
inline Index lrm_term_count(const NeighborsView<S, I>& graph, Index frames) {
  return frames * edge_count(graph);
}

namespace detail {

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
  const detail::LrmParams<S> p = detail::lrm_params<S>(options, grad_positions.data() != nullptr);
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
