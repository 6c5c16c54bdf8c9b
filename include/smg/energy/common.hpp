// smg/energy/common.hpp — small pieces shared by the energies: the accumulator type of energy
// sums, the factor of Normalization::mean, the confidence-aware edge weight (E7) and the
// validation of their optional confidence input.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <type_traits>

#include "smg/core/types.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"

namespace smg {

// Energies are summed in double when the computation runs in float (millions of terms would
// otherwise lose ~1e-4 relative); for double (and AutoDiffScalar) in the Scalar itself.
template <class S>
using Accumulator = std::conditional_t<std::is_same_v<S, float>, double, S>;

namespace detail {
// scale / terms, 0 when there are none: an energy's factor under Normalization::mean. Host and
// device: the CPU terms divide by counts known on the host, the CUDA kernels and elements by the
// edge count read from device memory (scale_over_count); one formula, so both round alike.
SMG_HOST_DEVICE inline double scale_over_terms(double scale, Index terms) {
  return terms > 0 ? scale / static_cast<double>(terms) : 0.0;
}
// scale / (factor · *count): the same, with the count where the edge count lives.
SMG_HOST_DEVICE inline double scale_over_count(double scale, Index factor, const std::int32_t* count) {
  return scale_over_terms(scale, factor * static_cast<Index>(*count));
}
}  // namespace detail

// w̃_ij^t = w_ij (α + (1 − α) c_{t,j}): the asymmetric, confidence-aware weight of edge i -> j
// at frame t (the confidence of the *neighbour* j). The one definition of (E7), called by the
// C-ARAP and LRM kernels and their residual forms. V: a scalar or a lane type (lanes.hpp).
template <class V, class L>
SMG_FORCE_INLINE SMG_HOST_DEVICE V confidence_edge_weight(const V& w_ij, L alpha, const V& c_j) {
  return w_ij * (alpha + (L(1) - alpha) * c_j);
}

// Validation of the optional confidence input of C-ARAP and LRM: absent (null) is fine;
// otherwise [T][N] with every element in [0, 1] (NaN fails).
template <class S>
inline Status validate_optional_confidence(FrameScalarsView<const S> confidence, Index T, Index N) {
  if (confidence.data() == nullptr) return Status::ok();
  if (Status s = detail::check_shape("confidence", confidence.data(), confidence.frames(), confidence.nodes(), -1,
                                     T, N, -1, "T", "N");
      !s)
    return s;
  for (Index t = 0; t < T; ++t)
    for (Index i = 0; i < N; ++i)
      if (!(confidence(t, i) >= S(0) && confidence(t, i) <= S(1)))
        return Status::error("confidence: element " + detail::at_string(t, i, "t", "i") + " is not in [0, 1]");
  return Status::ok();
}

}  // namespace smg
