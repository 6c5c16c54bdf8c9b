// smg/energy/driver.hpp — the CPU driver of the regulariser terms: any set of terms
// (energy/terms/*.hpp; the concept is in energy/block.hpp) in one pass over the graph, the
// frames cut into blocks (docs/math/energy.md "The fused regulariser pass"). Per block it
// gathers the block's frames node-major (one contiguous record [x; y; z; c] per node, so a
// neighbour's frames are one cache-friendly read), lets each term fill what it fills per block
// (the confidences), then calls every term per node, in the order given, and each term's end().
//
// Determinism: a block owns the gradient rows of its frames; contributions to the up to
// max(reach) frames past its end go to per-block spill buffers added afterwards in block order.
// No float atomics: the results are bit-identical for any thread count, in float and double.
//
// Memory (all in the EnergyWorkspace): per slot (a block in flight) 4·N·S_b for the records,
// 3·N·S_b for the block's position gradient and what the terms ask for (slot_scalars), with
// S_b = the block's stored frames (at most 32 + max reach, rounded up to 4 from 4 on); shared: the spill
// 2·blocks·G·N·3 (positions, rotations) and the terms' fixed_scalars. The number of slots
// (≤ threads, ≤ blocks) is lowered until the total is at most `bound` bytes (the caller passes
// its inputs' size); one slot is left where even that exceeds it.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cstddef>
#include <tuple>
#include <utility>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/scalar.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/block.hpp"
#include "smg/energy/element_pass.hpp"
#include "smg/energy/term_list.hpp"  // RegularizerResult
#include "smg/energy/terms/confidence.hpp"
#include "smg/energy/workspace.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {
namespace detail {

inline namespace SMG_ISA_NAMESPACE {

// What the driver reads and writes (views over the caller's memory).
template <class S, class I>
struct DriverIO {
  PositionsView<const S> x;
  QuaternionsView<const S> q;        // may be empty when no term reads rotations
  NeighborsView<S, I> graph;
  PositionsView<S> gx;               // may be empty
  TangentsView<S> gr;                // may be empty
  QuaternionsView<S> grq;            // may be empty (raw-quaternion gradient)
};

// Stored frames of a block with nr frames (incl. the overlap) and nown owned: the most any term
// asks for.
template <class... Terms>
Index driver_stored(Index nr, Index nown, const Terms&... terms) {
  Index s = nr;
  ((s = terms.on() ? std::max(s, terms.stored(nr, nown)) : s), ...);
  return s;
}

// The partition for these terms (a function of shapes, terms and `threads` only).
template <class... Terms>
BlockPlan driver_plan(Index T, Index N, Index K, bool want_x, bool want_r, Index threads,
                      const Terms&... terms) {
  BlockPlan p;
  p.T = T;
  p.N = N;
  p.K = K;
  Index lanes = 1, preferred = 0;
  bool pos = false, rot = false, all_prefer = true;
  ((terms.on() ? (p.G = std::max(p.G, terms.reach()), lanes = std::max(lanes, terms.lanes()),
                  pos = pos || terms.position_gradient(), rot = rot || terms.rotation_gradient(),
                  preferred = std::max(preferred, terms.preferred_block()),
                  all_prefer = all_prefer && (terms.reach() == 0 || terms.preferred_block() > 0),
                  0)
               : 0),
   ...);
  p.want_x = want_x && pos;
  p.want_r = want_r && rot;
  // The partition's rule, unless every energy term that is on prefers its own block length.
  p.B = all_prefer && preferred > 0 ? preferred : carap_block_frames(T, p.G);
  if (lanes > 1) p.B = BlockPlan::round_up(p.B, lanes);
  p.blocks = T > 0 ? (T + p.B - 1) / p.B : 0;
  p.span = BlockPlan::padded(driver_stored(p.B + p.G, p.B, terms...));
  p.slots = std::max<Index>(1, std::min<Index>(threads, p.blocks));
  return p;
}

template <class S, class... Terms>
Index driver_slot_scalars(const BlockPlan& p, const Terms&... terms) {
  Index s = BlockPlan::chunk(4 * p.N * p.span);
  if (p.want_x) s += BlockPlan::chunk(3 * p.N * p.span);
  ((s += terms.on() ? terms.slot_scalars(p) : 0), ...);
  return s;
}
inline Index driver_spill_scalars(const BlockPlan& p) {
  return (p.want_x ? p.blocks * p.G * p.N * 3 : 0) + (p.want_r ? p.blocks * p.G * p.N * 3 : 0);
}
// The terms' shared scratch (fixed_scalars of every term that is on).
template <class... Terms>
Index driver_term_fixed_scalars(const BlockPlan& p, const Terms&... terms) {
  Index s = 0;
  ((s += terms.on() ? terms.fixed_scalars(p) : 0), ...);
  return s;
}
template <class... Terms>
Index driver_fixed_scalars(const BlockPlan& p, const Terms&... terms) {
  return driver_spill_scalars(p) + BlockPlan::kAlign + driver_term_fixed_scalars(p, terms...);
}
template <class S, class... Terms>
Index driver_total_scalars(const BlockPlan& p, const Terms&... terms) {
  return p.slots * driver_slot_scalars<S>(p, terms...) + driver_fixed_scalars(p, terms...);
}

// Lowers the slot count until the scratch fits in `bound` bytes (at least one slot).
template <class S, class... Terms>
void driver_fit_slots(BlockPlan& p, std::size_t bound, const Terms&... terms) {
  while (p.slots > 1 &&
         sizeof(S) * static_cast<std::size_t>(driver_total_scalars<S>(p, terms...)) > bound)
    --p.slots;
}

// Each term's per-block state, in list order (the confidences fill the records first); off
// terms get an empty one (begin() may allocate).
template <class S, class I, std::size_t... Is, class... Terms>
std::tuple<typename Terms::Block...> begin_blocks(BlockView<S, I>& v, S* const* slots,
                                                  std::index_sequence<Is...>,
                                                  const Terms&... terms) {
  return {(terms.on() ? terms.begin(v, slots[Is]) : typename Terms::Block{})...};
}

template <class E, class S, class I, class... Terms>
E drive_checked(const DriverIO<S, I>& io, const BlockPlan& p, EnergyWorkspace<S>* workspace,
                ParallelOptions parallel, Terms&... terms);

// Runs every term that is on over all blocks; returns the energies E (each term adds to its own
// fields; finish() scales them). Terms are bound (bind) here, so a term object serves one call.
// The concept first (energy/block.hpp check_term): a term that misses a member stops the build at
// the static_assert naming it, and nothing more of the driver is compiled for it.
template <class E, class S, class I, class... Terms>
E drive(const DriverIO<S, I>& io, const BlockPlan& p, EnergyWorkspace<S>* workspace,
        ParallelOptions parallel, Terms&... terms) {
  constexpr bool models = (check_term<Terms, S, I>() && ...);
  if constexpr (models)
    return drive_checked<E>(io, p, workspace, parallel, terms...);
  else
    return E();
}

// drive(), its terms checked.
template <class E, class S, class I, class... Terms>
E drive_checked(const DriverIO<S, I>& io, const BlockPlan& p, EnergyWorkspace<S>* workspace,
                ParallelOptions parallel, Terms&... terms) {
  E result;
  const Index T = p.T, N = p.N, K = p.K;
  if (T == 0 || N == 0) return result;
  WorkspaceRef<S> ws(workspace);
  const Index fixed_terms = driver_term_fixed_scalars(p, terms...);
  // The spill and the terms' shared scratch in one workspace buffer (none when both are empty:
  // then no pointer below is offset).
  S* spill = nullptr;
  if (driver_spill_scalars(p) + fixed_terms > 0)
    spill = ws->spill(static_cast<std::size_t>(driver_spill_scalars(p) + fixed_terms));
  {
    S* f = spill ? spill + driver_spill_scalars(p) : nullptr;
    ((terms.on() ? (terms.bind(p, f, io.graph), f = f ? f + terms.fixed_scalars(p) : f, 0) : 0),
     ...);
  }
  const Index per_slot = driver_slot_scalars<S>(p, terms...);
  // The slots' base on a 64-byte boundary (BlockPlan::chunk; kAlign covers the workspace's).
  S* scratch = ws->scratch_aligned(static_cast<std::size_t>(p.slots * per_slot));
  RotationSink<S> rot;
  rot.q = io.q;
  rot.gr = io.gr;
  rot.grq = io.grq;
  rot.G = p.G;
  rot.N = N;
  // Block b's position spill: G frames of [N][3] (the rotation spill follows, RotationSink).
  auto spill_x = [&](Index b) { return spill + b * p.G * N * 3; };
  rot.spill = spill && p.want_x ? spill + p.blocks * p.G * N * 3 : spill;
  bool reads_q = false;
  ((reads_q = reads_q || (terms.on() && terms.reads_rotations())), ...);

  auto run_block = [&](Index b, Index slot) {
    BlockView<S, I> v;
    v.plan = &p;
    v.x = io.x;
    v.q = io.q;
    v.graph = io.graph;
    v.rot = &rot;
    v.b = b;
    v.t0 = b * p.B;
    v.t1 = std::min(T, v.t0 + p.B);
    v.te = std::min(T, v.t1 + p.G);
    v.nr = v.te - v.t0;
    v.nown = v.t1 - v.t0;
    v.ne = BlockPlan::padded(driver_stored(v.nr, v.nown, terms...));
    v.want_x = p.want_x;
    v.want_r = p.want_r;
    const Index ne = v.ne, n4 = v.n4(), n3 = v.n3();
    SlotCursor<S> cur{scratch + slot * per_slot};
    v.Xb = cur.take(4 * N * p.span);
    v.GBx = p.want_x ? cur.take(3 * N * p.span) : nullptr;
    S* term_slot[sizeof...(Terms) + 1];
    {
      std::size_t k = 0;
      ((term_slot[k++] = cur.p, cur.p += terms.on() ? terms.slot_scalars(p) : 0), ...);
    }
    // The block's frames node-major (contiguous per neighbour: the strided [T][N][3] layout
    // would cost a cache line per frame and neighbour).
    std::fill(v.Xb, v.Xb + N * n4, S(0));
    // Rotation terms add into the block's rotation spill (a term need not write every entry).
    if (p.want_r && p.G > 0) std::fill(rot.spill_r(b), rot.spill_r(b) + p.G * N * 3, S(0));
    // No positions when no term reads them (a one-term call of a rotation term).
    for (Index l = 0; io.x.data() != nullptr && l < v.nr; ++l) {
      const S* row = io.x.ptr(v.t0 + l, 0);
      for (Index j = 0; j < N; ++j) {
        S* dst = v.Xb + j * n4 + l;
        dst[0] = row[3 * j];
        dst[ne] = row[3 * j + 1];
        dst[2 * ne] = row[3 * j + 2];
      }
    }
    if (v.GBx) std::fill(v.GBx, v.GBx + N * n3, S(0));
    std::tuple<typename Terms::Block...> blocks =
        begin_blocks(v, term_slot, std::index_sequence_for<Terms...>{}, terms...);
    // Neighbours are random in memory: the next node's data is requested while this node
    // computes.
    auto prefetch_node = [&](Index i) {
      constexpr Index line = 64 / static_cast<Index>(sizeof(S));
      if (reads_q)
        for (Index l = 0; l < v.nr; ++l) SMG_PREFETCH(io.q.ptr(v.t0 + l, i), 0);
      for (Index kk = 0; kk < K; ++kk) {
        const Index j = io.graph.indices(i, kk);
        if (j < 0) break;
        for (Index o = 0; o < n4; o += line) SMG_PREFETCH(v.Xb + j * n4 + o, 0);
        if (v.GBx)
          for (Index o = 0; o < n3; o += line) SMG_PREFETCH(v.GBx + j * n3 + o, 1);
      }
    };
    if (N > 0) prefetch_node(0);
    E energy;
    for (Index i = 0; i < N; ++i) {
      if (i + 1 < N) prefetch_node(i + 1);
      std::apply([&](auto&... blk) { ((terms.on() ? (terms.node(v, blk, i, energy), 0) : 0), ...); },
                 blocks);
    }
    std::apply([&](auto&... blk) { ((terms.on() ? (terms.end(v, blk), 0) : 0), ...); }, blocks);
    // Owned frames into the caller's rows, the overlap into this block's spill.
    if (v.GBx)
      for (Index l = 0; l < v.nr; ++l) {
        const bool own = l < v.nown;
        S* row = own ? io.gx.ptr(v.t0 + l, 0) : spill_x(b) + (l - v.nown) * N * 3;
        for (Index j = 0; j < N; ++j) {
          const S* src = v.GBx + j * n3 + l;
          if (own) {
            row[3 * j] += src[0];
            row[3 * j + 1] += src[ne];
            row[3 * j + 2] += src[2 * ne];
          } else {
            row[3 * j] = src[0];
            row[3 * j + 1] = src[ne];
            row[3 * j + 2] = src[2 * ne];
          }
        }
      }
    return energy;
  };

  std::vector<E> partial(static_cast<std::size_t>(p.blocks));
  SlotPool pool(p.slots);
  ParallelOptions po = parallel;
  po.grain = 1;
  po.threads = static_cast<int>(p.slots);
  parallel_for_chunks(
      p.blocks,
      [&](Index b, Index, Index) {
        const Index slot = pool.acquire();
        struct Release {
          SlotPool& pl;
          Index s;
          ~Release() { pl.release(s); }
        } release{pool, slot};
        partial[static_cast<std::size_t>(b)] = run_block(b, slot);
      },
      po);
  for (const E& e : partial) result += e;
  ((terms.on() ? (terms.finish(result), 0) : 0), ...);

  if (p.want_x || p.want_r) {
    // Spills into the frames past each block, in block order (deterministic); then what terms
    // add per frame (LRM's last-frame term on frame T − 2).
    parallel_for(
        T,
        [&](Index begin, Index end) {
          for (Index s = begin; s < end; ++s) {
            for (Index b = 0; b < p.blocks; ++b) {
              const Index t1 = std::min(T, b * p.B + p.B);
              const Index te = std::min(T, t1 + p.G);
              if (s < t1 || s >= te) continue;
              if (p.want_x) {
                const S* src = spill_x(b) + (s - t1) * N * 3;
                S* dst = io.gx.ptr(s, 0);
                for (Index c = 0; c < 3 * N; ++c) dst[c] += src[c];
              }
              if (p.want_r) {
                const S* src = rot.spill_r(b) + (s - t1) * N * 3;
                for (Index j = 0; j < N; ++j) rot.add(s, j, src + 3 * j, 1);
              }
            }
            if (p.want_x) ((terms.on() ? (terms.finish_frame(s, io.gx.ptr(s, 0)), 0) : 0), ...);
          }
        },
        parallel);
  }
  return result;
}

// The plan for these terms, its slots fitted under the bytes of the inputs (positions,
// rotations and visibility when given, and the graph).
template <class S, class I, class... Terms>
BlockPlan fitted_plan(Index T, Index N, Index K, bool want_x, bool want_r, ParallelOptions parallel,
                      bool rotations, bool visibility, const Terms&... terms) {
  const Index threads = parallel.threads > 0 ? parallel.threads : num_threads();
  BlockPlan p = driver_plan(T, N, K, want_x, want_r, threads, terms...);
  driver_fit_slots<S>(p, regularizer_input_bytes<S, I>(T, N, K, rotations, visibility), terms...);
  return p;
}

// An operator's call of the driver over the caller's views (the fused step with its term list,
// carap(), lrm(), accel() with one term): the fitted plan, the views, the pass. Returns the
// energies.
template <class S, class I, class... Terms>
RegularizerResult<S> drive_views(PositionsView<const S> positions, QuaternionsView<const S> rotations,
                                 bool visibility_given, const NeighborsView<S, I>& graph,
                                 PositionsView<S> grad_positions, RotationGradientView<S> grad_rotations,
                                 EnergyWorkspace<S>* workspace, ParallelOptions parallel,
                                 Terms&... terms) {
  // The concept before the plan reads the terms (see drive()).
  constexpr bool models = (check_term<Terms, S, I>() && ...);
  if constexpr (!models) {
    return RegularizerResult<S>();
  } else {
    // Terms that are all per-(frame, node) steps reading no graph run by nodes on every core
    // (energy/element_pass.hpp); the rest by frame blocks below.
    if (element_schedule<S, I>(terms...)) {
      bool pos = false, rot = false;
      ((terms.on() ? (pos = pos || terms.position_gradient(), rot = rot || terms.rotation_gradient(), 0)
                   : 0),
       ...);
      return drive_elements<RegularizerResult<S>, S, I>(
          positions, rotations, positions.nodes(), pos ? grad_positions.data() : nullptr,
          rot ? grad_rotations.tangent().data() : nullptr, rot ? grad_rotations.raw().data() : nullptr,
          parallel, terms...);
    }
    const BlockPlan p = fitted_plan<S, I>(positions.frames(), positions.nodes(), graph.k(),
                                          grad_positions.data() != nullptr, !grad_rotations.empty(),
                                          parallel, rotations.data() != nullptr, visibility_given,
                                          terms...);
    DriverIO<S, I> io;
    io.x = positions;
    io.q = rotations;
    io.graph = graph;
    if (p.want_x) io.gx = grad_positions;
    if (p.want_r) {
      io.gr = grad_rotations.tangent();
      io.grq = grad_rotations.raw();
    }
    return drive_checked<RegularizerResult<S>>(io, p, workspace, parallel, terms...);
  }
}

// A one-term operator's pass (carap(), lrm(), accel()): its term with the caller's confidences
// (`confidence`, or 1 where empty) and no confidence computation, through drive_views. Returns
// the energies.
template <class S, class I, class Term>
RegularizerResult<S> drive_one_term(PositionsView<const S> positions,
                                    QuaternionsView<const S> rotations,
                                    FrameScalarsView<const S> confidence,
                                    const NeighborsView<S, I>& graph, PositionsView<S> grad_positions,
                                    RotationGradientView<S> grad_rotations,
                                    EnergyWorkspace<S>* workspace, ParallelOptions parallel,
                                    Term& term) {
  ConfidenceTerm<S, I> conf;
  conf.given = confidence;
  return drive_views<S, I>(positions, rotations, false, graph, grad_positions, grad_rotations,
                           workspace, parallel, conf, term);
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace detail
}  // namespace smg
