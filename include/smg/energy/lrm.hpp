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
// Evaluation: the regulariser driver (energy/driver.hpp) with the LRM term alone
// (energy/terms/lrm.hpp): frames in blocks, each node's W consecutive frames in one SIMD lane
// group. Bit-identical for any thread count.
#pragma once

#include "smg/core/config.hpp"

#include "smg/energy/one_term.hpp"
#include "smg/energy/terms/lrm.hpp"

namespace smg {

// Number of terms of (E14): T · Σ_i |N(i)|. Normalization::mean divides by this.
template <class S, class I>
inline Index lrm_term_count(const NeighborsView<S, I>& graph, Index frames) {
  return frames * edge_count(graph);
}

inline namespace SMG_ISA_NAMESPACE {

// LRM energy (E14), returned in Accumulator<S> (double for float). When given, adds the
// gradient w.r.t. positions to grad_positions [T][N][3] (E15-E16) and writes the local angular
// velocities ω_i^t (radians per frame, world frame) into omega [T][N][3]. confidence [T][N] may
// be empty (all 1). Precondition: validate_lrm.
// ω is written for every frame, also where the energy's gradient is not asked for.
template <class S, class I>
Accumulator<S> lrm(detail::NonDeducedT<PositionsView<const S>> positions,
                   detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                   const NeighborsView<S, I>& graph, const LrmOptions& options,
                   PositionsView<S> grad_positions = {}, EnergyWorkspace<S>* workspace = nullptr,
                   ParallelOptions parallel = {}, TangentsView<S> omega = {}) {
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  SMG_ASSERT(detail::graph_operator_shapes(confidence, graph, grad_positions, T, N),
             "lrm: confidence, graph or grad_positions shape");
  SMG_ASSERT(detail::absent_or_shape(omega, T, N), "lrm: omega shape");
  if (T == 0 || N == 0 || K == 0) return Accumulator<S>(0);
  // One term of the driver: LRM alone, with the caller's confidences (or 1).
  detail::LrmTerm<S, I> term;
  term.configure(options, T, K, edge_count(graph), grad_positions.data() != nullptr);
  term.omega = omega;
  if (!term.on()) return Accumulator<S>(0);
  return detail::drive_one_term<S, I>(positions, QuaternionsView<const S>(), confidence, graph,
                                      grad_positions, RotationGradientView<S>(), workspace,
                                      parallel, term)
      .lrm;
}

}  // inline namespace SMG_ISA_NAMESPACE

}  // namespace smg
