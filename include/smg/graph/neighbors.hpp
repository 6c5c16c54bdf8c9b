// smg/graph/neighbors.hpp — the view every graph consumer takes: K neighbours per node.
//
// Layout (docs/interop.md graph_indices.npy / graph_weights.npy):
//   indices [N][K] int32 or int64 (I), neighbour node ids, -1 = none; valid entries first, then
//           -1 padding. int64 is what PyTorch produces by default: it is read in place, no copy.
//   weights [N][K] Scalar, topology weights w_ij >= 0 matching indices (0 on padding)
// Row i lists the out-edges i -> j of node i (N(i) in docs/design.md). Rows need not be
// symmetric.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <type_traits>

#include "smg/core/status.hpp"
#include "smg/core/views.hpp"

namespace smg {

// S: the weight scalar; I: the index type, std::int32_t (default) or std::int64_t.
template <class S, class I = std::int32_t>
struct NeighborsView {
  static_assert(std::is_same_v<I, std::int32_t> || std::is_same_v<I, std::int64_t>,
                "graph indices are std::int32_t or std::int64_t");
  using IndexType = I;
  TableView<const I, Eigen::Dynamic> indices;  // [N][K]
  TableView<const S, Eigen::Dynamic> weights;  // [N][K]

  NeighborsView() = default;
  SMG_HOST_DEVICE NeighborsView(const I* idx, const S* w, Index nodes, Index k)
      : indices(idx, nodes, k), weights(w, nodes, k) {}

  SMG_HOST_DEVICE Index nodes() const { return indices.rows(); }
  SMG_HOST_DEVICE Index k() const { return indices.cols(); }
  // Number of valid (non-negative) entries in row i (they come first).
  SMG_HOST_DEVICE Index degree(Index i) const {
    Index d = 0;
    while (d < k() && indices(i, d) >= 0) ++d;
    return d;
  }
};

// Number of valid neighbour entries Σ_i |N(i)| of a graph (the edges i -> j it lists).
template <class S, class I>
inline Index edge_count(const NeighborsView<S, I>& graph) {
  Index n = 0;
  for (Index i = 0; i < graph.nodes(); ++i) n += graph.degree(i);
  return n;
}

namespace detail {
// Checks that indices and weights are both [nodes][K] (contents not read): the shape part of
// validate_neighbors, shared with the CUDA launchers' host checks, which cannot read device
// memory, so that every validator words a wrong graph shape the same way.
template <class S, class I>
Status check_neighbors_shape(const NeighborsView<S, I>& g, Index nodes, const std::string& name) {
  if (g.indices.rows() == nodes && g.weights.rows() == nodes && g.indices.cols() == g.weights.cols())
    return Status::ok();
  std::ostringstream s;
  s << name << ": expected indices and weights of shape [N=" << nodes << "][K], got ["
    << g.indices.rows() << "][" << g.indices.cols() << "] and [" << g.weights.rows() << "]["
    << g.weights.cols() << "]";
  return Status::error(s.str());
}
}  // namespace detail

// Checks a neighbour table against N nodes: shapes, indices in [0, N) or -1, no self edges,
// padding only at the end of a row (with weight 0), weights finite and >= 0.
template <class S, class I>
Status validate_neighbors(const NeighborsView<S, I>& g, Index nodes,
                          const std::string& name = "graph") {
  auto fail = [&](Index i, Index k, const std::string& what) {
    std::ostringstream s;
    s << name << ": entry [i=" << i << "][k=" << k << "] " << what;
    return Status::error(s.str());
  };
  if (Status s = detail::check_neighbors_shape(g, nodes, name); !s) return s;
  if (nodes * g.k() > 0 && (g.indices.data() == nullptr || g.weights.data() == nullptr))
    return Status::error(name + ": null data pointer for a non-empty array");
  for (Index i = 0; i < nodes; ++i) {
    bool padding = false;
    for (Index k = 0; k < g.k(); ++k) {
      const I j = g.indices(i, k);
      const S w = g.weights(i, k);
      if (!std::isfinite(w) || w < S(0)) return fail(i, k, "has a weight that is negative or not finite");
      if (j == -1) {
        padding = true;
        if (w != S(0)) return fail(i, k, "is padding (-1) with a nonzero weight");
        continue;
      }
      if (padding) return fail(i, k, "is a neighbour after -1 padding");
      if (j < -1 || j >= nodes) return fail(i, k, "is out of range: " + std::to_string(j));
      if (j == i) return fail(i, k, "is a self edge");
    }
  }
  return Status::ok();
}

}  // namespace smg
