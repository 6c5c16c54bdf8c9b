// smg/energy/velocities.hpp — every node velocity (E1) of a sequence, in parallel chunks on the
// CPU: the loop over velocity.hpp's per-element function, apart from it so that CUDA
// translation units do not reach the CPU thread pool.
#pragma once

#include "smg/core/config.hpp"

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/energy/velocity.hpp"

namespace smg {

// All velocities u [T][N][3] (same shape as x).  (E1)
template <class S>
void velocities(detail::NonDeducedT<PositionsView<const S>> x, PositionsView<S> u,
                ParallelOptions parallel = {}) {
  const Index T = x.frames(), N = x.nodes();
  SMG_ASSERT(u.frames() == T && u.nodes() == N, "velocities: u shape");
  parallel_for(
      T * N,
      [&](Index begin, Index end) {
        for (Index k = begin; k < end; ++k) u(k / N, k % N) = velocity(x, k / N, k % N);
      },
      parallel);
}

// Checks velocities()' arguments: x [T][N][3] finite, u of the same shape (written).
template <class S>
Status validate_velocities(detail::NonDeducedT<PositionsView<const S>> x, PositionsView<S> u) {
  if (Status s = validate_positions<S>(x, -1, -1, "positions"); !s) return s;
  return validate_output(u, x.frames(), x.nodes(), "velocities");
}

}  // namespace smg
