// smg/graph/point_knn.hpp — exact k nearest neighbours of points in R³, optionally within a
// radius (docs/math/graph.md (G15)): the neighbour tables the field's codebases build with tools
// of their own (Open3D's KDTreeFlann, scipy's cKDTree, frnn, pytorch3d's knn_points).
//
// Row i lists the k points j with the smallest d²_ij = ‖p_j − p_i‖² (point_distance2), in the
// order (d², j) — ties by index, so a row never depends on the search's internals or the
// thread count — keeping only d²_ij <= r² (frnn's test; r = +inf keeps every point) and, with
// include_self = false, j != i. Entries past the last neighbour are index −1 and squared
// distance +inf. point_knn returns exactly the rows of point_knn_brute_force, bit for bit.
//
// The search: a balanced bounding-box tree over the points (median splits along the widest
// axis, leaves of at most 16 points, built once per call), descended nearer child first with a
// bound that shrinks to the row's k-th squared distance. A subtree is skipped only when its
// box's squared distance exceeds the bound strictly; the box distance never exceeds the
// squared distance of a point inside it in floating point (each per-axis gap is at most the
// point's |difference|, and rounding is monotonic), so no candidate that could enter the row,
// tie included, is skipped. Queries run in tree order (nearby queries after one another) over
// chunks on every core; each writes only its own row. Work: O(N log N) to build, about
// O(k log N) per query on spread-out points; memory: the tree (about 7 values per point), no
// O(N²) ever.
#pragma once

#include "smg/core/config.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/core/views.hpp"
#include "smg/graph/point_knn_element.hpp"
#include "smg/graph/segment_index.hpp"

namespace smg {

struct PointKnnOptions {
  int k = 16;               // entries per row (>= 1); rows hold fewer neighbours when N or r allow fewer
  double radius = std::numeric_limits<double>::infinity();  // keep d² <= r², r² rounded to S (>= 0)
  bool include_self = true;  // whether j = i may appear in row i (first, at d² = 0, unless a
                             // lower-indexed exact duplicate precedes it)
  ParallelOptions parallel{};
};

// Checks the inputs and outputs of point_knn: points [N][3] finite; k >= 1; radius >= 0 (+inf
// allowed, NaN not); indices and squared distances of shape [N][k]; an index type that holds N.
template <class S, class I>
Status validate_point_knn(detail::NonDeducedT<TableView<const S, 3>> points, const PointKnnOptions& o,
                          TableView<I, Eigen::Dynamic> indices, TableView<S, Eigen::Dynamic> distances2) {
  if (o.k < 1) return Status::error("k: must be >= 1, got " + std::to_string(o.k));
  if (!(o.radius >= 0))
    return Status::error("radius: must be >= 0 or +inf, got " + std::to_string(o.radius));
  const Index N = points.rows();
  if (Status s = detail::check_point_knn_arguments<S, I>(N, o.k, o.radius, points.data(), indices, distances2); !s)
    return s;
  for (Index i = 0; i < N; ++i)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(static_cast<double>(points(i, c)))) {
        std::ostringstream s;
        s << "points: point " << i << " has a NaN or infinite coordinate (" << points(i, 0) << ", "
          << points(i, 1) << ", " << points(i, 2) << ")";
        return Status::error(s.str());
      }
  return Status::ok();
}

namespace detail {

// The balanced bounding-box tree of point_knn: points reordered by median splits
// (median_partition, the trajectory KNN's), stored xyz-interleaved in tree order with their
// original indices; node k covers tree positions [b, e), children 2k+1 and 2k+2 the halves, and
// a node of at most kLeaf points is a leaf. Its shape depends on N only.
template <class S>
struct PointTree {
  static constexpr Index kLeaf = 16;
  std::vector<S> xyz;              // [N][3], tree order
  std::vector<std::int32_t> ids;   // original index of each tree position
  std::vector<Box<S>> bounds;      // node boxes, heap order

  Index size() const { return static_cast<Index>(ids.size()); }
  const S* point(Index p) const { return xyz.data() + 3 * p; }

  void build(TableView<const S, 3> points) {
    const Index n = points.rows();
    std::vector<std::array<S, 3>> centre(static_cast<std::size_t>(n));
    for (Index i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) centre[static_cast<std::size_t>(i)][static_cast<std::size_t>(c)] = points(i, c);
    ids.resize(static_cast<std::size_t>(n));
    for (Index i = 0; i < n; ++i) ids[static_cast<std::size_t>(i)] = static_cast<std::int32_t>(i);
    if (n > 0) median_partition(ids.data(), centre, 0, n, kLeaf);
    xyz.resize(static_cast<std::size_t>(3 * n));
    for (Index p = 0; p < n; ++p)
      for (int c = 0; c < 3; ++c)
        xyz[static_cast<std::size_t>(3 * p + c)] = centre[static_cast<std::size_t>(ids[static_cast<std::size_t>(p)])][static_cast<std::size_t>(c)];
    bounds.assign(static_cast<std::size_t>(n > 0 ? SegmentTree<S>::capacity_for(n) : 0), empty_box<S>());
    if (n > 0) fill(0, 0, n);
  }

  // Row of query q (a point [3]) into dist/idx (k entries, caller storage), skipping index
  // `exclude` (−1: none); returns the number found (<= k), rows sorted by (d², j) (G15).
  template <class I>
  int search(const S* q, S r2, int k, std::int64_t exclude, S* dist, I* idx) const {
    const Index n = size();
    if (n == 0) return 0;
    Box<S> qb;
    for (int c = 0; c < 3; ++c) qb.lo[c] = qb.hi[c] = q[c];
    struct Entry { Index node, b, e; S d2; };
    std::array<Entry, 128> stack;  // depth <= log2(N / kLeaf) + 1 < 64 for any Index-sized N
    int top = 0, found = 0;
    stack[static_cast<std::size_t>(top++)] = {0, 0, n, box_distance2(bounds[0], qb)};
    while (top > 0) {
      const Entry en = stack[static_cast<std::size_t>(--top)];
      if (en.d2 > point_knn_bound(r2, k, found, dist)) continue;
      if (en.e - en.b <= kLeaf) {
        for (Index p = en.b; p < en.e; ++p) {
          const std::int32_t j = ids[static_cast<std::size_t>(p)];
          if (j == exclude) continue;
          point_knn_insert(point_distance2(point(p), q), static_cast<I>(j), r2, k, found, dist, idx);
        }
        continue;
      }
      const Index mid = en.b + (en.e - en.b) / 2;
      const Index lk = 2 * en.node + 1, rk = 2 * en.node + 2;
      const Entry l{lk, en.b, mid, box_distance2(bounds[static_cast<std::size_t>(lk)], qb)};
      const Entry r{rk, mid, en.e, box_distance2(bounds[static_cast<std::size_t>(rk)], qb)};
      // Nearer child on top: visited first, so the bound shrinks sooner.
      stack[static_cast<std::size_t>(top++)] = l.d2 <= r.d2 ? r : l;
      stack[static_cast<std::size_t>(top++)] = l.d2 <= r.d2 ? l : r;
    }
    return found;
  }

 private:
  const Box<S>& fill(Index node, Index b, Index e) {
    Box<S>& out = bounds[static_cast<std::size_t>(node)];
    if (e - b <= kLeaf) {
      for (Index p = b; p < e; ++p) {
        Box<S> pt;
        for (int c = 0; c < 3; ++c) pt.lo[c] = pt.hi[c] = point(p)[c];
        box_extend(out, pt);
      }
    } else {
      const Index mid = b + (e - b) / 2;
      box_extend(out, fill(2 * node + 1, b, mid));
      box_extend(out, fill(2 * node + 2, mid, e));
    }
    return out;
  }
};

}  // namespace detail

// Exact point KNN (G15): for every point i, row i of `indices` [N][k] and `distances2` [N][k]
// (squared, in the points' units²) holds its k nearest points by (d², j), within the radius,
// self included or not, padded with −1 / +inf. I is std::int32_t or std::int64_t (torch's).
// Deterministic and bit-identical for any thread count. Call validate_point_knn first on
// untrusted input.
template <class S, class I>
void point_knn(detail::NonDeducedT<TableView<const S, 3>> points, const PointKnnOptions& o,
               TableView<I, Eigen::Dynamic> indices, TableView<S, Eigen::Dynamic> distances2) {
  SMG_ASSERT((validate_point_knn<S, I>(points, o, indices, distances2).is_ok()), "point_knn: invalid arguments");
  const Index N = points.rows();
  if (N == 0) return;
  detail::PointTree<S> tree;
  tree.build(points);
  const S r2 = detail::point_knn_radius2<S>(o.radius);
  const int k = o.k;
  parallel_for_chunks(N, [&](Index, Index b, Index e) {
    for (Index p = b; p < e; ++p) {
      const Index i = tree.ids[static_cast<std::size_t>(p)];
      S* dist = distances2.ptr(i);
      I* idx = indices.ptr(i);
      const int found = tree.search(tree.point(p), r2, k, o.include_self ? -1 : std::int64_t(i), dist, idx);
      point_knn_pad(k, found, dist, idx);
    }
  }, o.parallel);
}

// The all-pairs reference of point_knn: the same contract and the same rows, bit for bit, in
// O(N²) (tests and the benchmark's check).
template <class S, class I>
void point_knn_brute_force(detail::NonDeducedT<TableView<const S, 3>> points, const PointKnnOptions& o,
                           TableView<I, Eigen::Dynamic> indices, TableView<S, Eigen::Dynamic> distances2) {
  SMG_ASSERT((validate_point_knn<S, I>(points, o, indices, distances2).is_ok()),
             "point_knn_brute_force: invalid arguments");
  const Index N = points.rows();
  const S r2 = detail::point_knn_radius2<S>(o.radius);
  parallel_for_chunks(N, [&](Index, Index b, Index e) {
    for (Index i = b; i < e; ++i) {
      S* dist = distances2.ptr(i);
      I* idx = indices.ptr(i);
      int found = 0;
      for (Index j = 0; j < N; ++j) {
        if (!o.include_self && j == i) continue;
        point_knn_insert(point_distance2(points.ptr(j), points.ptr(i)), static_cast<I>(j), r2, o.k, found, dist, idx);
      }
      point_knn_pad(o.k, found, dist, idx);
    }
  }, o.parallel);
}

}  // namespace smg
