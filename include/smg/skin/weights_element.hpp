// smg/skin/weights_element.hpp — one point's row of the driver table (S1) and of the skinning
// weights (S2)-(S4), the host-device steps that the CPU loops (skin/drivers.hpp skin_drivers,
// skin/weights.hpp skinning_weights) and the CUDA kernels (cuda/skin_weights.cuh) both run, so
// that the GPU's driver table is the CPU's bit for bit (docs/math/skin.md). Why a header of its
// own: device headers must not reach the CPU thread pool (core/parallel.hpp), which the loops use.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/core/types.hpp"
#include "smg/core/views.hpp"
#include "smg/graph/neighbors.hpp"
#include "smg/skin/skin_views.hpp"
#include "smg/skin/weights_point.hpp"

namespace smg {

// The driver row of one point with anchor node a: row[0..K] = (a, the valid neighbours of a in
// graph order, −1 padding). Host-device: skin_drivers and the CUDA kernel
// (smg/cuda/skin_weights.cuh) both build each row with it.  (S1)
template <class S, class I>
SMG_HOST_DEVICE inline void skin_drivers_row(const NeighborsView<S, I>& graph, std::int32_t a,
                                             std::int32_t* row) {
  const Index K = graph.k();
  row[0] = a;
  Index c = 1;
  for (Index k = 0; k < K; ++k) {
    const Index j = graph.indices(a, k);
    if (j < 0) break;
    row[c++] = static_cast<std::int32_t>(j);
  }
  for (; c <= K; ++c) row[c] = -1;
}

namespace detail {

// Gathers one point's driver positions (at t_ref) and sigmas; returns the driver count.
template <class S>
SMG_HOST_DEVICE inline Index skin_load_weight_inputs(PositionsView<const S> positions, SkinDriversView drivers,
                                     SkinIndexView t_ref, TableView<const S, 1> sigma, Index p,
                                     Vector3<S>* x, S* sg) {
  const Index tr = t_ref(p, 0);
  Index D = 0;
  for (Index k = 0; k < drivers.cols(); ++k) {
    const std::int32_t n = drivers(p, k);
    if (n < 0) break;
    x[D] = positions(tr, n);
    sg[D] = sigma(n, 0);
    ++D;
  }
  return D;
}

// The weights row of point p: weights_out[p][k] = w_pk (S2)-(S4), 0 on padding; x and sg are
// scratch of drivers.cols() entries. Returns true when the fallback (S4) was used.
// Host-device: skinning_weights and the CUDA kernel (smg/cuda/skin_weights.cuh) both compute
// each point with it.
template <class S>
SMG_HOST_DEVICE inline bool skinning_weights_row(PositionsView<const S> positions,
                                                 SkinDriversView drivers, SkinIndexView t_ref,
                                                 TableView<const S, 3> points,
                                                 TableView<const S, 1> sigma,
                                                 TableView<S, Eigen::Dynamic> weights_out, Index p,
                                                 Vector3<S>* x, S* sg) {
  const Index D = skin_load_weight_inputs(positions, drivers, t_ref, sigma, p, x, sg);
  S* w = weights_out.ptr(p);
  const bool fallback = skinning_weights_point<S>(Vector3<S>(points.row(p)), D, x, sg, w);
  for (Index k = D; k < drivers.cols(); ++k) w[k] = S(0);
  return fallback;
}
}  // namespace detail

}  // namespace smg
