// smg/core/scalar.hpp — per-Scalar numeric constants used by the small-angle branches, and the
// integer types of a scalar's bits.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include <Eigen/Core>

namespace smg {

// The plain arithmetic type for numeric constants in formulas over S: S itself for float and
// double, the underlying double for Eigen::AutoDiffScalar. Writing constants as Literal<S>
// rather than S keeps AutoDiffScalar expressions free of zero-sized derivative vectors (which
// Eigen cannot combine with sized ones inside nested expressions).
template <class S>
using Literal = typename Eigen::NumTraits<S>::Literal;

// Below this angle (radians) the rotation coefficient functions switch from their closed form
// to a Taylor series through theta^8. The switch point balances the series' truncation error
// (~theta^10 / 10!) against the cancellation error of the closed forms ((theta - sin theta) and
// 1/theta^2 - cot(theta/2)/(2 theta) lose ~eps/theta^2 relative, but enter the Jacobians
// multiplied by theta^2, so their absolute contribution stays ~eps): 0.1 in double (series
// error ~1e-19, both branches agree to ~1 ulp at the switch) and 0.9 in float (~1e-9).
// The series branches use theta^2 only, never sqrt, so automatic differentiation through
// smg (Eigen::AutoDiffScalar) stays finite at theta = 0.
template <class S>
SMG_HOST_DEVICE inline typename Eigen::NumTraits<S>::Real series_threshold() {
  using Real = typename Eigen::NumTraits<S>::Real;
  return Eigen::NumTraits<Real>::epsilon() > Real(1e-10) ? Real(0.9) : Real(0.1);
}

// Tolerance used when validating that a quaternion is unit: |1 - |q|| <= unit_tolerance.
template <class S>
SMG_HOST_DEVICE inline typename Eigen::NumTraits<S>::Real unit_tolerance() {
  using Real = typename Eigen::NumTraits<S>::Real;
  return Real(1e3) * Eigen::NumTraits<Real>::epsilon();
}

namespace detail {
// The integer types of S's size (32 bits for float, 64 for double), for work on a value's bits:
// the masks of SIMD lanes (energy/lanes.hpp), the rasteriser's branch-free selects and exp.
template <class S>
struct FloatBits;
template <>
struct FloatBits<float> {
  using Signed = std::int32_t;
  using Unsigned = std::uint32_t;
};
template <>
struct FloatBits<double> {
  using Signed = std::int64_t;
  using Unsigned = std::uint64_t;
};
}  // namespace detail

}  // namespace smg
