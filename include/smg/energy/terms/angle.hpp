// smg/energy/terms/angle.hpp — the rotation-angle velocity or acceleration of node rotations, the
// regulariser MoSca puts on its motion bases' rotations (`compute_vel_acc`), as a term of the
// regulariser driver (energy/block.hpp has the concept; docs/math/terms/angle.md (E23)):
//   θ_i^t = the angle of R_i^{t+1} R_i^{tT} = 2 atan2(‖v‖, |w|), (w, v) = q_i^{t*} ⊗ q_i^{t+1}
//   velocity form      Θ = k Σ_i Σ_{t=0}^{T−2} w_i^t θ_i^t
//   acceleration form  Θ = k Σ_i Σ_{t=0}^{T−3} w_i^t |θ_i^{t+1} − θ_i^t|
// as written with penalty=norm (the default); squared and sqrt_weighted as (E22) on the scalar.
// with w_i^t = c_{t,i} (confidence-weighted, at the earliest frame) or 1, and k the weight
// (divided by the term count with Normalization::mean). Unsquared, as MoSca's defaults. The
// gradient goes to the rotations only (right tangent, or raw quaternions through (Q5)): with u
// the unit axis of q^{t*} ⊗ q^{t+1} (sign(w) v / ‖v‖, 0 at θ = 0 and at w = 0),
// ∂θ^t/∂φ^{t+1} = u, ∂θ^t/∂φ^t = −u; |·| has sub-gradient 0 at 0 (torch's conventions). Each
// term is indexed by its earliest frame, which the block owns; its later frames are in the
// block's overlap (reach 1 or 2) and reach the caller through the rotation spill.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>

#include "smg/core/rotation_gradient.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/options.hpp"

namespace smg {

// Rotation-angle velocity or acceleration of node rotations (E23, docs/math/terms/angle.md), as
// MoSca regularises its motion bases' rotations: θ_i^t, the angle of R_i^{t+1} R_i^{tT}, summed
// (velocity) or |θ_i^{t+1} − θ_i^t| summed (acceleration), unsquared, weighted by c_{t,i} at the
// earliest frame or by 1. The forms are AccelForm's.
struct AngleOptions {
  AccelForm form = AccelForm::acceleration;
  bool confidence_weighted = false;  // w = c_{t,i} (E6) at the earliest frame; else w = 1
  Normalization normalization = Normalization::sum;  // mean: over (T − 2) · N terms (or T − 1)
  double weight = 1.0;  // overall factor (units: 1 / radian, or 1 / radian² squared)
  // (E22) on the scalar θ (or Δθ): norm |·| (MoSca's, the default), squared (MoSca's
  // square=True), sqrt_weighted sqrt(w·² + ε).
  Penalty penalty = Penalty::norm;
  double penalty_eps = 1e-20;  // ε of sqrt_weighted (radian²), finite and > 0; read by it only
};

template <class O, class F, detail::IfOptions<O, AngleOptions> = 0>
void for_each_option(O& o, F&& f) {
  detail::for_each_trajectory_option(o, f);
}

inline Status validate_options(const AngleOptions& o) {
  return detail::check_trajectory_options("AngleOptions", o);
}

// Checks the arguments of angle(): rotations [T][N][4] (nonzero, normalised on entry);
// `confidence` [T][N] may be empty (all 1; read only with options.confidence_weighted), the
// gradient may be empty (not computed).
template <class S>
Status validate_angle(detail::NonDeducedT<QuaternionsView<const S>> rotations,
                      detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                      const AngleOptions& options,
                      detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  return detail::validate_rotation_term<S>(
      rotations, validate_optional_confidence<S>(confidence, rotations.frames(), rotations.nodes()),
      validate_options(options), grad_rotations);
}

// θ of (E23), the rotation angle of R_b R_aᵀ in [0, π], from the quaternions qa, qb (w, x, y, z;
// any nonzero norm: θ and u do not depend on it), and u (3 values) with ∂θ/∂φ_b = u, ∂θ/∂φ_a = −u
// for right-tangent perturbations R ← R Exp(φ). u = 0 where ‖v‖ = 0 (θ = 0) or w = 0 (θ = π, a
// kink of θ: torch's |w|' = sign(0) = 0 gives 0 there too).
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S rotation_angle(const S* qa, const S* qb, S* u) {
  using std::atan2;
  using std::sqrt;
  const S aw = qa[0], ax = qa[1], ay = qa[2], az = qa[3];
  const S bw = qb[0], bx = qb[1], by = qb[2], bz = qb[3];
  // s = qa* ⊗ qb (the relative rotation R_aᵀ R_b: the same angle as R_b R_aᵀ).
  const S w = aw * bw + ax * bx + ay * by + az * bz;
  const S vx = aw * bx - bw * ax - (ay * bz - az * by);
  const S vy = aw * by - bw * ay - (az * bx - ax * bz);
  const S vz = aw * bz - bw * az - (ax * by - ay * bx);
  const S n = sqrt(vx * vx + vy * vy + vz * vz);
  const S aw_abs = w < S(0) ? S(-w) : w;
  const S sg = w > S(0) ? S(1) : (w < S(0) ? S(-1) : S(0));
  const S f = n > S(0) ? S(sg / n) : S(0);
  u[0] = f * vx;
  u[1] = f * vy;
  u[2] = f * vz;
  return L(2) * atan2(n, aw_abs);
}

// One term of (E23) from its angles θ0 = θ^t and (acceleration) θ1 = θ^{t+1}, with factor k
// and weight w, under the penalty p (E22 on the scalar r = θ0, order 1, or θ1 − θ0, order 2):
// norm (the default, MoSca's) k w |r|, squared k w r², sqrt_weighted k sqrt(w r² + ε); returns
// it, and g0 = ∂/∂θ0, g1 = ∂/∂θ1 (norm: sub-gradient 0 at r = 0, torch's abs).
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE S angle_term(int order, Penalty p, S k, S w, S eps, S th0,
                                              S th1, S& g0, S& g1) {
  using std::sqrt;
  const S r = order == 1 ? th0 : S(th1 - th0);
  S e, h;  // the penalty and its derivative in r
  if (p == Penalty::squared) {
    const S f = k * w;
    e = f * r * r;
    h = S(2) * f * r;
  } else if (p == Penalty::sqrt_weighted) {
    const S q = sqrt(w * r * r + eps);  // >= sqrt(ε) > 0
    e = k * q;
    h = k * w * r / q;
  } else {
    const S f = k * w;
    h = r > S(0) ? f : (r < S(0) ? S(-f) : S(0));
    e = r < S(0) ? S(-f * r) : S(f * r);
  }
  if (order == 1) {
    g0 = h;
    g1 = S(0);
  } else {
    g0 = -h;
    g1 = h;
  }
  return e;
}

// The number of terms of (E23) over T frames and N nodes (Normalization::mean divides by it).
inline Index angle_term_count(const AngleOptions& o, Index frames, Index nodes) {
  const Index span = o.form == AccelForm::acceleration ? 2 : 1;
  return std::max<Index>(0, frames - span) * nodes;
}
inline bool angle_active(const AngleOptions& o, Index frames, Index nodes) {
  return angle_term_count(o, frames, nodes) > 0 && o.weight != 0.0;
}
inline double angle_scale(const AngleOptions& o, Index frames, Index nodes) {
  const Index terms = angle_term_count(o, frames, nodes);
  return o.normalization == Normalization::mean && terms > 0 ? o.weight / static_cast<double>(terms)
                                                             : o.weight;
}

// (E23) at frame t of node i, the one step both drivers run: the energy of the term whose
// earliest frame is t (when own_energy), and the right-tangent gradient of R_i^t from the terms
// containing frame t whose earliest frame u lies in [u_lo, u_hi) (the CPU block: its owned
// frames; the GPU: all), added to g[3]. q [T][N][4]; weight(u): w_i^u.
template <class S, class W>
SMG_FORCE_INLINE SMG_HOST_DEVICE void angle_at(Index t, Index i, QuaternionsView<const S> q,
                                               int order, Penalty penalty, Literal<S> k,
                                               Literal<S> eps, const W& weight, Index u_lo,
                                               Index u_hi, bool own_energy, S* g, S& energy) {
  using L = Literal<S>;
  const Index T = q.frames();
  for (Index u = t - order; u <= t; ++u) {
    if (u < 0 || u + order >= T || u < u_lo || u >= u_hi) continue;
    S a0[3], a1[3] = {S(0), S(0), S(0)};
    const S th0 = rotation_angle<S, L>(q.ptr(u, i), q.ptr(u + 1, i), a0);
    const S th1 = order == 2 ? rotation_angle<S, L>(q.ptr(u + 1, i), q.ptr(u + 2, i), a1) : S(0);
    S g0, g1;
    const S e = angle_term<S>(order, penalty, S(k), weight(u), S(eps), th0, th1, g0, g1);
    if (u == t && own_energy) energy += e;
    // θ^u = θ(u, u+1): −u_0 on frame u, +u_0 on u+1; θ^{u+1} = θ(u+1, u+2): −u_1 on u+1, +u_1 on
    // u+2.
    const Index p = t - u;
    const S m0 = p == 0 ? S(-g0) : (p == 1 ? g0 : S(0));
    const S m1 = p == 1 ? S(-g1) : (p == 2 ? g1 : S(0));
    for (int d = 0; d < 3; ++d) g[d] += m0 * a0[d] + m1 * a1[d];
  }
}

// (E23) as one element (frame t, node i) of the CUDA driver (cuda/driver.cuh): it reads the
// rotations and writes the rotation gradient (kReadsRotations), so its step also takes q
// [T][N][4] and the gradient rows grad_tangent [T][N][3] or grad_raw [T][N][4] (either or both
// null). conf [T][N] or null (c ≡ 1; read only when weighted). Host values: AngleTerm::element().
template <class S>
struct AngleElement {
  static constexpr bool kReadsRotations = true;
  Literal<S> k = Literal<S>(0);
  Literal<S> eps = Literal<S>(0);  // ε of sqrt_weighted
  bool weighted = false;
  int order = 2;  // 2: acceleration, 1: velocity
  Penalty penalty = Penalty::norm;

  struct Weight {
    const S* conf;
    Index N, i;
    SMG_HOST_DEVICE S operator()(Index u) const { return conf != nullptr ? conf[u * N + i] : S(1); }
  };

  bool reads_confidence() const { return weighted; }

  // The CPU element pass (energy/element_pass.hpp) evaluates each term once, term_at(), rather
  // than once per frame it touches, at(): a thread there owns all of node i's rows.
  static constexpr bool kWholeTerms = true;

  // The term with earliest frame u of node i, once: its energy into `energy` and the right-tangent
  // gradients of R_i^u … R_i^{u+order} (θ^u = θ(u, u+1): −u_0 on frame u, +u_0 on u+1; θ^{u+1}:
  // −u_1 on u+1, +u_1 on u+2), each added to its row (grad_tangent or grad_raw; either or both
  // null: no gradient).
  SMG_HOST_DEVICE void term_at(Index u, Index i, PositionsView<const S>, QuaternionsView<const S> q,
                               const S* conf, S*, S* grad_tangent, S* grad_raw, S& energy) const {
    using L = Literal<S>;
    const Index N = q.nodes();
    S a0[3], a1[3] = {S(0), S(0), S(0)};
    const S th0 = rotation_angle<S, L>(q.ptr(u, i), q.ptr(u + 1, i), a0);
    const S th1 = order == 2 ? rotation_angle<S, L>(q.ptr(u + 1, i), q.ptr(u + 2, i), a1) : S(0);
    S g0, g1;
    energy += angle_term<S>(order, penalty, S(k), Weight{weighted ? conf : nullptr, N, i}(u), S(eps),
                            th0, th1, g0, g1);
    if (grad_tangent == nullptr && grad_raw == nullptr) return;
    for (Index p = 0; p <= order; ++p) {
      const S m0 = p == 0 ? S(-g0) : (p == 1 ? g0 : S(0));
      const S m1 = p == 1 ? S(-g1) : (p == 2 ? g1 : S(0));
      S g[3];
      for (int d = 0; d < 3; ++d) g[d] = m0 * a0[d] + m1 * a1[d];
      add_rotation_gradient(q.ptr(u + p, i), (u + p) * N + i, g, grad_tangent, grad_raw);
    }
  }

  SMG_HOST_DEVICE void at(Index t, Index i, PositionsView<const S>, QuaternionsView<const S> q,
                          const S* conf, S*, S* grad_tangent, S* grad_raw, S& energy) const {
    const Index T = q.frames(), N = q.nodes();
    S g[3] = {S(0), S(0), S(0)};
    angle_at<S>(t, i, q, order, penalty, k, eps, Weight{weighted ? conf : nullptr, N, i},
                Index(0), T, true, g, energy);
    add_rotation_gradient(q.ptr(t, i), t * N + i, g, grad_tangent, grad_raw);
  }
};

namespace detail {

template <class S, class I>
struct AngleTerm : ScratchFreeRotationTerm, FormState {
  using L = Literal<S>;
  using Acc = Accumulator<S>;

  void configure(const AngleOptions& o, Index frames, Index nodes) {
    set_form(o, frames, angle_scale(o, frames, nodes), angle_active(o, frames, nodes));
  }

  // The list's entry "angle".
  template <class RO>
  void setup(const RO& o, const TermShape& s) {
    if (o.terms.angle) configure(o.angle, s.T, s.N);
    want_rotations = s.want_r;
  }

  bool on() const { return enabled; }
  Index reach() const { return order; }

  using Element = AngleElement<S>;
  Element element() const { return form_element<Element>(); }
  static Acc& energy_of(RegularizerResult<S>& r) { return r.angle; }

  // The block's weights: c of node i at the owned frame u (the record's c row).
  struct BlockWeight {
    const S* c;
    Index t0;
    bool weighted;
    SMG_HOST_DEVICE S operator()(Index u) const { return weighted ? c[u - t0] : S(1); }
  };

  // The terms of node i whose earliest frame the block owns; R_i's gradient of the block's
  // frames: owned ones into the caller's rows, the overlap into the block's rotation spill.
  template <class E>
  void node(const BlockView<S, I>& v, Block&, Index i, E& energy) const {
    const Index t0 = v.t0;
    const S* c = v.Xb + i * v.n4() + 3 * v.ne;
    const BlockWeight w{c, t0, weighted};
    const int ord = static_cast<int>(order);
    const Index u_hi = std::min(v.t1, T - order);
    if (u_hi <= t0) return;
    Acc e(0);
    // The overlap's frames only receive gradient.
    const Index frames = v.want_r ? v.nr : v.nown;
    for (Index l = 0; l < frames; ++l) {
      S g[3] = {S(0), S(0), S(0)};
      S el(0);
      angle_at<S>(t0 + l, i, v.q, ord, penalty, L(scale_d), L(eps_d), w, t0, u_hi, l < v.nown,
                  g, el);
      e += Acc(el);
      if (v.want_r) v.add_rotation(l, i, g);
    }
    energy.angle += e;
  }
};

}  // namespace detail
}  // namespace smg
