// smg/energy/terms/lrm.hpp — LRM (E11)-(E16) as a term of the regulariser driver
// (energy/block.hpp has the concept): per node, the block's owned frames in groups of W SIMD
// lanes (W consecutive frames of one node; its neighbour set does not change with t), read from
// the block's gathered records. The per-neighbourhood maths is elements/lrm.hpp's.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <type_traits>
#include <vector>

#include "smg/core/scalar.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/lanes.hpp"
#include "smg/energy/elements/lrm.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/velocity.hpp"

namespace smg {
namespace detail {

// Lanes of the fast kernel: one SIMD register of the target (16 bytes with SSE, 32 with AVX),
// so that no lane value is wider than the ABI's vector registers. They follow __AVX__, hence the
// ISA-specific namespace (smg/core/config.hpp), as have lrm() and the driver, which use them.
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

template <class S, class I>
struct LrmTerm : TermDefaults {
  using L = Literal<S>;
  using Acc = Accumulator<S>;
  // W frames at once for float/double; one at a time for other scalars (autodiff).
  using V = std::conditional_t<std::is_floating_point_v<S>, LrmLane<S>, S>;
  static constexpr Index W = std::is_floating_point_v<S> ? lrm_lanes<S>() : 1;

  bool enabled = false;
  L alpha = L(0), scale = L(0);
  double scale_d = 0;
  LrmParams<S> params;
  Index T = 0, nodes = 0;
  S* tail = nullptr;  // [N][3] the last frame's velocity term on frame T − 2 (gradient only)
  TangentsView<S> omega;  // output ω_i^t [T][N][3] (E12), may be empty

  // On when asked for with a graph; the overall scale as lrm() computes it (the sum, or the
  // mean over T · edges terms).
  void configure(const LrmOptions& o, Index frames, Index K, Index edges, bool gradient) {
    T = frames;
    enabled = K > 0;
    scale_d = o.weight;
    if (o.normalization == Normalization::mean) {
      if (T * edges == 0) enabled = false;
      else scale_d = o.weight / static_cast<double>(T * edges);
    }
    alpha = L(o.alpha);
    scale = L(scale_d);
    params = lrm_params<S>(o, gradient);
  }

  // The list's entry "lrm".
  template <class RO>
  void setup(const RO& o, const TermShape& s) {
    if (o.terms.lrm) configure(o.lrm, s.T, s.K, s.edges, s.want_x);
  }

  bool on() const { return enabled; }
  // The velocity at a block's last frame reads the next frame (E1), and its gradient reaches it.
  Index reach() const { return 1; }
  Index lanes() const { return W; }
  // Alone, two lane groups per block: a block's records (4·N·(2W + 1) scalars, padded) stay
  // nearer the cache while every node reads its neighbours' (the partition's 16 to 32 frames
  // hold 4·N·20 or more: 1.6 MB at N = 5000, float), and the blocks spread over the threads
  // evenly. Measured on bench_energy's LRM gradient rows (N = 5000, T = 100, K = 16, 2 threads):
  // float 53.8 ms with the partition's rule, 54 with W, 51.3 with 2W (the former kernel 46.5);
  // double 94-107 ms (the former kernel 127-136). With the whole-lane scatter of group() (one
  // run, best of two rounds, old kernel of 6db459c beside it): float 36.8 ms (6db459c: 38.2),
  // double 68.1 ms (104).
  Index preferred_block() const { return 2 * W; }
  // Lane groups start at multiples of W; the last group's velocities read one frame past it.
  Index stored(Index nr, Index nown) const {
    return std::max(nr, BlockPlan::round_up(nown, W) + 1);
  }
  Index slot_scalars(const BlockPlan&) const { return 0; }
  Index fixed_scalars(const BlockPlan& p) const { return p.want_x ? 3 * p.N : 0; }
  void bind(const BlockPlan& p, S* fixed, const NeighborsView<S, I>&) {
    nodes = p.N;
    if (!p.want_x) return;
    tail = fixed;
    std::fill(tail, tail + 3 * p.N, S(0));
  }

  // x, u, a, gx, gu, ω and the neighbourhood scratch of one lane group (a few KB per block).
  struct Block {
    std::vector<V> lanes;
  };
  Block begin(BlockView<S, I>& v, S*) const {
    Block k;
    k.lanes.resize(static_cast<std::size_t>((13 + lrm_scratch_size(1)) * v.plan->K + 3));
    return k;
  }

  template <class E>
  void node(const BlockView<S, I>& v, Block& k, Index i, E& energy) const {
    const Index n_groups = (v.nown + W - 1) / W;
    for (Index grp = 0; grp < n_groups; ++grp)
      energy.lrm += group(v, i, grp * W, std::min(W, v.nown - grp * W), k.lanes.data());
  }

  // After the blocks' spills: the last frame's velocity term on frame T − 2.
  void finish_frame(Index s, S* grad_row) const {
    if (!tail || s != T - 2) return;
    for (Index c = 0; c < 3 * nodes; ++c) grad_row[c] += tail[c];
  }
  template <class E>
  void finish(E& e) const {
    e.lrm *= Acc(scale_d);
  }

  // LRM (E11)-(E16) of node i at the nl (<= W) frames t0 + l0 … of one lane group, from the
  // gathered records; ∂L/∂x and ∂L/∂u (scaled) added to the block's position gradient. Returns
  // the unscaled energy (finish() scales the sum).
  Acc group(const BlockView<S, I>& v, Index i, Index l0, Index nl, V* lanes) const {
    const Index K = v.plan->K, ne = v.ne, n4 = v.n4(), n3 = v.n3(), t0 = v.t0;
    V* xs = lanes;
    V* us = xs + 3 * K;
    V* a = us + 3 * K;
    V* gxl = a + K;
    V* gul = gxl + 3 * K;
    V* om = gul + 3 * K;
    V* nb_scratch = om + 3;
    V valid;  // 1 for the group's frames, 0 for padding lanes
    for (Index l = 0; l < W; ++l) lane_ref<V, S>(valid, l) = l < nl ? S(1) : S(0);
    const I* idx = v.graph.indices.ptr(i);
    const S* wrow = v.graph.weights.ptr(i);
    // The lane of frame T − 1 (if in this group): its velocity is the backward difference (E1).
    const Index last = (T >= 2 && t0 + l0 + nl == T) ? nl - 1 : -1;
    for (Index kk = 0; kk < K; ++kk) {
      const Index j = idx[kk] >= 0 ? idx[kk] : i;  // padding: own record, weight 0
      const S* rec = v.Xb + j * n4 + l0;
      for (int c = 0; c < 3; ++c) {
        V xn;
        lane_load(xs[c * K + kk], rec + c * ne);
        lane_load(xn, rec + c * ne + 1);
        us[c * K + kk] = xn - xs[c * K + kk];  // u^t = x^{t+1} − x^t (E1)
        if (T < 2) us[c * K + kk] = lane_constant<V>(L(0));
      }
      if (last >= 0) {
        const Vector3<S> u = velocity(v.x, t0 + l0 + last, j);
        for (int c = 0; c < 3; ++c) lane_ref<V, S>(us[c * K + kk], last) = u(c);
      }
      V cj;
      lane_load(cj, rec + 3 * ne);
      const S wk = idx[kk] >= 0 ? wrow[kk] : S(0);
      a[kk] = confidence_edge_weight(V(wk * valid), alpha, cj);
    }
    V ev = lrm_neighborhood<V, S>(K, xs, us, a, params, nb_scratch, gxl, gul, om);
    Acc e(0);
    for (Index l = 0; l < nl; ++l) e += Acc(lane_ref<V, S>(ev, l));
    if (omega.data())
      for (Index l = 0; l < nl; ++l)
        for (int c = 0; c < 3; ++c) omega(t0 + l0 + l, i)(c) = lane_ref<V, S>(om[c], l);
    // With one frame u ≡ 0 is a constant (E1): no velocity term reaches the positions.
    if (!params.gradient) return e;
    const bool moving = T >= 2;
    // A full group that does not hold frame T − 1 adds its parts as whole lanes: dst[l] gets
    // ∂L/∂u^{l−1} (u^{l−1} = x^l − x^{l−1}, moved up one lane), then ∂L/∂x^l, then −∂L/∂u^l,
    // and dst[W] gets ∂L/∂u^{W−1}: the scalar loop's additions in its order, element by
    // element, so the results are bit-identical (lane 0 adds −0, the exact identity). dst[W]
    // is in the block's stored span (stored()).
    const bool whole = moving && nl == W && last < 0;
    const L s_scale = scale;
    for (Index kk = 0; kk < K; ++kk) {
      const Index j = idx[kk];
      if (j < 0) break;
      S* rec = v.GBx + j * n3 + l0;
      for (int c = 0; c < 3; ++c) {
        V gxs = s_scale * gxl[c * K + kk], gus = s_scale * gul[c * K + kk];
        S* dst = rec + c * ne;
        if constexpr (W > 1) {
          if (whole) {
            V d;
            lane_load(d, dst);
            d += lanes_shift_up(gus, S(-0.0));
            d += gxs;
            d -= gus;
            lane_store(d, dst);
            dst[W] += lane_ref<V, S>(gus, W - 1);
            continue;
          }
        }
        for (Index l = 0; l < nl; ++l) {
          const S vx = lane_ref<V, S>(gxs, l), vu = lane_ref<V, S>(gus, l);
          dst[l] += vx;
          if (!moving) continue;
          if (l == last) {
            // u^{T−1} = x^{T−1} − x^{T−2}: x^{T−2} is the previous frame, or the previous
            // block's (then through `tail`, added after the spills).
            dst[l] += vu;
            if (l0 + l >= 1)
              dst[l - 1] -= vu;
            else
              tail[3 * j + c] -= vu;
          } else {
            dst[l + 1] += vu;
            dst[l] -= vu;
          }
        }
      }
    }
    return e;
  }
};

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace detail
}  // namespace smg
