// smg/energy/block.hpp — what the regulariser driver (energy/driver.hpp), its terms
// (energy/terms/*.hpp) and the CUDA fused step (cuda/regularizers.cuh) share: the partition of
// the frames into blocks, the per-block view a term reads and writes, the sink of rotation
// gradients, the argument checks of the fused step and the bytes its scratch keeps
// under (docs/math/energy.md "The fused regulariser pass", "Determinism"). No loops over the graph
// and no thread pool: a term header includes this, and CUDA translation units can include it
// without the CPU's parallel.hpp.
//
// The term concept (each energy/terms/<name>.hpp is one; the driver calls these, in this order):
//   bool on() const                         computes anything at all (an off term costs nothing)
//   Index reach() const                     frames past a block's end it reads or writes (max δ)
//   Index lanes() const                     block lengths must be a multiple of this (SIMD lanes)
//   Index preferred_block() const           frames per block it runs best with (0: no preference;
//                                           used only when every energy term that is on has one)
//   Index stored(Index nr, Index nown) const  frames a block of nr (nown owned) must store
//   bool reads_rotations() const, bool position_gradient() const, bool rotation_gradient() const
//   Index slot_scalars(const BlockPlan&) const   scratch of one slot (a block in flight)
//   Index fixed_scalars(const BlockPlan&) const  scratch shared by all blocks
//   void bind(const BlockPlan&, S* fixed)        before the blocks; fixed has fixed_scalars()
//   Block begin(BlockView&, S* slot) const       per block, before its nodes (may fill c)
//   void node(const BlockView&, Block&, Index i, Energies&) const   per (block, node)
//   void finish_frame(Index s, S* grad_row) const  after the spills, per frame (may be a no-op)
//   void finish(Energies&) const                 the block sums' overall scale
// Every term is bit-identical for any thread count because a block owns the rows of its frames
// and writes its overlap only into the spill (driver.hpp).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cstdint>

#include "smg/core/rotation_gradient.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/common.hpp"
#include "smg/energy/options.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

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

  static Index padded(Index frames) { return (frames + 3) / 4 * 4; }
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
};

}  // namespace detail

// Checks the arguments of regularizers(); one line naming the bad argument. `rotations` may be
// empty when neither C-ARAP nor ARAP is on; `visibility` [T][N] (0/1) may be empty (all
// visible); `confidence` (output [T][N]) may be given only with terms.confidence; the
// gradients may be empty (not computed).
template <class S, class I>
Status validate_regularizers(detail::NonDeducedT<PositionsView<const S>> positions,
                             detail::NonDeducedT<QuaternionsView<const S>> rotations,
                             VisibilityView<const std::uint8_t> visibility,
                             const NeighborsView<S, I>& graph, const RegularizerOptions& options,
                             FrameScalarsView<S> confidence = {},
                             PositionsView<S> grad_positions = {},
                             detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  const RegularizerTerms& on = options.terms;
  if (Status s = validate_positions<S>(positions, -1, -1, "positions"); !s) return s;
  if (on.carap || on.arap || rotations.data() != nullptr)
    if (Status s = validate_quaternions<S>(rotations, T, N, QuaternionNorm::normalize_on_entry,
                                           "rotations");
        !s)
      return s;
  if (visibility.data() != nullptr)
    if (Status s = validate_visibility<std::uint8_t>(visibility, T, N, "visibility"); !s) return s;
  if (Status s = validate_neighbors(graph, N, "graph"); !s) return s;
  if (Status s = validate_options(options); !s) return s;
  if (confidence.data() != nullptr && !on.confidence)
    return Status::error("confidence: an output was given but options.terms.confidence is off");
  if (Status s = validate_optional_output(confidence, T, N, "confidence"); !s) return s;
  return detail::validate_gradient_outputs<S>(grad_positions, grad_rotations, T, N);
}

}  // namespace smg
