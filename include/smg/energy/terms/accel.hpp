// smg/energy/terms/accel.hpp — smoothness of node trajectories, the regulariser MoSca and
// Shape-of-Motion put on their motion bases, as a term of the regulariser driver
// (energy/block.hpp has the concept; docs/math/energy.md (E21)):
//   acceleration form  A = k Σ_i Σ_{t=0}^{T−3} w_i^t ‖x_i^{t+2} − 2 x_i^{t+1} + x_i^t‖²
//   velocity form      A = k Σ_i Σ_{t=0}^{T−2} w_i^t ‖x_i^{t+1} − x_i^t‖²
// with w_i^t = c_{t,i} (confidence-weighted, taken at the earliest frame as (E7) takes it) or 1,
// and k the weight (divided by the term count with Normalization::mean). Each term is indexed by
// its earliest frame, which the block owns; its later frames are in the block's overlap (reach
// 2, or 1), so the driver's spill carries them. Confidences are constants (stop-gradient).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>

#include "smg/core/scalar.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/options.hpp"

namespace smg {

// One term of (E21): the difference a (3 values) of frames t, t+1[, t+2] and its factor
// f = k w; returns f ‖a‖² and writes g = ∂/∂a = 2 f a. The frames' gradients are g·(1, −2, 1)
// (acceleration) or g·(−1, 1) (velocity).
template <class S, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE S accel_term(S f, S ax, S ay, S az, S& gx, S& gy, S& gz) {
  const S h = L(2) * f;
  gx = h * ax;
  gy = h * ay;
  gz = h * az;
  return f * (ax * ax + ay * ay + az * az);
}

// The number of terms of (E21) over T frames and N nodes (Normalization::mean divides by it).
inline Index accel_term_count(const AccelOptions& o, Index frames, Index nodes) {
  const Index span = o.form == AccelForm::acceleration ? 2 : 1;
  return std::max<Index>(0, frames - span) * nodes;
}

namespace detail {

template <class S, class I>
struct AccelTerm : TermDefaults {
  using L = Literal<S>;
  using Acc = Accumulator<S>;

  bool enabled = false, weighted = false;
  Index order = 2;  // 2: acceleration, 1: velocity
  double scale_d = 0;
  Index T = 0;

  void configure(const AccelOptions& o, Index frames, Index nodes) {
    T = frames;
    order = o.form == AccelForm::acceleration ? 2 : 1;
    weighted = o.confidence_weighted;
    const Index terms = accel_term_count(o, frames, nodes);
    scale_d = o.weight;
    if (o.normalization == Normalization::mean && terms > 0) scale_d /= static_cast<double>(terms);
    enabled = terms > 0 && o.weight != 0.0;
  }

  bool on() const { return enabled; }
  Index reach() const { return order; }
  Index slot_scalars(const BlockPlan&) const { return 0; }
  void bind(const BlockPlan&, S*, const NeighborsView<S, I>&) {}
  struct Block {};
  Block begin(BlockView<S, I>&, S*) const { return {}; }

  // The terms of node i whose earliest frame the block owns; the gradient into the block's rows.
  template <class E>
  void node(const BlockView<S, I>& v, Block&, Index i, E& energy) const {
    const Index ne = v.ne, last = std::min(v.nown, T - order - v.t0);
    const S* X = v.Xb + i * v.n4();
    const S* c = X + 3 * ne;
    S* G = v.GBx ? v.GBx + i * v.n3() : nullptr;
    const S k = S(L(scale_d));
    Acc e(0);
    for (Index l = 0; l < last; ++l) {
      S a[3];
      for (int d = 0; d < 3; ++d) {
        const S* r = X + d * ne + l;
        a[d] = order == 2 ? S(r[2] - L(2) * r[1] + r[0]) : S(r[1] - r[0]);
      }
      S g[3];
      e += Acc(accel_term<S, L>(weighted ? S(k * c[l]) : S(k), a[0], a[1], a[2], g[0], g[1], g[2]));
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
