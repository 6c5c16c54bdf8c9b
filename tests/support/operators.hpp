// tests/support/operators.hpp — the regularisers as one list (Operators), for the tests that must
// treat every operator the same way (int64 graphs, callers' executors, debug assertions): each
// iterates over the list, so an operator added here is covered by all of them.
#pragma once

#include <cstddef>
#include <cstdint>
#include <tuple>
#include <type_traits>
#include <utility>

#include "smg/energy.hpp"

namespace smg::test {

// What an operator may read: positions [T][N][3], rotations [T][N][4], visibility [T][N] (empty:
// all visible), confidences [T][N] (empty: all 1) and the graph [N][K]. Mutable: the caller's
// mutable views, which every entry point takes as well as const ones, with no template argument
// (tests/api/test_mutable_views.cpp runs the list with both): so `run` and `validate` below call
// the operators without one.
template <class S, class I = std::int32_t, bool Mutable = false>
struct OperatorInputs {
  template <class T>
  using In = std::conditional_t<Mutable, T, const T>;
  PositionsView<In<S>> positions;
  QuaternionsView<In<S>> rotations;
  VisibilityView<In<std::uint8_t>> visibility;
  FrameScalarsView<In<S>> confidence;
  NeighborsView<S, I> graph;
};

// The inputs of a test scene (tests/energy/scene.hpp) with graph g and confidences c.
template <class Scene, class S, class I>
OperatorInputs<S, I> inputs_of(const Scene& s, const NeighborsView<S, I>& g, FrameScalarsView<const S> c) {
  return {s.positions(), s.rotations(), s.visibility(), c, g};
}

// What an operator may write (any view may be empty): position gradients or updates [T][N][3]
// and rotation gradients or updates in the right tangent [T][N][3], added to; confidences [T][N],
// overwritten.
template <class S>
struct OperatorOutputs {
  PositionsView<S> positions;
  TangentsView<S> rotations;
  FrameScalarsView<S> confidence;
};

// Which optional inputs an operator reads (its `reads`).
constexpr unsigned kReadsGraph = 1, kReadsConfidence = 2, kReadsVisibility = 4, kReadsRotations = 8;
// ... and whether it reads no positions at all (a term of the rotations alone: angle).
constexpr unsigned kNoPositions = 16;

// Each operator: `name` (also the smg_assert_probe mode that misuses it), `exact_gradient` (its
// outputs are the exact gradient of its energy in the given inputs: tests/energy/test_terms.cpp
// checks them against central differences and AutoDiffScalar), run(in, out, workspace,
// parallel), with default options, which returns the energy in Accumulator<S> (0 for the
// confidences, which have none), and validate(in, out): its validate_* with the same views and
// options (run's precondition), whose one-line errors name the argument (test_terms.cpp checks
// them by the list). `reads` says which of the optional inputs the operator reads (a bad one of
// those must be refused).
// The separate operators of the fused step's terms also have `term`, the term's name in
// smg::for_each_term (nullptr for the others), separate(in, o, grad_positions,
// grad_rotations, confidence, workspace, parallel): the call with o's options for the term
// (tests/energy/test_regularizers.cpp runs the fused step against them by the list), and
// validate_with(in, out, o), its validator with o's options (tests/stability/
// test_energy_hard_cases.cpp gives it each bad option value); run() is separate() and validate()
// validate_with() with options(), the test defaults.

// run() and validate() of a term's operator (Op: Confidences, Carap, ...): separate() and
// validate_with() with Op::options(), the test defaults. One definition, so that an operator
// entry only says what differs (its call, its validator, its options).
template <class Op>
struct TermOperator {
  static RegularizerOptions options() { return {}; }  // an operator with other defaults hides it
  template <class S, class I, bool M>
  static Accumulator<S> run(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                            EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
    return Op::separate(in, Op::options(), out.positions, out.rotations, out.confidence, workspace, parallel);
  }
  template <class S, class I, bool M>
  static Status validate(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out) {
    return Op::validate_with(in, out, Op::options());
  }
};

struct Confidences : TermOperator<Confidences> {
  static constexpr const char* name = "confidences";
  static constexpr const char* term = "confidence";
  static constexpr bool exact_gradient = false;  // no energy
  template <class S, class I, bool M>
  static Accumulator<S> separate(const OperatorInputs<S, I, M>& in, const RegularizerOptions& o, PositionsView<S>,
                                 detail::NonDeducedT<RotationGradientView<S>>, FrameScalarsView<S> confidence,
                                 EnergyWorkspace<S>* workspace, ParallelOptions parallel) {
    node_confidences(in.positions, in.visibility, in.graph, o.confidence, confidence, {}, {}, workspace, parallel);
    return Accumulator<S>(0);
  }
  static constexpr unsigned reads = kReadsGraph | kReadsVisibility;
  template <class S, class I, bool M>
  static Status validate_with(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                              const RegularizerOptions& o) {
    return validate_confidence(in.positions, in.visibility, in.graph, o.confidence, out.confidence);
  }
};

struct Carap : TermOperator<Carap> {
  static constexpr const char* name = "carap";
  static constexpr const char* term = "carap";
  static constexpr bool exact_gradient = true;
  template <class S, class I, bool M>
  static Accumulator<S> separate(const OperatorInputs<S, I, M>& in, const RegularizerOptions& o, PositionsView<S> gx,
                                 detail::NonDeducedT<RotationGradientView<S>> gr, FrameScalarsView<S>, EnergyWorkspace<S>* workspace,
                                 ParallelOptions parallel) {
    return carap(in.positions, in.rotations, in.confidence, in.graph, o.carap, gx, gr, workspace, parallel);
  }
  static constexpr unsigned reads = kReadsGraph | kReadsConfidence | kReadsRotations;
  static constexpr Penalty default_penalty = Penalty::squared;
  static Penalty& penalty_of(RegularizerOptions& o) { return o.carap.penalty; }
  template <class S, class I, bool M>
  static Status validate_with(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                              const RegularizerOptions& o) {
    return validate_carap(in.positions, in.rotations, in.confidence, in.graph, o.carap, out.positions,
                             out.rotations);
  }
};

struct Arap : TermOperator<Arap> {
  static constexpr const char* name = "arap";
  static constexpr const char* term = "arap";
  static constexpr bool exact_gradient = true;
  template <class S, class I, bool M>
  static Accumulator<S> separate(const OperatorInputs<S, I, M>& in, const RegularizerOptions& o, PositionsView<S> gx,
                                 detail::NonDeducedT<RotationGradientView<S>> gr, FrameScalarsView<S>, EnergyWorkspace<S>* workspace,
                                 ParallelOptions parallel) {
    return arap(in.positions, in.rotations, in.graph, o.arap, gx, gr, workspace, parallel);
  }
  static constexpr unsigned reads = kReadsGraph | kReadsRotations;
  template <class S, class I, bool M>
  static Status validate_with(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                              const RegularizerOptions& o) {
    return validate_arap(in.positions, in.rotations, in.graph, o.arap, out.positions, out.rotations);
  }
};

// The directed reading of C-ARAP (its updates go to the gradient views); it takes no workspace.
struct CarapDirected {
  static constexpr const char* name = "carap_directed";
  static constexpr const char* term = nullptr;  // a reading of C-ARAP, not a term of the fused step
  static constexpr bool exact_gradient = false;  // updates, not a gradient (E20)
  template <class S, class I, bool M>
  static Accumulator<S> run(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out, EnergyWorkspace<S>* = nullptr,
                    ParallelOptions parallel = {}) {
    return carap_directed(in.positions, in.rotations, in.confidence, in.graph, CarapOptions{}, out.positions,
                             out.rotations, parallel);
  }
  static constexpr unsigned reads = kReadsGraph | kReadsConfidence | kReadsRotations;
  template <class S, class I, bool M>
  static Status validate(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out) {
    return Carap::validate(in, out);  // the same arguments and options as carap()
  }
};

struct Lrm : TermOperator<Lrm> {
  static constexpr const char* name = "lrm";
  static constexpr const char* term = "lrm";
  static constexpr bool exact_gradient = true;
  template <class S, class I, bool M>
  static Accumulator<S> separate(const OperatorInputs<S, I, M>& in, const RegularizerOptions& o, PositionsView<S> gx,
                                 detail::NonDeducedT<RotationGradientView<S>>, FrameScalarsView<S>, EnergyWorkspace<S>* workspace,
                                 ParallelOptions parallel) {
    return lrm(in.positions, in.confidence, in.graph, o.lrm, gx, workspace, parallel);
  }
  static constexpr unsigned reads = kReadsGraph | kReadsConfidence;
  template <class S, class I, bool M>
  static Status validate_with(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                              const RegularizerOptions& o) {
    return validate_lrm(in.positions, in.confidence, in.graph, o.lrm, out.positions);
  }
};

// Trajectory smoothness (E21), acceleration form, weighted by the given confidences.
struct Accel : TermOperator<Accel> {
  static constexpr const char* name = "accel";
  static constexpr const char* term = "accel";
  static constexpr bool exact_gradient = true;
  static RegularizerOptions options() {
    RegularizerOptions o;
    o.accel.confidence_weighted = true;
    return o;
  }
  template <class S, class I, bool M>
  static Accumulator<S> separate(const OperatorInputs<S, I, M>& in, const RegularizerOptions& o, PositionsView<S> gx,
                                 detail::NonDeducedT<RotationGradientView<S>>, FrameScalarsView<S>, EnergyWorkspace<S>* workspace,
                                 ParallelOptions parallel) {
    return accel(in.positions, in.confidence, o.accel, gx, workspace, parallel);
  }
  static constexpr unsigned reads = kReadsConfidence;
  static constexpr Penalty default_penalty = Penalty::squared;
  static Penalty& penalty_of(RegularizerOptions& o) { return o.accel.penalty; }
  template <class S, class I, bool M>
  static Status validate_with(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                              const RegularizerOptions& o) {
    return validate_accel(in.positions, in.confidence, o.accel, out.positions);
  }
};

// Rotation-angle acceleration (E23), weighted by the given confidences: it reads the rotations
// only (no positions) and writes the rotation gradient only.
struct Angle : TermOperator<Angle> {
  static constexpr const char* name = "angle";
  static constexpr const char* term = "angle";
  static constexpr bool exact_gradient = true;
  static RegularizerOptions options() {
    RegularizerOptions o;
    o.angle.confidence_weighted = true;
    return o;
  }
  template <class S, class I, bool M>
  static Accumulator<S> separate(const OperatorInputs<S, I, M>& in, const RegularizerOptions& o, PositionsView<S>,
                                 detail::NonDeducedT<RotationGradientView<S>> gr, FrameScalarsView<S>,
                                 EnergyWorkspace<S>* workspace, ParallelOptions parallel) {
    return angle(in.rotations, in.confidence, o.angle, gr, workspace, parallel);
  }
  static constexpr unsigned reads = kReadsConfidence | kReadsRotations | kNoPositions;
  static constexpr Penalty default_penalty = Penalty::norm;
  static Penalty& penalty_of(RegularizerOptions& o) { return o.angle.penalty; }
  template <class S, class I, bool M>
  static Status validate_with(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                              const RegularizerOptions& o) {
    return validate_angle<S>(in.rotations, in.confidence, o.angle, out.rotations);
  }
};

// Relative-rotation consistency (E25) with its default penalty, sqrt_weighted: k sqrt(ε) per
// term where the relative rotations agree (a still trajectory's energy is above 0).
struct Relrot : TermOperator<Relrot> {
  static constexpr const char* name = "relrot";
  static constexpr const char* term = "relrot";
  static constexpr bool exact_gradient = true;
  static constexpr bool still_floor = true;
  static constexpr bool sign_sensitive = true;  // r = q^{t+1} q^{t*} as a raw 4-vector (E25)
  template <class S, class I, bool M>
  static Accumulator<S> separate(const OperatorInputs<S, I, M>& in, const RegularizerOptions& o, PositionsView<S>,
                                 detail::NonDeducedT<RotationGradientView<S>> gr, FrameScalarsView<S>,
                                 EnergyWorkspace<S>* workspace, ParallelOptions parallel) {
    return relrot(in.rotations, in.graph, o.relrot, gr, workspace, parallel);
  }
  static constexpr unsigned reads = kReadsGraph | kReadsRotations | kNoPositions;
  static constexpr Penalty default_penalty = Penalty::sqrt_weighted;
  static Penalty& penalty_of(RegularizerOptions& o) { return o.relrot.penalty; }
  template <class S, class I, bool M>
  static Status validate_with(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out,
                              const RegularizerOptions& o) {
    return validate_relrot<S>(in.rotations, in.graph, o.relrot, out.rotations);
  }
};

// A term's operator (Accel, Carap, Angle) with each other penalty of the library's list
// (kPenalties: E22 for the smoothness and the angles, E24 for the rigid energies; the default,
// Base::default_penalty, is the operator itself): the same calls with
// Base::penalty_of(options()) = P. Variants of a term, not terms (term = nullptr): the
// fused-step tests find the term's operator by its term. A base provides default_penalty,
// penalty_of(RegularizerOptions&) and validate_with(in, out, options).
struct OperatorName {
  char text[48] = {};
};
constexpr OperatorName variant_name(const char* base, const char* value) {
  OperatorName n;
  std::size_t k = 0;
  for (const char* c = base; *c != 0 && k + 2 < sizeof(n.text); ++c) n.text[k++] = *c;
  n.text[k++] = '_';
  for (const char* c = value; *c != 0 && k + 1 < sizeof(n.text); ++c) n.text[k++] = *c;
  return n;
}
template <class Base, Penalty P>
struct WithPenalty : Base, TermOperator<WithPenalty<Base, P>> {
  // run() and validate() with this options(), not the base's.
  using TermOperator<WithPenalty<Base, P>>::run;
  using TermOperator<WithPenalty<Base, P>>::validate;
  static constexpr Penalty penalty = P;
  // sqrt(w‖r‖² + ε) is k sqrt(ε) per term at r = 0: a still trajectory's energy is not 0.
  static constexpr bool still_floor = P == Penalty::sqrt_weighted;
  static constexpr OperatorName name_text = variant_name(Base::name, to_string(P));
  static constexpr const char* name = name_text.text;  // "accel_norm", "carap_sqrt_weighted", ...
  static constexpr const char* term = nullptr;
  static RegularizerOptions options() {
    RegularizerOptions o = Base::options();
    Base::penalty_of(o) = P;
    return o;
  }
};
// C-ARAP in the neighbour's frame (E24, MoSca's local coordinates): a variant of the term, as
// WithPenalty's, so that central differences, AutoDiffScalar, float, threads and the hard cases
// run on it by the list.
struct CarapNeighborFrame : Carap, TermOperator<CarapNeighborFrame> {
  using TermOperator<CarapNeighborFrame>::run;
  using TermOperator<CarapNeighborFrame>::validate;
  static constexpr const char* name = "carap_frame_neighbor";
  static constexpr const char* term = nullptr;
  static RegularizerOptions options() {
    RegularizerOptions o = Carap::options();
    o.carap.frame = RigidFrame::neighbor;
    return o;
  }
};
// The operators' optional bool traits, false where an operator does not declare one; the generic
// tests read them instead of a name:
//   still_floor: its energy on a still trajectory is a constant above 0 (sqrt_weighted's
//     k sqrt(ε) per term; tests/energy/test_terms.cpp's and test_energy_hard_cases.cpp's hard
//     cases);
//   sign_sensitive: it compares quaternions as raw 4-vectors without choosing a sign (relrot,
//     as D3DGS does), so q and −q, the same rotation, give other outputs; every other operator
//     must not see the sign (tests/stability/test_energy_hard_cases.cpp);
//   graph_free_terms: besides terms along the graph's edges it has terms of single nodes (the
//     fused step's smoothness and angles), so an empty graph does not make its energy 0; an
//     operator that reads the graph without it has only edge terms (the same file).
namespace detail_operators {
template <template <class> class Trait, class Op, class = void>
struct Declared : std::false_type {};
template <template <class> class Trait, class Op>
struct Declared<Trait, Op, std::void_t<Trait<Op>>> : Trait<Op> {};
template <class Op>
using StillFloorOf = std::bool_constant<Op::still_floor>;
template <class Op>
using SignSensitiveOf = std::bool_constant<Op::sign_sensitive>;
template <class Op>
using GraphFreeTermsOf = std::bool_constant<Op::graph_free_terms>;
}  // namespace detail_operators
template <class Op>
constexpr bool still_floor() { return detail_operators::Declared<detail_operators::StillFloorOf, Op>::value; }
template <class Op>
constexpr bool sign_sensitive() { return detail_operators::Declared<detail_operators::SignSensitiveOf, Op>::value; }
template <class Op>
constexpr bool graph_free_terms() { return detail_operators::Declared<detail_operators::GraphFreeTermsOf, Op>::value; }

namespace detail_operators {
template <class Base, std::size_t... K>
auto penalty_operators(std::index_sequence<K...>)
    -> decltype(std::tuple_cat(std::conditional_t<kPenalties[K] == Base::default_penalty, std::tuple<>,
                                                  std::tuple<WithPenalty<Base, kPenalties[K]>>>{}...));
}  // namespace detail_operators
// WithPenalty<Base, P> for every penalty of the list but the base's default.
template <class Base>
using PenaltyOperators = decltype(detail_operators::penalty_operators<Base>(
    std::make_index_sequence<sizeof(kPenalties) / sizeof(kPenalties[0])>{}));

// The fused step (regularizers.hpp) with every term: the confidences it computes (from the
// visibility; the confidence input is not read), C-ARAP, ARAP, LRM and smoothness; returns their
// sum.
struct Regularizers {
  static constexpr const char* name = "regularizers";
  static constexpr const char* term = nullptr;  // the fused step itself
  static constexpr bool graph_free_terms = true;  // smoothness, angles
  static constexpr bool sign_sensitive = true;    // relative rotations
  // Every term of the list on, with its defaults.
  static RegularizerOptions options() {
    RegularizerOptions o;
    for_each_term(o, [](const char*, bool& on, const auto&) { on = true; });
    return o;
  }
  // Its gradient holds the confidences it computes constant (stop-gradient): central
  // differences would move them (test_regularizers.cpp checks it with the confidences off).
  static constexpr bool exact_gradient = false;
  template <class S, class I, bool M>
  static Accumulator<S> run(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out, EnergyWorkspace<S>* workspace = nullptr,
                    ParallelOptions parallel = {}) {
    return regularizers(in.positions, in.rotations, in.visibility, in.graph, options(), out.confidence,
                           out.positions, out.rotations, workspace, parallel)
        .total();
  }
  static constexpr unsigned reads = kReadsGraph | kReadsVisibility | kReadsRotations;
  template <class S, class I, bool M>
  static Status validate(const OperatorInputs<S, I, M>& in, const OperatorOutputs<S>& out) {
    return validate_regularizers(in.positions, in.rotations, in.visibility, in.graph, options(), out.confidence,
                                    out.positions, out.rotations);
  }
};

// The list. A new regulariser gets a struct like the ones above and an entry here; a term of the
// fused step that has none fails test_regularizers.cpp's "every term on the list".
using Operators = decltype(std::tuple_cat(std::tuple<Confidences, Carap, Arap, CarapDirected, Lrm, Accel, Angle, Relrot>{},
                                          PenaltyOperators<Accel>{}, PenaltyOperators<Carap>{},
                                          std::tuple<CarapNeighborFrame>{},
                                          PenaltyOperators<Angle>{}, PenaltyOperators<Relrot>{},
                                          std::tuple<Regularizers>{}));

// Calls f(Op{}) for each operator of the list, in its order.
template <class F>
void for_each_operator(F&& f) {
  std::apply([&](auto... op) { (f(op), ...); }, Operators{});
}

}  // namespace smg::test
