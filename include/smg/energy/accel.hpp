// smg/energy/accel.hpp — trajectory smoothness (E21) as a separate operator: the squared
// acceleration (or velocity) of every node trajectory, weighted by given confidences or 1, with
// its gradient (docs/math/energy.md (E21)). The same term the fused step runs
// (regularizers.hpp, options.terms.accel), through the same driver: a one-term call.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "smg/energy/element_pass.hpp"
#include "smg/energy/one_term.hpp"
#include "smg/energy/term_list.hpp"  // RegularizerResult
#include "smg/energy/terms/accel.hpp"

namespace smg {

inline namespace SMG_ISA_NAMESPACE {

// Trajectory smoothness (E21), returned in Accumulator<S> (double for float): with the
// acceleration form Σ_i Σ_t w_i^t ‖x_i^{t+2} − 2 x_i^{t+1} + x_i^t‖² times options.weight (the
// velocity form: first differences), w = confidence(t, i) at the earliest frame when
// options.confidence_weighted, else 1. positions [T][N][3] in scene units; the gradient
// w.r.t. positions is *added* to grad_positions [T][N][3]. Bit-identical for any thread count.
// Precondition: validate_accel.
template <class S>
Accumulator<S> accel(detail::NonDeducedT<PositionsView<const S>> positions,
                     detail::NonDeducedT<FrameScalarsView<const S>> confidence,
                     const AccelOptions& options, PositionsView<S> grad_positions = {},
                     EnergyWorkspace<S>* workspace = nullptr, ParallelOptions parallel = {}) {
  const Index T = positions.frames(), N = positions.nodes();
  SMG_ASSERT(detail::absent_or_shape(confidence, T, N), "accel: confidence shape");
  SMG_ASSERT(detail::absent_or_shape(grad_positions, T, N), "accel: grad_positions shape");
  if (T == 0 || N == 0) return Accumulator<S>(0);
  using I = std::int32_t;
  detail::AccelTerm<S, I> term;
  term.configure(options, T, N);
  if (!term.on()) return Accumulator<S>(0);
  // No graph: the term reads each node's own trajectory only.
  return detail::drive_one_term<S, I>(
             positions, QuaternionsView<const S>(),
             options.confidence_weighted ? confidence : FrameScalarsView<const S>(),
             NeighborsView<S, I>(nullptr, nullptr, N, 0), grad_positions, RotationGradientView<S>(),
             workspace, parallel, term)
      .accel;
}

// Checks accel_windows' arguments: x [G][T][B][3] finite (named by window, frame and
// trajectory), the options, and non-null arrays when G·T·B > 0.
template <class S>
Status validate_accel_windows(const S* x, Index G, Index T, Index B, const AccelOptions& options) {
  if (G < 0 || T < 0 || B < 0) return Status::error("positions: negative window shape");
  if (Status s = validate_options(options); !s) return s;
  if (G * T * B > 0 && x == nullptr) return Status::error("positions: null data pointer for a non-empty array");
  for (Index g = 0; g < G; ++g)
    for (Index t = 0; t < T; ++t)
      for (Index b = 0; b < B; ++b)
        for (int d = 0; d < 3; ++d)
          if (!std::isfinite(static_cast<double>(x[((g * T + t) * B + b) * 3 + d])))
            return Status::error("positions: window " + std::to_string(g) + ", frame " + std::to_string(t) +
                                 ", trajectory " + std::to_string(b) + " has a NaN or infinite coordinate");
  return Status::ok();
}

// Trajectory smoothness (E21) over G windows stored trajectory-major, x [G][T][B][3]: window g
// holds B trajectories over T frames as a [T][B][3] positions array (Shape of Motion's
// [G, T, B, 3] track neighbourhoods; its [K, T, 3] motion bases are B = 1). The energy is
// accel()'s on the G·B trajectories with frames in their own order — every term the same term,
// with Normalization::mean over all (T − order)·G·B of them — and no confidences (c ≡ 1); the
// gradient is *added* to grad [G][T][B][3] (the same layout) when not null, bit for bit accel()'s
// rows (each row's contributions in the same order), the energy to round-off (summed by
// window). The point of it: a trajectory-major caller needs no [T][N][3] copy of its input and
// no copy of the gradient back. Windows run in chunks fixed by G and B on every core, partial
// energies summed in chunk order: bit-identical for any thread count. Precondition:
// validate_accel_windows.
template <class S>
Accumulator<S> accel_windows(const S* x, Index G, Index T, Index B, const AccelOptions& options,
                             S* grad = nullptr, ParallelOptions parallel = {}) {
  if (G <= 0 || T <= 0 || B <= 0) return Accumulator<S>(0);
  using I = std::int32_t;
  detail::AccelTerm<S, I> term;
  term.configure(options, T, G * B);
  if (!term.on()) return Accumulator<S>(0);
  // About 64 chunks, at least 256 trajectories each (element_chunk_nodes' reasoning, by windows).
  ParallelOptions po = parallel;
  po.grain = std::max<Index>((G + 63) / 64, (256 + B - 1) / B);
  std::vector<Accumulator<S>> partial(static_cast<std::size_t>(parallel_chunk_count(G, po.grain)), Accumulator<S>(0));
  parallel_for_chunks(
      G,
      [&](Index c, Index g0, Index g1) {
        RegularizerResult<S> e;
        for (Index g = g0; g < g1; ++g) {
          const Index at = g * T * B * 3;
          detail::element_rows<S, I>(term, PositionsView<const S>(x + at, T, B), QuaternionsView<const S>(), nullptr,
                                     grad ? grad + at : nullptr, nullptr, nullptr, 0, B, e);
        }
        partial[static_cast<std::size_t>(c)] = e.accel;
      },
      po);
  Accumulator<S> sum(0);
  for (const Accumulator<S>& p : partial) sum += p;
  return sum;
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace smg
