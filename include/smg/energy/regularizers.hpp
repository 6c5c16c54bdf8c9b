// smg/energy/regularizers.hpp — the regulariser step in one pass: node confidences (E2)-(E6),
// C-ARAP (E7)-(E10), plain ARAP ((E9) with c ≡ 1, α = 1), LRM (E11)-(E16) and trajectory
// smoothness (E21), any subset, with the gradients of the energies, from one walk over the graph
// (docs/math/energy.md "The fused regulariser pass").
//
// Why one pass: a trainer calls all of them every iteration, and the separate operators each
// gather the same neighbourhoods again and keep their own scratch. This header only names the
// terms and checks the arguments: the walk is the CPU driver's (energy/driver.hpp: frames cut
// into blocks, each node's neighbourhood over a block's frames gathered once, results
// bit-identical for any thread count), each term is one header in energy/terms/ built on the
// element functions (elements/confidence.hpp, elements/carap.hpp, elements/lrm.hpp, common.hpp), and
// RegularizerTermSet below is the list of them. Confidences are computed first, per block, into
// the gathered records: C-ARAP, LRM and (confidence-weighted) smoothness read c at the earlier
// frame (E7), which the block owns, as constants (stop-gradient).
//
// Memory: what driver.hpp says, in the EnergyWorkspace, plus per block (not per node) a few
// vectors of O(K) entries (LRM's lanes, C-ARAP's active edges). No T·N·K and no T·N·3 scratch
// (the raw-quaternion gradient is converted per contribution). The number of slots is lowered
// until the total is at most the bytes of the inputs (positions, rotations, visibility, graph);
// only one slot is left where even that exceeds them, which happens for short sequences: one
// slot (7·N·S_b) plus the spill (about 6·N·max δ per block of 8 to 32 frames) against 7·N·T of
// inputs; with N = 5000, K = 8 or 16, all terms and gradients, float, up to T ≈ 20 frames
// (measured). regularizers_extra_bytes() returns the figure; tests/energy/test_regularizers.cpp
// checks it against the workspace.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <type_traits>

#include "smg/core/parallel.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/driver.hpp"
#include "smg/energy/options.hpp"
#include "smg/energy/validate.hpp"
#include "smg/energy/term_list.hpp"
#include "smg/energy/workspace.hpp"
// Each term of the list with its separate operator (the one-term call, which includes the term's
// header): including the fused step gives every regulariser, and a new term is included here,
// where it joins RegularizerTermSet, and nowhere else.
#include "smg/energy/accel.hpp"
#include "smg/energy/angle.hpp"
#include "smg/energy/relrot.hpp"
#include "smg/energy/arap.hpp"
#include "smg/energy/carap.hpp"
#include "smg/energy/confidence.hpp"
#include "smg/energy/lrm.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

inline namespace SMG_ISA_NAMESPACE {

// The extra bytes regularizers() allocates for these shapes, options, outputs and thread count
// (the workspace it fills; see the header comment), and the input bytes it keeps under.
template <class S, class I>
std::size_t regularizers_extra_bytes(Index frames, Index nodes, Index k,
                                     const RegularizerOptions& options, bool grad_positions,
                                     bool grad_rotations, bool rotations_given,
                                     bool visibility_given, ParallelOptions parallel = {}) {
  if (frames == 0 || nodes == 0) return 0;
  // Edges are counted for Normalization::mean only; the sizes do not depend on them.
  detail::RegularizerTermSet<S, I> terms(frames, nodes, k, nodes * k, options, grad_positions,
                                         grad_rotations);
  const Index n = terms.apply([&](const auto&... t) {
    if (detail::element_schedule<S, I>(t...)) return Index(0);  // the element pass keeps no scratch
    const detail::BlockPlan p = detail::fitted_plan<S, I>(frames, nodes, k, grad_positions, grad_rotations,
                                                          parallel, rotations_given, visibility_given, t...);
    return detail::driver_total_scalars<S>(p, t...);
  });
  return sizeof(S) * static_cast<std::size_t>(n);
}

// The fused regulariser step: any subset of confidences (E6), C-ARAP (E9), ARAP, LRM (E14),
// trajectory smoothness (E21), the rotation-angle term (E23) and relative-rotation consistency
// (E25) (options.terms) in one pass over the graph; returns the energies,
// each equal to what node_confidences + carap()/arap()/lrm() give on the same inputs (to
// rounding: the sums are associated differently, see tests/energy/test_regularizers.cpp).
//   positions [T][N][3]; rotations [T][N][4] (w, x, y, z; normalised on entry), may be empty
//   without C-ARAP, ARAP, angle and relrot (reads_rotations); visibility [T][N] (0/1) multiplies the
//   confidences (E6), empty = all visible. confidence [T][N]: with options.terms.confidence an
//   output, receiving c_{t,i}; without, an input when given: the caller's c (in [0, 1];
//   visibility not applied), which C-ARAP, LRM, confidence-weighted smoothness and angle read as
//   their separate calls read theirs (empty: c ≡ 1). Why both in one view: a trainer that
//   refreshes its confidences every few iterations, or takes them from elsewhere, passes them
//   here and keeps one call.
//   grad_positions [T][N][3] and grad_rotations (right tangent [T][N][3] or raw quaternion
//   [T][N][4], (Q5)) receive the gradient of the energies, *added* to their contents.
// Confidences are constants for the gradient (stop-gradient), as in the separate operators.
// Bit-identical for any thread count. Scalars: float, double, or an autodiff scalar (one frame
// per lane). Precondition: validate_regularizers.
template <class S, class I>
RegularizerResult<S> regularizers(
    detail::NonDeducedT<PositionsView<const S>> positions,
    detail::NonDeducedT<QuaternionsView<const S>> rotations,
    VisibilityView<const std::uint8_t> visibility, const NeighborsView<S, I>& graph,
    const RegularizerOptions& options, FrameScalarsView<S> confidence = {},
    PositionsView<S> grad_positions = {},
    detail::NonDeducedT<RotationGradientView<S>> grad_rotations = {},
    EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes(), K = graph.k();
  SMG_ASSERT(!reads_rotations(options.terms) || (rotations.frames() == T && rotations.nodes() == N),
             "regularizers: rotations shape");
  SMG_ASSERT(detail::graph_operator_shapes(confidence, graph, grad_positions, T, N),
             "regularizers: confidence, graph or grad_positions shape");
  SMG_ASSERT(detail::absent_or_shape(visibility, T, N), "regularizers: visibility shape");
  SMG_ASSERT(detail::absent_or_shape(grad_rotations, T, N), "regularizers: grad_rotations shape");
  if (T == 0 || N == 0) return {};
  const bool want_x = grad_positions.data() != nullptr, want_r = !grad_rotations.empty();
  detail::RegularizerTermSet<S, I> terms(T, N, K, edge_count(graph), options, want_x, want_r);
  if (!terms.any_energy() && !options.terms.confidence) return {};
  terms.confidence.vis = visibility;
  if (options.terms.confidence)
    terms.confidence.out = confidence;
  else
    terms.confidence.given = FrameScalarsView<const S>(confidence.data(), confidence.frames(), confidence.nodes());
  return terms.apply([&](auto&... t) {
    return detail::drive_views<S, I>(positions, rotations, visibility.data() != nullptr, graph,
                                     grad_positions, grad_rotations, workspace, parallel, t...);
  });
}

}  // inline namespace SMG_ISA_NAMESPACE

}  // namespace smg
