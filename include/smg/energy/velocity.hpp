// smg/energy/velocity.hpp — node velocities by frame differences (docs/design.md "Velocity" and the
// pinned "Time" rule; docs/math/energy.md (E1)).
//
//   u_i^t = x_i^{t+1} − x_i^t      for t < T − 1   (forward difference)
//   u_i^{T−1} = x_i^{T−1} − x_i^{T−2}               (backward difference at the last frame)
//   u_i^0 = 0                      when T = 1
//
// The same rule gives the per-frame edge-length change of the confidence (E4). Velocities are in
// world units per frame. Per-element functions only (CUDA kernels include this header): the loop
// over all nodes and frames, velocities(), is in velocities.hpp.
#pragma once

#include "smg/core/config.hpp"

#include "smg/core/views.hpp"

namespace smg {

// u^t = x^plus − x^minus; `moving` is false when T < 2 (then u = 0).
struct VelocityFrames {
  Index plus = 0;
  Index minus = 0;
  bool moving = false;
};

// The two frames whose difference is the velocity at frame t of a T-frame sequence.  (E1)
SMG_HOST_DEVICE inline VelocityFrames velocity_frames(Index t, Index frames) {
  if (frames < 2) return {t, t, false};
  if (t < frames - 1) return {t + 1, t, true};
  return {frames - 1, frames - 2, true};
}

// u_i^t of node i, world units per frame.  (E1)
template <class S>
inline Vector3<S> velocity(PositionsView<const S> x, Index t, Index i) {
  const VelocityFrames f = velocity_frames(t, x.frames());
  if (!f.moving) return Vector3<S>::Zero();
  return x(f.plus, i) - x(f.minus, i);
}

}  // namespace smg
