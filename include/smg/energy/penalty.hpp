// smg/energy/penalty.hpp — the penalties (E22) of a residual vector a, from its squared norm:
// the one place their arithmetic is written, for every term that puts a Penalty on a vector
// (the smoothness (E21) on 3-vectors, the relative-rotation term (E25) on 4-vectors). Host and
// device; no loops, no thread pool.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>

#include "smg/core/scalar.hpp"
#include "smg/core/types.hpp"
#include "smg/energy/options.hpp"  // Penalty

namespace smg {

// P(a) of (E22) from aa = ‖a‖² ≥ 0, the factor k (the term's weight, / the term count with
// Normalization::mean), the residual's weight w ≥ 0 and ε (the option's penalty_eps > 0); returns
// P and writes h with ∂P/∂a = h a:
//   squared        k w ‖a‖²             h = 2 k w
//   norm           k w ‖a‖              h = k w / ‖a‖, and 0 at a = 0 (torch's norm backward)
//   sqrt_weighted  k sqrt(w ‖a‖² + ε)   h = k w / sqrt(w ‖a‖² + ε)   (the weight inside the root)
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S penalty_of_square(Penalty p, S k, S w, S eps, S aa, S& h) {
  using std::sqrt;
  if (p == Penalty::norm) {
    const S f = k * w, n = sqrt(aa);
    h = n > S(0) ? S(f / n) : S(0);
    return f * n;
  }
  if (p == Penalty::sqrt_weighted) {
    const S r = sqrt(w * aa + eps);  // >= sqrt(ε) > 0
    h = k * w / r;
    return k * r;
  }
  const S f = k * w;
  h = L(2) * f;
  return f * aa;
}

namespace detail {
// What the trajectory terms (the smoothness E21, the rotation angle E23) keep of their options,
// formed on the host in double, and the copy their CUDA Elements take: the form's order (2:
// acceleration, 1: velocity), the penalty (E22) and its ε, the confidence weighting, the overall
// factor k (scale_d, / the term count with Normalization::mean), T, and whether it is on.
struct FormState {
  bool enabled = false, weighted = false;
  Index order = 2;
  Penalty penalty = Penalty::squared;
  double scale_d = 0, eps_d = 0;
  Index T = 0;

  template <class O>
  void set_form(const O& o, Index frames, double scale, bool active) {
    T = frames;
    order = o.form == AccelForm::acceleration ? 2 : 1;
    penalty = o.penalty;
    eps_d = o.penalty_eps;
    weighted = o.confidence_weighted;
    scale_d = scale;
    enabled = active;
  }
  template <class E>
  E form_element() const {
    E e;
    e.k = decltype(e.k)(scale_d);
    e.eps = decltype(e.eps)(eps_d);
    e.penalty = penalty;
    e.weighted = weighted;
    e.order = static_cast<int>(order);
    return e;
  }
};
}  // namespace detail

}  // namespace smg
