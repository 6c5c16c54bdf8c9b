// smg/energy/term_list.hpp — the list of the fused step's terms, written once
// (SMG_REGULARIZER_TERMS), and what is written from it: which terms a call computes
// (RegularizerTerms), their options (RegularizerOptions), for_each_term, the energies it returns
// (RegularizerResult), validate_options(RegularizerOptions) and the driver's list of term objects
// (detail::RegularizerTermSet) (docs/math/energy.md "The fused regulariser pass").
//
// Why one list: the bindings (smg_cli regularizers, smg_torch.regularizers), the bench rows, the
// docs' terms table, both drivers (the CPU's, energy/regularizers.hpp, and the CUDA element pass,
// cuda/driver.cuh) and the generic tests read these, so a term added to the list is exposed by
// all of them. Adding a term: its header in energy/terms/ (options, equations, term), one include
// and one line below (docs/contributing.md §3).
//
// Why a header of its own: device headers must not reach the CPU thread pool (core/parallel.hpp),
// which the CPU driver and the one-term operators include; the terms' headers and this one are
// free of it (tests/api/check_include_closure.py).
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <sstream>
#include <string>
#include <tuple>
#include <type_traits>

#include "smg/core/status.hpp"
#include "smg/core/types.hpp"
#include "smg/energy/common.hpp"  // Accumulator<S>, the type of the energies
#include "smg/energy/options.hpp"
#include "smg/energy/terms/accel.hpp"
#include "smg/energy/terms/angle.hpp"
#include "smg/energy/terms/confidence.hpp"
#include "smg/energy/terms/lrm.hpp"
#include "smg/energy/terms/relrot.hpp"
#include "smg/energy/terms/rigid.hpp"

// The fused step's energy terms, one line each, in the order the driver calls them per node
// (after the confidences, which fill the records the others read and have no energy). Columns:
//   name      the member of RegularizerTerms, RegularizerOptions and RegularizerResult, and the
//             bindings' spelling (smg_cli --<name>-*, smg_torch's keyword)
//   Options   its options struct (with for_each_option and validate_options beside it)
//   Term      its term, a template <S, I> of energy/terms/ (one term may serve two entries, as
//             RigidTerm serves C-ARAP and ARAP, which share d (E8); it reads both entries)
//   on        whether a default RegularizerOptions computes it
// Whether a term reads the rotations is its own reads_rotations() (the term concept,
// energy/block.hpp), not a column: one statement of it.
#define SMG_REGULARIZER_TERMS(X)                                                            \
  /* name   Options        Term        on                                                */ \
  X(carap,  CarapOptions,  RigidTerm,  true)  /* (E9), weights (E7) with c                 */ \
  X(arap,   ArapOptions,   RigidTerm,  false) /* (E9) with c ≡ 1, α = 1 (ablations)        */ \
  X(lrm,    LrmOptions,    LrmTerm,    true)  /* (E14), weights (E7) with c                */ \
  X(accel,  AccelOptions,  AccelTerm,  false) /* (E21), trajectory smoothness              */ \
  X(angle,  AngleOptions,  AngleTerm,  false) /* (E23), rotation-angle velocity / accel.   */ \
  X(relrot, RelrotOptions, RelrotTerm, false) /* (E25), relative rotations along the edges */

namespace smg {

// The fused step (regularizers.hpp): which terms it computes. Confidences off: C-ARAP and LRM
// use c ≡ 1 (as carap() and lrm() do with an empty confidence view), or the caller's c.
struct RegularizerTerms {
  bool confidence = true;  // c_{t,i} (E6); written to the `confidence` output when given
#define SMG_TERM_FLAG_(name, Options, Term, on) bool name = on;
  SMG_REGULARIZER_TERMS(SMG_TERM_FLAG_)
#undef SMG_TERM_FLAG_
};

// Whether a term that is on reads the rotations (so the caller must give them): its term says
// (reads_rotations(), known without options).
inline bool reads_rotations(const RegularizerTerms& t) {
  bool r = false;
#define SMG_TERM_READS_(name, Options, Term, on) \
  r = r || (t.name && detail::Term<double, std::int32_t>().reads_rotations());
  SMG_REGULARIZER_TERMS(SMG_TERM_READS_)
#undef SMG_TERM_READS_
  return r;
}

// The options of the fused step: the terms, and each term's own options (plain values).
struct RegularizerOptions {
  RegularizerTerms terms;
  ConfidenceOptions confidence;
#define SMG_TERM_OPTIONS_(name, Options, Term, on) Options name;
  SMG_REGULARIZER_TERMS(SMG_TERM_OPTIONS_)
#undef SMG_TERM_OPTIONS_
};

// The term list of the fused step: f(name, on, options) for every entry of RegularizerOptions,
// the confidences first, then the list's order, with on = o.terms.<name> (bool& or const bool&).
// validate_options below, smg_torch.regularizers (its options, defaults and argument names) and
// smg_cli regularizers (its flags) loop over it.
template <class RO, class F, detail::IfOptions<RO, RegularizerOptions> = 0>
void for_each_term(RO& o, F&& f) {
  f("confidence", o.terms.confidence, o.confidence);
#define SMG_TERM_VISIT_(name, Options, Term, on) f(#name, o.terms.name, o.name);
  SMG_REGULARIZER_TERMS(SMG_TERM_VISIT_)
#undef SMG_TERM_VISIT_
}

// The energies of one fused step, each as the separate operator returns it (0 for a term that
// is off), in Accumulator<S> (double for float), in the list's order. Plain doubles in this
// order: the torch CUDA glue reads it as a tensor of each_energy's length.
template <class S>
struct RegularizerResult {
#define SMG_TERM_ENERGY_(name, Options, Term, on) Accumulator<S> name = Accumulator<S>(0);
  SMG_REGULARIZER_TERMS(SMG_TERM_ENERGY_)
#undef SMG_TERM_ENERGY_

  // f(name, r.<energy>...) for each energy, in the list's order, of one or more results: total(),
  // +=, the torch glue's energies tensor and smg_torch.Regularizers' names, smg_cli's summary
  // and the tests follow it.
  template <class F, class... R>
  static void each_energy(F&& f, R&... r) {
#define SMG_TERM_EACH_(name, Options, Term, on) f(#name, r.name...);
    SMG_REGULARIZER_TERMS(SMG_TERM_EACH_)
#undef SMG_TERM_EACH_
  }
  Accumulator<S> total() const {
    Accumulator<S> t(0);
    each_energy([&](const char*, const Accumulator<S>& e) { t += e; }, *this);
    return t;
  }
  RegularizerResult& operator+=(const RegularizerResult& o) {
    each_energy([](const char*, Accumulator<S>& a, const Accumulator<S>& b) { a += b; }, *this, o);
    return *this;
  }
};

// The options of every term of the fused step that is on (regularizers(), CPU and CUDA); the
// first bad one's message.
inline Status validate_options(const RegularizerOptions& o) {
  Status first = Status::ok();
  for_each_term(o, [&](const char*, bool on, const auto& term) {
    if (on && first) first = validate_options(term);
  });
  // The rigid term computes d once for C-ARAP and ARAP (E8) and back-propagates their
  // d-gradients together (E10), so one call expresses both in one frame and holds one endpoint.
  auto same = [&](const char* name, auto a, auto b) {
    if (first && o.terms.carap && o.terms.arap && a != b)
      first = Status::error(std::string("RegularizerOptions: carap.") + name + " (" + to_string(a) +
                            ") and arap." + name + " (" + to_string(b) +
                            ") differ; one fused call computes both rigid energies together: "
                            "call them separately");
  };
  same("stop_gradient", o.carap.stop_gradient, o.arap.stop_gradient);
  same("frame", o.carap.frame, o.arap.frame);
  return first;
}

namespace detail {

// A type list and its first occurrences, in order: the list's Term column with each term once
// (RigidTerm serves two entries).
template <class... T>
struct TypeList {};
template <class List, class... U>
struct UniqueTypes {
  using type = List;
};
template <class... T, class U, class... R>
struct UniqueTypes<TypeList<T...>, U, R...>
    : UniqueTypes<std::conditional_t<(std::is_same<T, U>::value || ...), TypeList<T...>,
                                     TypeList<T..., U>>,
                  R...> {};
template <class List>
struct TupleOf;
template <class... T>
struct TupleOf<TypeList<T...>> {
  using type = std::tuple<T...>;
};

inline namespace SMG_ISA_NAMESPACE {

// The term objects of one call, in the order the driver calls them per node: the confidences
// first (they fill the records the others read), then each term of the list once, each set up
// from RegularizerOptions by its own setup(). The CUDA driver reads this list too: a term whose
// struct names an Element runs in its element pass (cuda/driver.cuh, ListElements).
template <class S, class I>
struct RegularizerTermSet {
// Term names a template: (Term)<S, I> would not parse.
#define SMG_TERM_TYPE_(name, Options, Term, on) , Term<S, I>  // NOLINT(bugprone-macro-parentheses)
  using Energies =
      typename TupleOf<typename UniqueTypes<TypeList<> SMG_REGULARIZER_TERMS(SMG_TERM_TYPE_)>::type>::type;
#undef SMG_TERM_TYPE_

  ConfidenceTerm<S, I> confidence;
  Energies energies;

  RegularizerTermSet(Index T, Index N, Index K, Index edges, const RegularizerOptions& o,
                     bool want_x, bool want_r) {
    const TermShape shape{T, N, K, edges, want_x, want_r};
    confidence.setup(o, shape);
    std::apply([&](auto&... t) { (t.setup(o, shape), ...); }, energies);
  }
  bool any_energy() const {
    return std::apply([](const auto&... t) { return (t.on() || ...); }, energies);
  }
  // f(terms...) over the list, each checked against the term concept (energy/block.hpp) first:
  // both drivers (the CPU's drive(), the CUDA element pass's ListElements) take the list here.
  template <class F>
  decltype(auto) apply(F&& f) {
    return std::apply([&](auto&... t) -> decltype(auto) { return checked(f, confidence, t...); },
                      energies);
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
