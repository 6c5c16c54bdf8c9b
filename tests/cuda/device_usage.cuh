// tests/cuda/device_usage.cuh — what the compile-only device_usage_*.cu files share.
#pragma once

#include "smg/core/types.hpp"

namespace smg_device_usage {

// Sums a matrix into *out so that no call is optimised away.
template <class S, class M>
__device__ void sink(S* out, const M& m) {
  for (smg::Index k = 0; k < m.size(); ++k) *out += m.data()[k];
}

}  // namespace smg_device_usage
