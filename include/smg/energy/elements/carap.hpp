// smg/energy/elements/carap.hpp — one term of C-ARAP (E9), written once for every place that
// evaluates it: the vectorised energy kernel (carap.hpp), the residual form
// (carap_residuals.hpp) and, later, GPU kernels; its edge weight (E7) is confidence_edge_weight
// in common.hpp. Plain functions of scalars, forced inline so that the kernel's loops still
// vectorise around them.
// (tests/energy/reference_energies.hpp re-derives the same equations independently, by design:
// a reference must not share code with what it checks.)
#pragma once

#include "smg/core/config.hpp"

#include <cmath>

#include "smg/energy/options.hpp"  // Penalty

namespace smg {

// The rotated edge vector d = Rᵀ e of e = x_j − x_i (E8); R is row-major 3x3.
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE void carap_edge_vector(const S* R, S ex, S ey, S ez, S& dx,
                                                        S& dy, S& dz) {
  dx = R[0] * ex + R[3] * ey + R[6] * ez;
  dy = R[1] * ex + R[4] * ey + R[7] * ez;
  dz = R[2] * ex + R[5] * ey + R[8] * ez;
}

// Back from ∂E/∂d = G and ∂E/∂‖e‖ = H of one edge at one frame to its variables (E10):
// F = R G + (H/‖e‖) e is ∂E/∂x_j (and −F is ∂E/∂x_i), G × d is the right-tangent gradient of R_i.
// inv_len = 1/‖e‖, or 0 at e = 0 (pinned: the derivative of ‖d‖ at d = 0 is taken as 0).
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE void carap_edge_backprop(const S* R, S gx, S gy, S gz, S h,
                                                          S inv_len, S ex, S ey, S ez, S dx,
                                                          S dy, S dz, S& fx, S& fy, S& fz,
                                                          S& rx, S& ry, S& rz) {
  const S s = h * inv_len;
  rx = gy * dz - gz * dy;
  ry = gz * dx - gx * dz;
  rz = gx * dy - gy * dx;
  fx = R[0] * gx + R[1] * gy + R[2] * gz + s * ex;
  fy = R[3] * gx + R[4] * gy + R[5] * gz + s * ey;
  fz = R[6] * gx + R[7] * gy + R[8] * gz + s * ez;
}

// The C-ARAP term of one edge and one pair of frames (t, s = t + δ) given the change of the
// rotated edge vector Δd = d^s − d^t (E8) and of its length Δℓ = ‖d^s‖ − ‖d^t‖, with the pair
// factor k = γ_δ · w̃_ij^t (times the energy's overall scale):
//   E = k (λc ‖Δd‖² + λl Δℓ²)                                                        (E9)
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S carap_term_energy(S k, S dx, S dy, S dz, S dl, L lambda_c, L lambda_l) {
  return k * (lambda_c * (dx * dx + dy * dy + dz * dz) + lambda_l * dl * dl);
}

// The same term and its partial derivatives (E10): P = ∂E/∂d^s = −∂E/∂d^t = 2 k λc Δd and
// Q = ∂E/∂‖d^s‖ = −∂E/∂‖d^t‖ = 2 k λl Δℓ. Returns E.
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S carap_term(S k, S dx, S dy, S dz, S dl, L lambda_c, L lambda_l, S& px, S& py,
                              S& pz, S& q) {
  const S f = L(2) * lambda_c * k;
  px = f * dx;
  py = f * dy;
  pz = f * dz;
  q = L(2) * lambda_l * k * dl;
  return carap_term_energy(k, dx, dy, dz, dl, lambda_c, lambda_l);
}

// The same term with each part under a penalty other than `squared` (E24, E22), given the gap
// factor m = γ_δ (times the energy's scale) and the edge weight w = w̃_ij^t apart, since
// sqrt_weighted puts w inside the root and leaves m and λ outside:
//   norm           m w (λc ‖Δd‖ + λl |Δℓ|)
//   sqrt_weighted  m (λc sqrt(w ‖Δd‖² + ε) + λl sqrt(w Δℓ² + ε)), a part with λ = 0 left out
// and P = ∂E/∂d^s, Q = ∂E/∂‖d^s‖ as carap_term's. norm's sub-gradients at Δd = 0 and Δℓ = 0
// are 0, as torch's norm and abs give. `squared` is carap_term(m w, ...), kept apart so that its
// arithmetic (and so every default result) stays what it was.
// The roots come in precomputed (carap_penalty_root_args, then a square root): the CPU loops
// take them from a vectorised sqrt over the whole block; carap_term_penalty below, one term.
// rc = ‖Δd‖ (norm) or sqrt(w ‖Δd‖² + ε), rl = sqrt(w Δℓ² + ε) (sqrt_weighted; unread by norm).
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S carap_term_penalty_roots(Penalty p, S m, S w, S dx, S dy, S dz,
                                                            S dl, S rc, S rl, L lambda_c,
                                                            L lambda_l, S& px, S& py, S& pz,
                                                            S& q) {
  // Plain selects only (each operand computed, then chosen), so that the CPU loops vectorise.
  S e, hc;
  if (p == Penalty::norm) {
    const S fc = m * w * lambda_c, fl = m * w * lambda_l;
    // fc/‖Δd‖, and 0 at Δd = 0: the divisor made 1 there and the quotient masked, by arithmetic
    // on the comparisons rather than selects (GCC, which keeps float traps, does not vectorise
    // a division fed by a select).
    const S zero = S(rc <= S(0)), nonzero = S(1) - zero;
    hc = fc / (rc + zero) * nonzero;
    const S sign = S(dl > S(0)) - S(dl < S(0));  // sign(Δℓ), 0 at 0
    e = fc * rc + fl * (sign * dl);
    q = fl * sign;
  } else {
    // rc, rl >= sqrt(ε) > 0; with λ = 0 a part's factor is 0, so it adds exactly nothing.
    const S fc = m * lambda_c, fl = m * lambda_l;
    e = fc * rc + fl * rl;
    hc = fc * w / rc;
    q = fl * w * dl / rl;
  }
  px = hc * dx;
  py = hc * dy;
  pz = hc * dz;
  return e;
}

// The arguments of the two roots of carap_term_penalty_roots: ‖Δd‖² (norm) or w ‖Δd‖² + ε, and
// w Δℓ² + ε.
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE void carap_penalty_root_args(Penalty p, S w, S eps, S dx, S dy,
                                                              S dz, S dl, S& ac, S& al) {
  const S cc = dx * dx + dy * dy + dz * dz;
  ac = p == Penalty::norm ? cc : S(w * cc + eps);
  al = w * dl * dl + eps;
}

// One term with its roots taken here (the CUDA element, tests). Returns E.
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S carap_term_penalty(Penalty p, S m, S w, S eps, S dx, S dy, S dz,
                                                      S dl, L lambda_c, L lambda_l, S& px, S& py,
                                                      S& pz, S& q) {
  using std::sqrt;
  S ac, al;
  carap_penalty_root_args(p, w, eps, dx, dy, dz, dl, ac, al);
  return carap_term_penalty_roots(p, m, w, dx, dy, dz, dl, S(sqrt(ac)), S(sqrt(al)), lambda_c,
                                  lambda_l, px, py, pz, q);
}

// The same term as a residual r = [√(k λc) Δd ; √(k λl) Δℓ] with ‖r‖² = E (E17); sc = √(k λc)
// and sl = √(k λl) are returned for the Jacobians.
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE void carap_term_residual(S k, S dx, S dy, S dz, S dl, L lambda_c, L lambda_l,
                                          S* r, S& sc, S& sl) {
  using std::sqrt;
  sc = sqrt(k * lambda_c);
  sl = sqrt(k * lambda_l);
  r[0] = sc * dx;
  r[1] = sc * dy;
  r[2] = sc * dz;
  r[3] = sl * dl;
}

}  // namespace smg
