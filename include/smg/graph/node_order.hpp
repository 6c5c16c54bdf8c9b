// smg/graph/node_order.hpp — a locality-preserving node order: a Morton (Z-order) curve over each
// node's mean position, the permutation and its inverse, and the remapping of per-node arrays and
// of a neighbour table into that order (docs/math/graph.md "Node order").
//
// Why: every energy visits node i and gathers its K neighbours j at each frame. When neighbours
// lie far apart in memory (nodes stored in the order a scene was loaded, interleaved across
// objects) each gather touches a new cache line; stored along a space-filling curve, neighbours
// are mostly a few entries apart. Reorder once, before training (bench/notes/energy.md measures
// the speed-up):
//
//   const smg::NodeOrder order = smg::spatial_node_order(positions, visibility);
//   smg::reorder_nodes(order, positions, positions_sorted);        // every [T][N][...] array
//   smg::reorder_graph(order, graph, idx_sorted, weights_sorted);  // rows moved, ids renumbered
//   ... energies and gradients in the sorted order ...
//   smg::reorder_nodes(order.inverse(), grad_sorted, grad);        // back to the caller's order
//
// Energies do not depend on the order (sums over the same terms, added in another order: equal to
// round-off).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "smg/core/status.hpp"
#include "smg/core/views.hpp"
#include "smg/graph/neighbors.hpp"

namespace smg {

// A permutation of N nodes. new_to_old[n] is the caller's id of the node stored at position n of
// the reordered arrays; old_to_new is its inverse (old_to_new[new_to_old[n]] == n).
struct NodeOrder {
  std::vector<Index> new_to_old;
  std::vector<Index> old_to_new;

  Index size() const { return static_cast<Index>(new_to_old.size()); }
  // The reverse permutation: reorder_nodes(order.inverse(), ...) restores the caller's order.
  NodeOrder inverse() const { return NodeOrder{old_to_new, new_to_old}; }
  // The order that keeps every node in place.
  static NodeOrder identity(Index nodes) {
    std::vector<Index> p(static_cast<std::size_t>(std::max<Index>(0, nodes)));
    std::iota(p.begin(), p.end(), Index(0));
    return NodeOrder{p, p};
  }
  // An order from new_to_old alone (its inverse is computed). Check it with validate_node_order.
  static NodeOrder from_new_to_old(std::vector<Index> new_to_old) {
    NodeOrder o;
    o.old_to_new.assign(new_to_old.size(), Index(-1));
    for (std::size_t n = 0; n < new_to_old.size(); ++n) {
      const Index old = new_to_old[n];
      if (old >= 0 && old < static_cast<Index>(new_to_old.size()))
        o.old_to_new[static_cast<std::size_t>(old)] = static_cast<Index>(n);
    }
    o.new_to_old = std::move(new_to_old);
    return o;
  }
};

// Checks that `order` is a permutation of `nodes` nodes whose two arrays are inverse to each other.
inline Status validate_node_order(const NodeOrder& order, Index nodes) {
  if (order.size() != nodes || static_cast<Index>(order.old_to_new.size()) != nodes)
    return Status::error("node order: expected " + std::to_string(nodes) + " entries, got " +
                         std::to_string(order.new_to_old.size()) + " and " +
                         std::to_string(order.old_to_new.size()));
  for (Index n = 0; n < nodes; ++n) {
    const Index old = order.new_to_old[static_cast<std::size_t>(n)];
    if (old < 0 || old >= nodes || order.old_to_new[static_cast<std::size_t>(old)] != n)
      return Status::error("node order: entry " + std::to_string(n) +
                           " is not a permutation with a matching inverse");
  }
  return Status::ok();
}

namespace detail {
// The 21 low bits of v spread to every third bit of a 63-bit word.
inline std::uint64_t morton_spread(std::uint64_t v) {
  v &= 0x1fffffULL;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}
}  // namespace detail

// The Morton (Z-order) key of each node's mean position: the mean over its visible frames
// (over every frame when `visibility` is empty or the node is never visible), quantised to
// 2^21 cells per axis of the bounding box of the means. Nodes whose mean is not finite get the
// largest key. Positions [T][N][3] (const or not); visibility [T][N] or empty.
template <class T, class V = const std::uint8_t>
std::vector<std::uint64_t> morton_keys(const SequenceView<T, 3>& positions,
                                       const SequenceView<V, 1>& visibility = {}) {
  const Index frames = positions.frames(), nodes = positions.nodes();
  const bool use_vis = !visibility.empty() && visibility.frames() == frames && visibility.nodes() == nodes;
  std::vector<double> mean(static_cast<std::size_t>(3 * std::max<Index>(0, nodes)), 0.0);
  for (Index i = 0; i < nodes; ++i) {
    double m[3] = {0, 0, 0}, a[3] = {0, 0, 0};
    Index seen = 0;
    for (Index t = 0; t < frames; ++t) {
      const auto* p = positions.ptr(t, i);
      for (int c = 0; c < 3; ++c) a[c] += static_cast<double>(p[c]);
      if (use_vis && visibility(t, i) != 0) {
        for (int c = 0; c < 3; ++c) m[c] += static_cast<double>(p[c]);
        ++seen;
      }
    }
    const double n = static_cast<double>(seen > 0 ? seen : std::max<Index>(1, frames));
    for (int c = 0; c < 3; ++c) mean[static_cast<std::size_t>(3 * i + c)] = (seen > 0 ? m[c] : a[c]) / n;
  }
  double lo[3], hi[3];
  for (int c = 0; c < 3; ++c) {
    lo[c] = std::numeric_limits<double>::infinity();
    hi[c] = -std::numeric_limits<double>::infinity();
  }
  auto finite = [&](Index i) {
    const double* p = &mean[static_cast<std::size_t>(3 * i)];
    return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
  };
  for (Index i = 0; i < nodes; ++i) {
    if (!finite(i)) continue;
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], mean[static_cast<std::size_t>(3 * i + c)]);
      hi[c] = std::max(hi[c], mean[static_cast<std::size_t>(3 * i + c)]);
    }
  }
  constexpr double kCells = 2097151.0;  // 2^21 - 1
  std::vector<std::uint64_t> key(static_cast<std::size_t>(std::max<Index>(0, nodes)),
                                 std::numeric_limits<std::uint64_t>::max());
  for (Index i = 0; i < nodes; ++i) {
    if (!finite(i)) continue;
    std::uint64_t k = 0;
    for (int c = 0; c < 3; ++c) {
      const double extent = hi[c] - lo[c];
      const double u = extent > 0 ? (mean[static_cast<std::size_t>(3 * i + c)] - lo[c]) / extent : 0.0;
      const auto cell = static_cast<std::uint64_t>(std::clamp(u, 0.0, 1.0) * kCells);
      k |= detail::morton_spread(cell) << c;
    }
    key[static_cast<std::size_t>(i)] = k;
  }
  return key;
}

// The locality-preserving order: nodes sorted by morton_keys (ties by the caller's id, so the
// order is deterministic). O(T N + N log N).
template <class T, class V = const std::uint8_t>
NodeOrder spatial_node_order(const SequenceView<T, 3>& positions,
                             const SequenceView<V, 1>& visibility = {}) {
  const std::vector<std::uint64_t> key = morton_keys(positions, visibility);
  std::vector<Index> p(key.size());
  std::iota(p.begin(), p.end(), Index(0));
  std::sort(p.begin(), p.end(), [&](Index a, Index b) {
    const std::uint64_t ka = key[static_cast<std::size_t>(a)], kb = key[static_cast<std::size_t>(b)];
    return ka != kb ? ka < kb : a < b;
  });
  return NodeOrder::from_new_to_old(std::move(p));
}

// out(t, n) = in(t, order.new_to_old[n]) for every frame t and channel: any [T][N][C] array
// (positions, quaternions, visibility, confidences, feature samples, gradients). With
// order.inverse() it moves arrays back to the caller's order. `in` and `out` must not overlap.
template <class T, class U, int Dim>
Status reorder_nodes(const NodeOrder& order, const SequenceView<T, Dim>& in,
                     const SequenceView<U, Dim>& out) {
  static_assert(std::is_same_v<std::remove_const_t<T>, U>,
                "reorder_nodes: out is a mutable view of in's element type");
  if (Status s = validate_node_order(order, in.nodes()); !s) return s;
  if (out.frames() != in.frames() || out.nodes() != in.nodes() || out.dim() != in.dim())
    return Status::error("reorder_nodes: out does not have the shape of in");
  if (in.size() > 0 && static_cast<const void*>(in.data()) == static_cast<const void*>(out.data()))
    return Status::error("reorder_nodes: in and out are the same array (reordering is not in place)");
  const Index dim = in.dim();
  for (Index t = 0; t < in.frames(); ++t)
    for (Index n = 0; n < in.nodes(); ++n)
      std::copy_n(in.ptr(t, order.new_to_old[static_cast<std::size_t>(n)]), dim, out.ptr(t, n));
  return Status::ok();
}

// out row n = in row order.new_to_old[n]: per-node tables [N][C] (features, sigmas).
template <class T, class U, int Cols>
Status reorder_nodes(const NodeOrder& order, const TableView<T, Cols>& in, const TableView<U, Cols>& out) {
  static_assert(std::is_same_v<std::remove_const_t<T>, U>,
                "reorder_nodes: out is a mutable view of in's element type");
  if (Status s = validate_node_order(order, in.rows()); !s) return s;
  if (out.rows() != in.rows() || out.cols() != in.cols())
    return Status::error("reorder_nodes: out does not have the shape of in");
  if (in.size() > 0 && static_cast<const void*>(in.data()) == static_cast<const void*>(out.data()))
    return Status::error("reorder_nodes: in and out are the same array (reordering is not in place)");
  for (Index n = 0; n < in.rows(); ++n)
    std::copy_n(in.ptr(order.new_to_old[static_cast<std::size_t>(n)]), in.cols(), out.ptr(n));
  return Status::ok();
}

// The neighbour table in the new order: row n is the caller's row order.new_to_old[n] with every
// neighbour id j renumbered to order.old_to_new[j] (-1 padding and the order within a row kept),
// weights moved with their entries. indices_out and weights_out are [N][K] like the input.
template <class S, class I>
Status reorder_graph(const NodeOrder& order, const NeighborsView<S, I>& in,
                     const TableView<I, Eigen::Dynamic>& indices_out,
                     const TableView<S, Eigen::Dynamic>& weights_out) {
  const Index nodes = in.nodes(), k = in.k();
  if (Status s = validate_node_order(order, nodes); !s) return s;
  if (indices_out.rows() != nodes || indices_out.cols() != k || weights_out.rows() != nodes ||
      weights_out.cols() != k || in.weights.rows() != nodes || in.weights.cols() != k)
    return Status::error("reorder_graph: indices_out and weights_out must be [N][K] like the graph");
  for (Index n = 0; n < nodes; ++n) {
    const Index old = order.new_to_old[static_cast<std::size_t>(n)];
    for (Index c = 0; c < k; ++c) {
      const I j = in.indices(old, c);
      if (j < -1 || j >= static_cast<I>(nodes))
        return Status::error("reorder_graph: neighbour id " + std::to_string(j) + " out of range");
      indices_out(n, c) = j < 0 ? I(-1) : static_cast<I>(order.old_to_new[static_cast<std::size_t>(j)]);
      weights_out(n, c) = in.weights(old, c);
    }
  }
  return Status::ok();
}

}  // namespace smg
