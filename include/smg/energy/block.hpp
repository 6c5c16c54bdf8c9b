// smg/energy/block.hpp — what the regulariser driver (energy/driver.hpp), its terms
// (energy/terms/*.hpp) and the CUDA fused step (cuda/regularizers.cuh) share: the partition of
// the frames into blocks, the per-block view a term reads and writes, the sink of rotation
// gradients, the bytes its scratch keeps under (docs/math/energy.md "The fused regulariser
// pass", "Determinism") and the term concept, checked. No loops over the graph and no thread
// pool: a term header includes this, and CUDA translation units can include it without the
// CPU's parallel.hpp.
//
// The term concept (each energy/terms/<name>.hpp is one; the driver calls these, in this order;
// TermDefaults below gives the ones marked *). detail::check_term<Term, S, I>() states it for the
// compiler: the drivers call it first, so a term that lacks a member, or has it with another
// signature, stops the build at one static_assert naming the member ("smg term concept: ...").
//   void setup(const RegularizerOptions&, const TermShape&)   reads its options (a template on the
//                                           options type: the list defines it after the terms)
//   bool on() const                         computes anything at all (an off term costs nothing)
//   Index reach() const                     frames past a block's end it reads or writes (max δ)
//   Index lanes() const *                   block lengths must be a multiple of this (SIMD lanes)
//   Index preferred_block() const *         frames per block it runs best with (0: no preference;
//                                           used only when every energy term that is on has one)
//   Index stored(Index nr, Index nown) const *  frames a block of nr (nown owned) must store
//   bool reads_rotations() const *, bool position_gradient() const *, bool rotation_gradient() const *
//   Index slot_scalars(const BlockPlan&) const   scratch of one slot (a block in flight)
//   Index fixed_scalars(const BlockPlan&) const *  scratch shared by all blocks
//   void bind(const BlockPlan&, S* fixed, const NeighborsView<S, I>&)   before the blocks; fixed
//                                           has fixed_scalars() scalars (null when 0)
//   struct Block (default-constructible)    the per-block state
//   Block begin(BlockView&, S* slot) const       per block, before its nodes (may fill c)
//   void node(const BlockView&, Block&, Index i, RegularizerResult<S>&) const   per (block, node)
//   void end(const BlockView&, Block&) const *   per block, after its nodes
//   void finish_frame(Index s, S* grad_row) const *  after the spills, per frame (may be a no-op)
//   void finish(RegularizerResult<S>&) const *   the block sums' overall scale
// A term the CUDA element pass runs (cuda/driver.cuh) also has `using Element = ...`, `Element
// element() const` and `static Accumulator<S>& energy_of(RegularizerResult<S>&)`, and the
// Element `bool reads_confidence() const` (checked by check_term too, when Element is named).
// Every term is bit-identical for any thread count because a block owns the rows of its frames
// and writes its overlap only into the spill (driver.hpp).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "smg/core/rotation_gradient.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/options.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

// The fused step's options and energies, defined by energy/term_list.hpp from its list of terms
// (which includes every term's header, so it cannot come first): the concept names them, and a
// term reads them only in member templates, which a driver instantiates after the list.
struct RegularizerOptions;
template <class S>
struct RegularizerResult;

namespace detail {

// The debug assertions' test of an optional per-(frame, node) view: absent, or [T][N] (an
// operator writes through a view it was given, so a wrong shape would write out of bounds).
template <class V>
auto view_absent(const V& v) -> decltype(v.data() == nullptr) {
  return v.data() == nullptr;
}
template <class S>
bool view_absent(const RotationGradientView<S>& v) {
  return v.empty();
}
template <class V>
bool absent_or_shape(const V& v, Index T, Index N) {
  return view_absent(v) || (v.frames() == T && v.nodes() == N);
}

// The debug assertions' test of the views every graph operator (carap, lrm, regularizers) takes
// alike: confidence [T][N] or absent, graph [N][K] (indices and weights), grad_positions
// [T][N][3] or absent. Written once so that the operators assert the same preconditions.
template <class V, class S, class I>
bool graph_operator_shapes(const V& confidence, const NeighborsView<S, I>& graph,
                           PositionsView<S> grad_positions, Index T, Index N) {
  return absent_or_shape(confidence, T, N) && graph.nodes() == N && graph.weights.rows() == N &&
         graph.weights.cols() == graph.k() && absent_or_shape(grad_positions, T, N);
}

// The gradient outputs every regulariser takes, checked alike: positions [T][N][3] and
// rotations (right tangent [T][N][3] or raw quaternions [T][N][4]), each may be empty.
template <class S>
Status validate_gradient_outputs(PositionsView<S> grad_positions,
                                 const RotationGradientView<S>& grad_rotations, Index T, Index N) {
  if (Status s = validate_optional_output(grad_positions, T, N, "grad_positions"); !s) return s;
  if (grad_rotations.is_raw())
    if (Status s = validate_output(grad_rotations.raw(), T, N, "grad_rotations"); !s) return s;
  return validate_optional_output(grad_rotations.tangent(), T, N, "grad_rotations");
}

// The checks of a rotation term's one-term call (angle(), relrot()), in the order of their
// messages: rotations [T][N][4] (nonzero, normalised on entry), the term's own input check and
// its options' (the caller's Status), the rotation gradient (may be empty).
template <class S>
Status validate_rotation_term(QuaternionsView<const S> rotations, const Status& input,
                              const Status& options, const RotationGradientView<S>& grad_rotations) {
  if (Status s = validate_quaternions<S>(rotations, -1, -1, QuaternionNorm::normalize_on_entry,
                                         "rotations");
      !s)
    return s;
  if (!input) return input;
  if (!options) return options;
  return validate_gradient_outputs<S>(PositionsView<S>(), grad_rotations, rotations.frames(),
                                      rotations.nodes());
}

// The bytes of the inputs positions [T][N][3], rotations [T][N][4] and visibility [T][N] (each
// when given) and the graph: the bound the drivers keep their extra memory under.
template <class S, class I>
std::size_t regularizer_input_bytes(Index T, Index N, Index K, bool rotations, bool visibility) {
  std::size_t b = sizeof(S) * static_cast<std::size_t>(3 * T * N);
  if (rotations) b += sizeof(S) * static_cast<std::size_t>(4 * T * N);
  if (visibility) b += static_cast<std::size_t>(T * N);
  b += (sizeof(S) + sizeof(I)) * static_cast<std::size_t>(N * K);
  return b;
}

// The graph with its in-edges, for an element of the CUDA pass that reads its neighbours' terms
// (cuda/driver.cuh, kReadsGraph): graph [N][K], offsets
// [N + 1] and entries (slot i·K + k of each edge into node n, in offsets[n] .. offsets[n + 1]),
// the CUDA driver's ReverseGraph; edge_count = &offsets[N] (the valid edges).
template <class S, class I>
struct ElementGraph {
  NeighborsView<S, I> graph;
  const std::int32_t* in_offsets = nullptr;
  const std::int64_t* in_entries = nullptr;
};

// Frames per block: a function of T and the largest reach only (determinism). A block
// recomputes max δ frames past its end, so longer blocks waste less; about 6 blocks (8 to 32
// frames each) still give the threads of a small machine fair shares. Rounded down so that
// block + max δ is a multiple of 4 (loops over a block's frames then have no scalar remainder).
inline Index carap_block_frames(Index frames, Index max_gap) {
  const Index b = std::min<Index>(32, std::max<Index>(8, (frames + 5) / 6));
  return std::max<Index>(4, b - (b + max_gap) % 4);
}

// The partition of one driver call: a function of the shapes, the terms and the slot count only,
// so that the results never depend on it.
struct BlockPlan {
  Index T = 0, N = 0, K = 0;
  Index B = 0, blocks = 0, G = 0;  // frames per block, blocks, frames spilled past a block
  Index span = 0;                  // stored frames per block (stride bound)
  bool want_x = false, want_r = false;
  Index slots = 1;

  // The stride of a block's per-node frame arrays: a multiple of 4 (whole vector lanes over the
  // frames), except for windows of 1 to 3 frames, which keep their length: a two-frame window
  // padded to 4 did twice the per-(edge, frame) work, half of it on zero frames.
  static Index padded(Index frames) { return frames < 4 ? frames : (frames + 3) / 4 * 4; }
  static Index round_up(Index v, Index m) { return (v + m - 1) / m * m; }
  Index M() const { return K * span; }
  // Every scratch array starts on a 64-byte boundary (its size rounded up to 16 scalars, the
  // slots' base aligned): Eigen's packet sums (sum_array) associate an unaligned head
  // differently, so the energies would otherwise depend on where the workspace or the slot
  // lies (with AVX, whose packets are 32 bytes and malloc's alignment 16).
  static constexpr Index kAlign = 16;
  static Index chunk(Index n) { return round_up(n, kAlign); }
};

// Carves chunk-aligned arrays off a slot, in order.
template <class S>
struct SlotCursor {
  S* p = nullptr;
  S* take(Index n) {
    S* r = p;
    p += BlockPlan::chunk(n);
    return r;
  }
};

// Where rotation gradients go: the caller's tangent [T][N][3] or raw quaternion [T][N][4] rows
// (converted per contribution, (Q5)), and the blocks' rotation spill [blocks][G][N][3].
template <class S>
struct RotationSink {
  QuaternionsView<const S> q;
  TangentsView<S> gr;   // may be empty
  QuaternionsView<S> grq;  // may be empty (raw-quaternion gradient)
  S* spill = nullptr;
  Index G = 0, N = 0;

  S* spill_r(Index b) const { return spill + b * G * N * 3; }
  // Adds one right-tangent contribution g (3 values, stride st) of rotation (t, i).
  void add(Index t, Index i, const S* g, Index st) const {
    const S v[3] = {g[0], g[st], g[2 * st]};
    if (grq.data()) {
      add_quaternion_gradient_from_tangent(q.ptr(t, i), v, grq.ptr(t, i));
    } else {
      S* dst = gr.ptr(t, i);
      dst[0] += v[0];
      dst[1] += v[1];
      dst[2] += v[2];
    }
  }
};

// One block as its terms see it. Frames t0 … te − 1 are stored (nr of them, stride ne ≥ nr,
// padding frames zero); t0 … t1 − 1 are owned (nown): a term computes the terms whose earliest
// frame is owned. Xb holds per node [x; y; z; c] over the stored frames (c only for owned frames;
// 1 where no confidences are computed); GBx per node [3][ne] the block's position gradient
// (null without one).
template <class S, class I>
struct BlockView {
  const BlockPlan* plan = nullptr;
  PositionsView<const S> x;
  QuaternionsView<const S> q;
  NeighborsView<S, I> graph;
  const RotationSink<S>* rot = nullptr;
  Index b = 0, t0 = 0, t1 = 0, te = 0, nr = 0, nown = 0, ne = 0;
  S* Xb = nullptr;
  S* GBx = nullptr;
  bool want_x = false, want_r = false;
  Index n4() const { return 4 * ne; }
  Index n3() const { return 3 * ne; }
  bool grad() const { return want_x || want_r; }
  // Adds a right-tangent rotation gradient g (3 values, stride st) of node n at block frame l: an
  // owned frame straight into the caller's rows (the block owns every node's row at its frames),
  // a frame of the overlap into the block's rotation spill. Every rotation term writes through it.
  void add_rotation(Index l, Index n, const S* g, Index st = 1) const {
    if (l < nown) {
      rot->add(t0 + l, n, g, st);
    } else {
      S* dst = rot->spill_r(b) + (l - nown) * plan->N * 3 + 3 * n;
      dst[0] += g[0];
      dst[1] += g[st];
      dst[2] += g[2 * st];
    }
  }
};

// What a term is set up for (setup(), called by RegularizerTermSet): T frames, N nodes, K
// neighbours, the graph's valid edges (the count Normalization::mean divides by), and whether
// the caller wants the position and rotation gradients.
struct TermShape {
  Index T = 0, N = 0, K = 0, edges = 0;
  bool want_x = false, want_r = false;
};

// The defaults of the term concept, for terms to inherit and override.
struct TermDefaults {
  Index lanes() const { return 1; }
  // Frames per block the term runs best with alone (0: the partition's rule, carap_block_frames).
  Index preferred_block() const { return 0; }
  Index stored(Index nr, Index) const { return nr; }
  bool reads_rotations() const { return false; }
  bool position_gradient() const { return true; }
  bool rotation_gradient() const { return false; }
  Index fixed_scalars(const BlockPlan&) const { return 0; }
  template <class S>
  void finish_frame(Index, S*) const {}
  template <class E>
  void finish(E&) const {}
  // After a block's nodes, before its position gradient leaves the block (relrot's per-node sums
  // become rotation gradients here).
  template <class V, class B>
  void end(const V&, B&) const {}
};

// The defaults of a term with no scratch of its own (each step reads the block's records only,
// as the CUDA element pass's terms do): no slot, nothing to bind, an empty Block.
struct ScratchFreeTerm : TermDefaults {
  Index slot_scalars(const BlockPlan&) const { return 0; }
  template <class S, class I>
  void bind(const BlockPlan&, S*, const NeighborsView<S, I>&) {}
  struct Block {};
  template <class V, class S>
  Block begin(V&, S*) const {
    return {};
  }
};

// A scratch-free term of the rotations only (angle, relrot): it reads them, writes no position
// gradient, and the rotation gradient when the caller wants it (setup() sets want_rotations).
struct ScratchFreeRotationTerm : ScratchFreeTerm {
  bool want_rotations = false;
  bool reads_rotations() const { return true; }
  bool position_gradient() const { return false; }
  bool rotation_gradient() const { return want_rotations; }
};

// ---- The term concept, checked (see the top of this file) ----
// Detection idiom (C++17): Op<Args...> is well-formed.
template <class, template <class...> class Op, class... Args>
struct Detected : std::false_type {};
template <template <class...> class Op, class... Args>
struct Detected<std::void_t<Op<Args...>>, Op, Args...> : std::true_type {};
template <template <class...> class Op, class... Args>
constexpr bool detected_v = Detected<void, Op, Args...>::value;
// Op<Args...> is well-formed and its type converts to R.
template <class R, template <class...> class Op, class... Args>
constexpr bool detected_as() {
  if constexpr (detected_v<Op, Args...>)
    return std::is_convertible<Op<Args...>, R>::value;
  else
    return false;
}

namespace term_members {
template <class T>
using setup = decltype(std::declval<T&>().setup(std::declval<const RegularizerOptions&>(),
                                                std::declval<const TermShape&>()));
template <class T> using on = decltype(std::declval<const T&>().on());
template <class T> using reach = decltype(std::declval<const T&>().reach());
template <class T> using lanes = decltype(std::declval<const T&>().lanes());
template <class T> using preferred_block = decltype(std::declval<const T&>().preferred_block());
template <class T> using stored = decltype(std::declval<const T&>().stored(Index(), Index()));
template <class T> using reads_rotations = decltype(std::declval<const T&>().reads_rotations());
template <class T> using position_gradient = decltype(std::declval<const T&>().position_gradient());
template <class T> using rotation_gradient = decltype(std::declval<const T&>().rotation_gradient());
template <class T>
using slot_scalars = decltype(std::declval<const T&>().slot_scalars(std::declval<const BlockPlan&>()));
template <class T>
using fixed_scalars = decltype(std::declval<const T&>().fixed_scalars(std::declval<const BlockPlan&>()));
template <class T, class S, class I>
using bind = decltype(std::declval<T&>().bind(std::declval<const BlockPlan&>(), std::declval<S*>(),
                                              std::declval<const NeighborsView<S, I>&>()));
template <class T> using block = typename T::Block;
template <class T, class S, class I>
using begin = decltype(std::declval<const T&>().begin(std::declval<BlockView<S, I>&>(), std::declval<S*>()));
template <class T, class S, class I>
using node = decltype(std::declval<const T&>().node(std::declval<const BlockView<S, I>&>(),
                                                    std::declval<typename T::Block&>(), Index(),
                                                    std::declval<RegularizerResult<S>&>()));
template <class T, class S, class I>
using end = decltype(std::declval<const T&>().end(std::declval<const BlockView<S, I>&>(),
                                                  std::declval<typename T::Block&>()));
template <class T, class S>
using finish_frame = decltype(std::declval<const T&>().finish_frame(Index(), std::declval<S*>()));
template <class T, class S>
using finish = decltype(std::declval<const T&>().finish(std::declval<RegularizerResult<S>&>()));
template <class T> using element_type = typename T::Element;
template <class T> using element = decltype(std::declval<const T&>().element());
template <class T, class S>
using energy_of = decltype(T::energy_of(std::declval<RegularizerResult<S>&>()));
template <class E> using reads_confidence = decltype(std::declval<const E&>().reads_confidence());
}  // namespace term_members

// Whether Term names an Element (the CUDA element pass runs it).
template <class Term>
constexpr bool has_element_v = detected_v<term_members::element_type, Term>;

// What an Element reads, for the drivers that run it (cuda/driver.cuh, energy/element_pass.hpp).
// An Element that reads the rotations says so (`static constexpr bool kReadsRotations = true`,
// AngleElement): its step then also takes q [T][N][4] and the rotation gradient rows,
// at(t, n, x, q, conf, grad_x, grad_tangent, grad_raw, energy).
template <class E, class = void>
struct ElementReadsRotations : std::false_type {};
template <class E>
struct ElementReadsRotations<E, std::void_t<decltype(E::kReadsRotations)>>
    : std::integral_constant<bool, E::kReadsRotations> {};
// An Element along the edges (`static constexpr bool kReadsGraph = true`, RelrotElement) reads
// the graph and its in-edges (ElementGraph: the gradient of its node from the terms of the edges
// into it, no atomics) and the rotations: at(t, n, q, graph, grad_tangent, grad_raw, energy).
template <class E, class = void>
struct ElementReadsGraph : std::false_type {};
template <class E>
struct ElementReadsGraph<E, std::void_t<decltype(E::kReadsGraph)>>
    : std::integral_constant<bool, E::kReadsGraph> {};

// The term concept for the compiler: one static_assert per member, each naming it, so that a term
// that misses one stops at a line that says which. Returns whether Term models the concept, so
// that the drivers compile nothing more for a term that does not (no template errors deep inside
// drive() after the static_asserts). Why not one trait: a single "is a term" false would not say
// what is missing.
template <class Term, class S, class I>
constexpr bool check_block_members() {
  namespace m = term_members;
  if constexpr (!detected_v<m::block, Term>) {
    return false;
  } else {
    constexpr bool def = std::is_default_constructible<typename Term::Block>::value;
    static_assert(def, "smg term concept: Block must be default-constructible (an off term gets Block{})");
    constexpr bool beg = detected_as<typename Term::Block, m::begin, Term, S, I>();
    static_assert(beg, "smg term concept: Block begin(BlockView<S, I>&, S* slot) const is missing");
    constexpr bool nod = detected_v<m::node, Term, S, I>;
    static_assert(nod, "smg term concept: void node(const BlockView<S, I>&, Block&, Index, RegularizerResult<S>&) const is missing");
    constexpr bool fin = detected_v<m::end, Term, S, I>;
    static_assert(fin, "smg term concept: void end(const BlockView<S, I>&, Block&) const is missing (derive from detail::TermDefaults)");
    return def && beg && nod && fin;
  }
}
template <class Term, class S>
constexpr bool check_element_members() {
  namespace m = term_members;
  if constexpr (!has_element_v<Term>) {
    return true;  // the CUDA element pass does not run it: nothing more to have
  } else {
    constexpr bool el = detected_as<typename Term::Element, m::element, Term>();
    static_assert(el, "smg term concept: a term naming an Element needs Element element() const");
    constexpr bool en = detected_as<Accumulator<S>&, m::energy_of, Term, S>();
    static_assert(en, "smg term concept: a term naming an Element needs static Accumulator<S>& energy_of(RegularizerResult<S>&)");
    constexpr bool rc = detected_as<bool, m::reads_confidence, typename Term::Element>();
    static_assert(rc, "smg term concept: an Element needs bool reads_confidence() const");
    return el && en && rc;
  }
}
template <class Term, class S, class I>
constexpr bool check_term() {
  namespace m = term_members;
  constexpr bool setup = detected_v<m::setup, Term>;
  static_assert(setup, "smg term concept: void setup(const RegularizerOptions&, const TermShape&) is missing");
  constexpr bool on = detected_as<bool, m::on, Term>();
  static_assert(on, "smg term concept: bool on() const is missing");
  constexpr bool reach = detected_as<Index, m::reach, Term>();
  static_assert(reach, "smg term concept: Index reach() const is missing");
  constexpr bool lanes = detected_as<Index, m::lanes, Term>();
  static_assert(lanes, "smg term concept: Index lanes() const is missing (derive from detail::TermDefaults)");
  constexpr bool pref = detected_as<Index, m::preferred_block, Term>();
  static_assert(pref, "smg term concept: Index preferred_block() const is missing (derive from detail::TermDefaults)");
  constexpr bool stored = detected_as<Index, m::stored, Term>();
  static_assert(stored, "smg term concept: Index stored(Index nr, Index nown) const is missing (derive from detail::TermDefaults)");
  constexpr bool rrot = detected_as<bool, m::reads_rotations, Term>();
  static_assert(rrot, "smg term concept: bool reads_rotations() const is missing (derive from detail::TermDefaults)");
  constexpr bool gx = detected_as<bool, m::position_gradient, Term>();
  static_assert(gx, "smg term concept: bool position_gradient() const is missing (derive from detail::TermDefaults)");
  constexpr bool gr = detected_as<bool, m::rotation_gradient, Term>();
  static_assert(gr, "smg term concept: bool rotation_gradient() const is missing (derive from detail::TermDefaults)");
  constexpr bool slot = detected_as<Index, m::slot_scalars, Term>();
  static_assert(slot, "smg term concept: Index slot_scalars(const BlockPlan&) const is missing");
  constexpr bool fixed = detected_as<Index, m::fixed_scalars, Term>();
  static_assert(fixed, "smg term concept: Index fixed_scalars(const BlockPlan&) const is missing (derive from detail::TermDefaults)");
  constexpr bool bind = detected_v<m::bind, Term, S, I>;
  static_assert(bind, "smg term concept: void bind(const BlockPlan&, S* fixed, const NeighborsView<S, I>&) is missing");
  constexpr bool block = detected_v<m::block, Term>;
  static_assert(block, "smg term concept: the per-block state `struct Block` is missing");
  constexpr bool frame = detected_v<m::finish_frame, Term, S>;
  static_assert(frame, "smg term concept: void finish_frame(Index, S* grad_row) const is missing (derive from detail::TermDefaults)");
  constexpr bool fin = detected_v<m::finish, Term, S>;
  static_assert(fin, "smg term concept: void finish(RegularizerResult<S>&) const is missing (derive from detail::TermDefaults)");
  constexpr bool blk = check_block_members<Term, S, I>();
  constexpr bool elem = check_element_members<Term, S>();
  return setup && on && reach && lanes && pref && stored && rrot && gx && gr && slot && fixed && bind && block &&
         frame && fin && blk && elem;
}

}  // namespace detail

}  // namespace smg
