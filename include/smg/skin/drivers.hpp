// smg/skin/drivers.hpp — the driving set of each point: its anchor node and the anchor's
// graph neighbours (docs/design.md "Pinned details: DQB").  (S1)
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>

#include "smg/core/parallel.hpp"
#include "smg/graph/neighbors.hpp"
#include "smg/skin/skin_views.hpp"
#include "smg/skin/weights_element.hpp"  // skin_drivers_row

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
