// smg/energy/terms/confidence.hpp — the node confidences c_{t,i} (E1)-(E6) as a term of the
// regulariser driver (energy/block.hpp has the concept): per block, before any node, it fills
// the c row of the block's records for the owned frames (C-ARAP's and LRM's weights (E7) read
// c at the earlier frame, which the block owns) and writes them to the caller's output. It adds
// no energy: confidences are constants for the gradient (stop-gradient), as in the paper.
// Off: c ≡ 1. With a caller's confidences (carap(), lrm()): those are copied instead.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/energy/block.hpp"
#include "smg/energy/elements/confidence.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/velocity.hpp"

namespace smg {
namespace detail {

template <class S, class I>
struct ConfidenceTerm : TermDefaults {
  bool computed = false;                 // compute c (E6); else copy `given` or use 1
  ConfidenceConstants<S> constants{ConfidenceOptions{}};
  VisibilityView<const std::uint8_t> vis;  // may be empty (all visible)
  FrameScalarsView<const S> given;       // the caller's c [T][N], when not computed (may be empty)
  FrameScalarsView<S> out;               // output [T][N] (may be empty)
  FrameScalarsView<S> motion, rigidity;  // outputs c^m (E3), c^r (E5) [T][N] (node_confidences; may be empty)
  const S* inv_w = nullptr;              // [N] 1/Σ_k w_ik (fixed scratch)

  // The list's entry "confidence": computed when on, with its constants (E3)-(E6).
  template <class RO>
  void setup(const RO& o, const TermShape&) {
    computed = o.terms.confidence;
    constants = ConfidenceConstants<S>(o.confidence);
  }

  // Always on: every block needs its c row (1 when nothing is computed).
  bool on() const { return true; }
  Index reach() const { return 0; }
  bool position_gradient() const { return false; }
  Index slot_scalars(const BlockPlan& p) const {
    return computed ? BlockPlan::chunk(3 * p.N) + BlockPlan::chunk(p.N) : 0;
  }
  Index fixed_scalars(const BlockPlan& p) const { return computed ? p.N : 0; }
  void bind(const BlockPlan& p, S* fixed, const NeighborsView<S, I>& graph) {
    if (!computed) return;
    for (Index i = 0; i < p.N; ++i) fixed[i] = inverse_row_weight(graph, i);
    inv_w = fixed;
  }

  struct Block {};

  // c of the owned frames, frame by frame: e_j^t of every node first (a node's confidence reads
  // its neighbours' values), then c_{t,i} (E6), into the records.
  Block begin(BlockView<S, I>& v, S* slot) const {
    const Index N = v.plan->N, n4 = v.n4(), ne = v.ne;
    SlotCursor<S> cur{slot};
    S* Vel = computed ? cur.take(3 * N) : nullptr;
    S* Ec = computed ? cur.take(N) : nullptr;
    for (Index l = 0; l < v.nown; ++l) {
      const Index t = v.t0 + l;
      if (!computed) {
        for (Index j = 0; j < N; ++j) v.Xb[j * n4 + 3 * ne + l] = given.data() ? given(t, j) : S(1);
        continue;
      }
      for (Index j = 0; j < N; ++j) {
        const Vector3<S> u = velocity(v.x, t, j);
        Vel[3 * j] = u(0);
        Vel[3 * j + 1] = u(1);
        Vel[3 * j + 2] = u(2);
        Ec[j] = confidence_edge_change(v.x, v.graph, inv_w[j], t, j);
      }
      for (Index i = 0; i < N; ++i) {
        // Frame index 0 of the one-frame arrays Vel [1][N][3] and Ec [1][N].
        S m(0), r(0);
        const S c = confidence_node<S, I>(Vel, Ec, v.graph, inv_w[i], 0, i, constants,
                                          motion.data() ? &m : nullptr,
                                          rigidity.data() ? &r : nullptr);
        const S ci = (vis.data() ? S(vis(t, i) ? 1 : 0) : S(1)) * c;
        v.Xb[i * n4 + 3 * ne + l] = ci;
        if (out.data()) out(t, i) = ci;
        if (motion.data()) motion(t, i) = m;
        if (rigidity.data()) rigidity(t, i) = r;
      }
    }
    return {};
  }
  template <class E>
  void node(const BlockView<S, I>&, Block&, Index, E&) const {}
};

}  // namespace detail
}  // namespace smg
