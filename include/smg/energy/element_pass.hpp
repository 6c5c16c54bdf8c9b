// smg/energy/element_pass.hpp — the CPU driver's schedule by nodes, for calls whose terms are all
// per-(frame, node) steps that read no graph (trajectory smoothness, AccelElement; the
// rotation-angle term, AngleElement): the very steps the CUDA element pass runs
// (cuda/driver.cuh), in host loops over chunks of nodes (docs/math/energy.md "The fused
// regulariser pass", "Schedules").
//
// Why: the frame blocks of driver.hpp let a term push gradient into other rows, so a block owns
// frames and a call over a short window (T up to 5–8 frames: Shape of Motion's three, a
// two-frame window) is one block on one thread, which also gathers every node's frames into
// records first. Here a chunk of nodes owns every row of its nodes: a term with a whole-term
// form (kWholeTerms: AccelElement, AngleElement) is evaluated once and adds its gradient to the
// rows it reaches; an Element without one would run its GPU step at(), which writes one row and
// recomputes the terms that share it. No row is written by two chunks, so the nodes split into
// chunks over every core, with no records, no spill and no scratch (the EnergyWorkspace is not
// touched).
//
// Determinism: the chunks are a function of N only (element_chunk_nodes), each chunk sums its
// terms' energies in (t, n) order, and the chunks' sums are added in chunk order: bit-identical
// for any thread count, in float and double. The gradient rows are each one step's sum in a fixed
// order. The rounding differs from the frame blocks' (another order of the same sums), so the
// choice is a function of the terms that are on only, never of the thread count.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <type_traits>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/terms/confidence.hpp"

namespace smg {
namespace detail {

inline namespace SMG_ISA_NAMESPACE {

// Whether Term names an Element that reads no graph (a step of its own node's rows only).
template <class Term, class = void>
struct NodeElement : std::false_type {};
template <class Term>
struct NodeElement<Term, std::enable_if_t<has_element_v<Term>>>
    : std::integral_constant<bool, !ElementReadsGraph<typename Term::Element>::value> {};

// Whether `term` lets the call run as the element pass: off; the confidences when they are only
// read (the caller's c, or 1: an element reads conf [T][N] itself); or an Element that reads no
// graph. Anything else (C-ARAP, ARAP, LRM, the relative rotations, computed confidences: terms
// along the edges) keeps the frame blocks.
template <class S, class I, class Term>
bool runs_as_element(const Term& term) {
  if (!term.on()) return true;
  if constexpr (std::is_same<Term, ConfidenceTerm<S, I>>::value) {
    return !term.computed;
  } else if constexpr (NodeElement<Term>::value) {
    return true;
  } else {
    return false;
  }
}

// The element pass runs a call when every term lets it and some energy term is on.
template <class S, class I, class... Terms>
bool element_schedule(const Terms&... terms) {
  bool any = false;
  ((any = any || (NodeElement<Terms>::value && terms.on())), ...);
  return any && (runs_as_element<S, I>(terms) && ...);
}

// Nodes per chunk: about 64 chunks (enough to balance any small machine's cores), at least 256
// nodes each (a chunk's rows span several cache lines per frame). A function of N only.
inline Index element_chunk_nodes(Index nodes) {
  return std::max<Index>(256, (nodes + 63) / 64);
}

// Whether an Element can evaluate each of its terms once, term_at(u, n, ...), adding the
// gradient to all of node n's rows the term reaches (`static constexpr bool kWholeTerms = true`,
// AccelElement): the pass owns every row of its nodes, so it need not recompute a term per row.
template <class E, class = void>
struct ElementWholeTerms : std::false_type {};
template <class E>
struct ElementWholeTerms<E, std::void_t<decltype(E::kWholeTerms)>>
    : std::integral_constant<bool, E::kWholeTerms> {};

// One term's steps over frames [0, T) and nodes [n0, n1), frame by frame (each frame's rows of
// the chunk are contiguous); its energy into energy_of(e). A row (t, n) receives its
// contributions in the order of their terms' earliest frames, always the same.
template <class S, class I, class Term, class E>
void element_rows(const Term& term, PositionsView<const S> x, QuaternionsView<const S> q,
                  const S* conf, S* grad_x, S* grad_tangent, S* grad_raw, Index n0, Index n1,
                  E& e) {
  if constexpr (NodeElement<Term>::value) {
    if (!term.on()) return;
    using El = typename Term::Element;
    const El step = term.element();
    Index T = std::max(x.frames(), q.frames());
    if constexpr (ElementWholeTerms<El>::value) T = std::max<Index>(0, T - step.order);  // earliest frames
    Accumulator<S> sum(0);
    for (Index t = 0; t < T; ++t)
      for (Index n = n0; n < n1; ++n) {
        S v(0);
        if constexpr (ElementWholeTerms<El>::value && ElementReadsRotations<El>::value)
          step.term_at(t, n, x, q, conf, grad_x, grad_tangent, grad_raw, v);  // each term once
        else if constexpr (ElementWholeTerms<El>::value)
          step.term_at(t, n, x, conf, grad_x, v);  // each term once, from its earliest frame
        else if constexpr (ElementReadsRotations<El>::value)
          step.at(t, n, x, q, conf, grad_x, grad_tangent, grad_raw, v);
        else
          step.at(t, n, x, conf, grad_x, v);
        sum += Accumulator<S>(v);
      }
    Term::energy_of(e) += sum;
  }
}

// The confidences a step reads: the caller's c [T][N] (ConfidenceTerm::given), or null (c ≡ 1).
template <class S, class I, class Term>
void element_confidence(const Term& term, const S*& conf) {
  if constexpr (std::is_same<Term, ConfidenceTerm<S, I>>::value) conf = term.given.data();
}

// The element pass over the caller's views (x [T][N][3], may be empty for a rotation term; q
// [T][N][4] when a term reads rotations; the gradient rows, each may be null): returns the
// energies. Precondition: element_schedule(terms...).
template <class E, class S, class I, class... Terms>
E drive_elements(PositionsView<const S> x, QuaternionsView<const S> q, Index N, S* grad_x,
                 S* grad_tangent, S* grad_raw, ParallelOptions parallel, const Terms&... terms) {
  E result;
  if (N == 0) return result;
  const S* conf = nullptr;
  (element_confidence<S, I>(terms, conf), ...);
  const Index grain = element_chunk_nodes(N);
  std::vector<E> partial(static_cast<std::size_t>(parallel_chunk_count(N, grain)));
  ParallelOptions po = parallel;
  po.grain = grain;
  parallel_for_chunks(
      N,
      [&](Index c, Index n0, Index n1) {
        E e;
        (element_rows<S, I>(terms, x, q, conf, grad_x, grad_tangent, grad_raw, n0, n1, e), ...);
        partial[static_cast<std::size_t>(c)] = e;
      },
      po);
  for (const E& e : partial) result += e;
  return result;
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace detail
}  // namespace smg
