// smg/core/rotation_gradient_batch.hpp — the conversions of core/rotation_gradient.hpp over
// whole [T][N] arrays, in parallel chunks on the CPU (docs/math/core.md (Q3), (Q5)). Apart from
// the per-element header so that a CUDA translation unit, which needs only (Q3) and (Q5) per
// rotation, does not reach the CPU thread pool.
#pragma once

#include "smg/core/config.hpp"

#include "smg/core/parallel.hpp"
#include "smg/core/rotation_gradient.hpp"
#include "smg/core/views.hpp"

namespace smg {

namespace detail {
// Calls convert(k) for every rotation k = t·N + i of quaternions [T][N][4], in parallel chunks
// (each k touches only its own rows: deterministic); the two gradient arrays must be [T][N]
// (asserted in debug builds).
template <class Q, class GT, class GQ, class F>
void for_each_rotation(const Q& quaternions, const GT& g_tangent, const GQ& g_quaternions,
                       ParallelOptions parallel, F&& convert) {
  const Index T = quaternions.frames(), N = quaternions.nodes();
  SMG_ASSERT(g_tangent.frames() == T && g_tangent.nodes() == N, "g_tangent shape");
  SMG_ASSERT(g_quaternions.frames() == T && g_quaternions.nodes() == N, "g_quaternions shape");
  (void)g_tangent;  // read by the assertions only (compiled out in Release)
  (void)g_quaternions;
  if (T * N == 0) return;
  parallel_for(
      T * N,
      [&](Index begin, Index end) {
        for (Index k = begin; k < end; ++k) convert(k);
      },
      parallel);
}
}  // namespace detail

// Batched (Q5): g_quaternions [T][N][4] += raw gradient of quaternions [T][N][4] given
// g_tangent [T][N][3]. Shapes must agree (asserted in debug builds). Deterministic.
template <class S>
void quaternion_gradient_from_tangent(QuaternionsView<const S> quaternions,
                                      TangentsView<const S> g_tangent,
                                      QuaternionsView<S> g_quaternions,
                                      ParallelOptions parallel = {}) {
  detail::for_each_rotation(quaternions, g_tangent, g_quaternions, parallel, [&](Index k) {
    add_quaternion_gradient_from_tangent(quaternions.data() + 4 * k, g_tangent.data() + 3 * k,
                                         g_quaternions.data() + 4 * k);
  });
}

// Batched (Q3): g_tangent [T][N][3] += right-tangent gradient given the raw gradient
// g_quaternions [T][N][4] of quaternions [T][N][4]. Deterministic.
template <class S>
void tangent_gradient_from_quaternion(QuaternionsView<const S> quaternions,
                                      QuaternionsView<const S> g_quaternions,
                                      TangentsView<S> g_tangent, ParallelOptions parallel = {}) {
  detail::for_each_rotation(quaternions, g_tangent, g_quaternions, parallel, [&](Index k) {
    add_tangent_gradient_from_quaternion(quaternions.data() + 4 * k, g_quaternions.data() + 4 * k,
                                         g_tangent.data() + 3 * k);
  });
}

}  // namespace smg
