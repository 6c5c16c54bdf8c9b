// smg/energy/terms/accel.hpp — smoothness of node trajectories, the regulariser MoSca and
// Shape-of-Motion put on their motion bases, as a term of the regulariser driver
// (energy/block.hpp has the concept; docs/math/energy.md (E21)–(E22), the term and its penalties):
//   acceleration form  A = Σ_i Σ_{t=0}^{T−3} P(a_i^t),  a_i^t = x_i^{t+2} − 2 x_i^{t+1} + x_i^t
//   velocity form      A = Σ_i Σ_{t=0}^{T−2} P(v_i^t),  v_i^t = x_i^{t+1} − x_i^t
//   P(a) = k w ‖a‖² (squared, the default), k w ‖a‖ (norm), k sqrt(w ‖a‖² + ε) (sqrt_weighted)
// with w_i^t = c_{t,i} (confidence-weighted, taken at the earliest frame as (E7) takes it) or 1,
// and k the weight (divided by the term count with Normalization::mean). Each term is indexed by
// its earliest frame, which the block owns; its later frames are in the block's overlap (reach
// 2, or 1), so the driver's spill carries them. Confidences are constants (stop-gradient).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>

#include "smg/core/scalar.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/penalty.hpp"

namespace smg {

// Smoothness of node trajectories (E21), as MoSca and Shape-of-Motion regularise their motion:
// the second differences x^{t+2} − 2x^{t+1} + x^t (acceleration) or first differences
// (velocity) of every node, weighted by c_{t,i} at the earliest frame or by 1, under a penalty
// (E22): squared by default, or the unsquared norm, or D3DGS's sqrt(w‖a‖² + ε).
struct AccelOptions {
  AccelForm form = AccelForm::acceleration;
  Penalty penalty = Penalty::squared;  // (E22)
  bool confidence_weighted = false;  // w = c_{t,i} (E6) at the earliest frame; else w = 1
  Normalization normalization = Normalization::sum;  // mean: over (T − 2) · N terms (or T − 1)
  double weight = 1.0;  // overall factor (units: 1 / length² squared, 1 / length otherwise)
  double penalty_eps = 1e-20;  // ε of sqrt_weighted (length²), finite and > 0; read by it only
};

template <class O, class F, detail::IfOptions<O, AccelOptions> = 0>
void for_each_option(O& o, F&& f) {
  detail::for_each_trajectory_option(o, f);
}

inline Status validate_options(const AccelOptions& o) {
  return detail::check_trajectory_options("AccelOptions", o);
}

// Checks the arguments of accel(): `confidence` [T][N] may be empty (all 1; read only with
// options.confidence_weighted), the gradient may be empty (not computed).
template <class S>
Status validate_accel(detail::NonDeducedT<PositionsView<const S>> positions,
                      detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                      const AccelOptions& options, PositionsView<S> grad_positions = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  return detail::first_error({validate_positions<S>(positions, -1, -1, "positions"),
                              validate_optional_confidence<S>(confidence, T, N),
                              validate_options(options),
                              validate_optional_output(grad_positions, T, N, "grad_positions")});
}

// The penalty (E22) of one term of (E21): the difference a (3 values) of frames t, t+1[, t+2],
// the factor k (the weight, / the term count with Normalization::mean), the term's weight w (its
// confidence, or 1) and ε (AccelOptions::penalty_eps); returns P(a) and writes g = ∂P/∂a:
//   squared        k w ‖a‖²             g = 2 k w a
//   norm           k w ‖a‖              g = k w a / ‖a‖, and 0 at a = 0 (torch's norm backward)
//   sqrt_weighted  k sqrt(w ‖a‖² + ε)   g = k w a / sqrt(w ‖a‖² + ε)
// The frames' gradients are g·(1, −2, 1) (acceleration) or g·(−1, 1) (velocity). CPU
// (AccelTerm::node) and CUDA (AccelElement::at) both evaluate the term through this function.
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S accel_penalty(Penalty p, S k, S w, S eps, S ax, S ay,
                                                 S az, S& gx, S& gy, S& gz) {
  S h;
  const S e = penalty_of_square<S, L>(p, k, w, eps, ax * ax + ay * ay + az * az, h);
  gx = h * ax;
  gy = h * ay;
  gz = h * az;
  return e;
}

// The number of terms of (E21) over T frames and N nodes (Normalization::mean divides by it).
inline Index accel_term_count(const AccelOptions& o, Index frames, Index nodes) {
  const Index span = o.form == AccelForm::acceleration ? 2 : 1;
  return std::max<Index>(0, frames - span) * nodes;
}

// The term's difference along one coordinate from the frames' values x0, x1[, x2] (order 2:
// x2 − 2 x1 + x0, acceleration; order 1: x1 − x0, velocity).
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S accel_difference(int order, S x0, S x1, S x2) {
  return order == 2 ? S(x2 - L(2) * x1 + x0) : S(x1 - x0);
}

// Whether (E21) contributes anything over T frames and N nodes (a term exists, the weight is not
// 0), and k, the factor of every term: the weight, / accel_term_count with Normalization::mean.
inline bool accel_active(const AccelOptions& o, Index frames, Index nodes) {
  return accel_term_count(o, frames, nodes) > 0 && o.weight != 0.0;
}
inline double accel_scale(const AccelOptions& o, Index frames, Index nodes) {
  const Index terms = accel_term_count(o, frames, nodes);
  return o.normalization == Normalization::mean && terms > 0 ? o.weight / static_cast<double>(terms)
                                                             : o.weight;
}

// (E21) with its penalty (E22) as one element (frame t, node i) of the CUDA driver (cuda/driver.cuh), a step without
// scratch that a kernel thread or a host loop runs: the energy of the term whose earliest frame
// is t into `energy`, and the gradient of x_i^t from every term containing frame t (earliest
// frames t − order … t, in that order) added to grad_x [T][N][3] when not null. x [T][N][3]; conf
// [T][N] or null (c ≡ 1; read only when weighted). Host values: AccelTerm::element().
template <class S>
struct AccelElement {
  Literal<S> k = Literal<S>(0);  // the weight, / the number of terms with Normalization::mean
  Literal<S> eps = Literal<S>(0);  // ε of sqrt_weighted
  bool weighted = false;
  int order = 2;  // 2: acceleration, 1: velocity
  Penalty penalty = Penalty::squared;

  // The difference a of the term with earliest frame u.
  SMG_HOST_DEVICE void difference(PositionsView<const S> x, Index u, Index i, S* a) const {
    const S* r0 = x.ptr(u, i);
    const S* r1 = x.ptr(u + 1, i);
    const S* r2 = order == 2 ? x.ptr(u + 2, i) : r1;
    for (int d = 0; d < 3; ++d) a[d] = accel_difference<S, Literal<S>>(order, r0[d], r1[d], r2[d]);
  }

  bool reads_confidence() const { return weighted; }

  // The CPU element pass (energy/element_pass.hpp) evaluates each term once, term_at(), rather
  // than once per frame it touches, at(): a thread there owns all of node i's rows.
  static constexpr bool kWholeTerms = true;

  // The term with earliest frame u of node i, once: its energy into `energy` and its gradient,
  // g·(1, −2, 1) or g·(−1, 1), added to node i's rows u … u + order of grad_x when not null.
  SMG_HOST_DEVICE void term_at(Index u, Index i, PositionsView<const S> x, const S* conf, S* grad_x,
                               S& energy) const {
    const Index N = x.nodes();
    const S w = weighted && conf != nullptr ? S(conf[u * N + i]) : S(1);
    S a[3], ga[3];
    difference(x, u, i, a);
    energy += accel_penalty<S, Literal<S>>(penalty, S(k), w, S(eps), a[0], a[1], a[2], ga[0], ga[1],
                                           ga[2]);
    if (grad_x == nullptr) return;
    for (Index p = 0; p <= order; ++p) {
      const S m = order == 2 ? (p == 1 ? S(-2) : S(1)) : (p == 0 ? S(-1) : S(1));
      S* row = grad_x + ((u + p) * N + i) * 3;
      for (int d = 0; d < 3; ++d) row[d] += m * ga[d];
    }
  }

  SMG_HOST_DEVICE void at(Index t, Index i, PositionsView<const S> x, const S* conf, S* grad_x,
                          S& energy) const {
    const Index T = x.frames(), N = x.nodes();
    S g[3] = {S(0), S(0), S(0)};
    for (Index u = t - order; u <= t; ++u) {
      if (u < 0 || u + order >= T) continue;
      // Without a gradient only the term frame t owns counts (the others are their frames').
      if (grad_x == nullptr && u != t) continue;
      const S w = weighted && conf != nullptr ? S(conf[u * N + i]) : S(1);
      S a[3], ga[3];
      difference(x, u, i, a);
      const S ev = accel_penalty<S, Literal<S>>(penalty, S(k), w, S(eps), a[0], a[1], a[2], ga[0],
                                                ga[1], ga[2]);
      if (u == t) energy += ev;
      // ∂a/∂x^t: (1, −2, 1) or (−1, 1) by the position of t in the term.
      const Index p = t - u;
      const S m = order == 2 ? (p == 1 ? S(-2) : S(1)) : (p == 0 ? S(-1) : S(1));
      for (int d = 0; d < 3; ++d) g[d] += m * ga[d];
    }
    if (grad_x != nullptr)
      for (int d = 0; d < 3; ++d) grad_x[(t * N + i) * 3 + d] += g[d];
  }
};

namespace detail {

template <class S, class I>
struct AccelTerm : ScratchFreeTerm, FormState {
  using L = Literal<S>;
  using Acc = Accumulator<S>;

  void configure(const AccelOptions& o, Index frames, Index nodes) {
    set_form(o, frames, accel_scale(o, frames, nodes), accel_active(o, frames, nodes));
  }

  // The list's entry "accel".
  template <class RO>
  void setup(const RO& o, const TermShape& s) {
    if (o.terms.accel) configure(o.accel, s.T, s.N);
  }

  bool on() const { return enabled; }
  Index reach() const { return order; }

  // The CUDA driver's element pass (cuda/driver.cuh) runs this term as its per-(frame, node)
  // step, configured as above (the scale formed on the host, in double, as node() forms it).
  using Element = AccelElement<S>;
  Element element() const { return form_element<Element>(); }
  static Acc& energy_of(RegularizerResult<S>& r) { return r.accel; }

  // The terms of node i whose earliest frame the block owns; the gradient into the block's rows.
  // The penalty is a template argument of the loop (one branch per node, not per term).
  template <class E>
  void node(const BlockView<S, I>& v, Block& b, Index i, E& energy) const {
    switch (penalty) {
      case Penalty::norm: return node_with<Penalty::norm>(v, b, i, energy);
      case Penalty::sqrt_weighted: return node_with<Penalty::sqrt_weighted>(v, b, i, energy);
      case Penalty::squared: break;
    }
    node_with<Penalty::squared>(v, b, i, energy);
  }

  template <Penalty P, class E>
  void node_with(const BlockView<S, I>& v, Block&, Index i, E& energy) const {
    const Index ne = v.ne, last = std::min(v.nown, T - order - v.t0);
    const S* X = v.Xb + i * v.n4();
    const S* c = X + 3 * ne;
    S* G = v.GBx ? v.GBx + i * v.n3() : nullptr;
    const S k = S(L(scale_d)), eps = S(L(eps_d));
    Acc e(0);
    for (Index l = 0; l < last; ++l) {
      S a[3];
      for (int d = 0; d < 3; ++d) {
        const S* r = X + d * ne + l;
        a[d] = accel_difference<S, L>(static_cast<int>(order), r[0], r[1],
                                      order == 2 ? r[2] : r[1]);
      }
      S g[3];
      e += Acc(accel_penalty<S, L>(P, k, weighted ? c[l] : S(1), eps, a[0], a[1], a[2], g[0], g[1],
                                   g[2]));
      if (!G) continue;
      for (int d = 0; d < 3; ++d) {
        S* r = G + d * ne + l;
        if (order == 2) {
          r[0] += g[d];
          r[1] -= L(2) * g[d];
          r[2] += g[d];
        } else {
          r[0] -= g[d];
          r[1] += g[d];
        }
      }
    }
    energy.accel += e;
  }
};

}  // namespace detail
}  // namespace smg
