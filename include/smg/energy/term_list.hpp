// smg/energy/term_list.hpp — the list of the fused step's terms, RegularizerTermSet: one member
// per energy/terms/<name>.hpp, in the order the driver calls them per node, each configured from
// RegularizerOptions (docs/math/energy.md "The fused regulariser pass").
//
// Why a header of its own: both drivers read the list, the CPU's (energy/regularizers.hpp) and
// the CUDA element pass (cuda/driver.cuh, ListElements), and device headers must not reach the
// CPU thread pool (core/parallel.hpp), which the CPU driver and the one-term operators include.
// The terms' headers and this one are free of it (tests/api/check_include_closure.py).
#pragma once

#include "smg/core/config.hpp"

#include "smg/core/types.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/terms/accel.hpp"
#include "smg/energy/terms/angle.hpp"
#include "smg/energy/terms/confidence.hpp"
#include "smg/energy/terms/lrm.hpp"
#include "smg/energy/terms/relrot.hpp"
#include "smg/energy/terms/rigid.hpp"

namespace smg {

namespace detail {

inline namespace SMG_ISA_NAMESPACE {

// The terms of the fused step, in the order the driver calls them per node (the confidences
// first: they fill the records the others read). Adding a term: a header in energy/terms/, its
// one-term call included in regularizers.hpp, its options and list entries in options.hpp, one member and one
// configure line here (docs/contributing.md §3). The CUDA driver reads this list too: a member
// whose struct names an Element runs in its element pass (cuda/driver.cuh, ListElements).
template <class S, class I>
struct RegularizerTermSet {
  ConfidenceTerm<S, I> confidence;
  RigidTerm<S, I> rigid;  // C-ARAP and ARAP, sharing d (E8)
  LrmTerm<S, I> lrm;
  AccelTerm<S, I> accel;
  AngleTerm<S, I> angle;
  RelrotTerm<S, I> relrot;

  RegularizerTermSet(Index T, Index N, Index K, Index edges, const RegularizerOptions& o,
                     bool want_x, bool want_r) {
    const RegularizerTerms& on = o.terms;
    confidence.computed = on.confidence;
    confidence.constants = ConfidenceConstants<S>(o.confidence);
    if (K > 0)
      rigid.configure(on.carap ? &o.carap : nullptr, on.arap ? &o.arap : nullptr, T, edges);
    rigid.want_rotations = want_r;
    if (on.lrm) lrm.configure(o.lrm, T, K, edges, want_x);
    if (on.accel) accel.configure(o.accel, T, N);
    if (on.angle) angle.configure(o.angle, T, N);
    angle.want_rotations = want_r;
    if (on.relrot && K > 0) relrot.configure(o.relrot, T, edges);
    relrot.want_rotations = want_r;
  }
  bool any_energy() const { return rigid.on() || lrm.on() || accel.on() || angle.on() || relrot.on(); }
  // f(terms...) over the list, each checked against the term concept (energy/block.hpp) first:
  // both drivers (the CPU's drive(), the CUDA element pass's ListElements) take the list here.
  template <class F>
  decltype(auto) apply(F&& f) {
    return checked(f, confidence, rigid, lrm, accel, angle, relrot);
  }

 private:
  template <class F, class... T>
  static decltype(auto) checked(F& f, T&... t) {
    static_assert((check_term<T, S, I>() && ...),
                  "smg: a term of RegularizerTermSet does not model the term concept (energy/block.hpp)");
    return f(t...);
  }
};

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace detail

}  // namespace smg
