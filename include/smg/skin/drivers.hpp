// smg/skin/drivers.hpp — the driving set of each point: its anchor node and the anchor's
// graph neighbours (docs/design.md "Pinned details: DQB").  (S1)
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/graph/neighbors.hpp"
#include "smg/skin/skin_views.hpp"

namespace smg {

// Columns of the driver table for a graph with K neighbours per node: the anchor + K.
template <class S, class I>
inline Index skin_driver_width(const NeighborsView<S, I>& graph) {
  return graph.k() + 1;
}

// Checks skin_drivers' arguments: the graph against N nodes (validate_neighbors), anchor [P] in
// [0, N), out [P][K + 1].
template <class S, class I>
Status validate_skin_drivers(const NeighborsView<S, I>& graph, SkinIndexView anchor, Index nodes,
                             TableView<std::int32_t, Eigen::Dynamic> out) {
  if (Status s = validate_neighbors(graph, nodes); !s) return s;
  if (Status s = detail::check_index_array(anchor, anchor.rows(), nodes, "anchor", "N"); !s)
    return s;
  return detail::check_output_table<std::int32_t, Eigen::Dynamic>(out, anchor.rows(),
                                                                   skin_driver_width(graph),
                                                                   "drivers");
}

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

// out[p] = (anchor[p], the valid neighbours of anchor[p] in graph order, −1 padding):
// D = K + 1 columns. A node without neighbours drives its points alone.  (S1)
template <class S, class I>
void skin_drivers(const NeighborsView<S, I>& graph, SkinIndexView anchor,
                  TableView<std::int32_t, Eigen::Dynamic> out, ParallelOptions options = {}) {
  parallel_for(
      anchor.rows(),
      [&](Index begin, Index end) {
        for (Index p = begin; p < end; ++p) skin_drivers_row(graph, anchor(p, 0), out.ptr(p));
      },
      options);
}

}  // namespace smg
