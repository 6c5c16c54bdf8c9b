// smg/graph/knn.hpp — exact trajectory-level k nearest neighbours (docs/design.md "KNN and gate";
// docs/math/graph.md (G4)-(G6)).
//
// For every node i: the k nodes j != i with the smallest trajectory distance D_ij ((G2) or
// (G3)) among those with |S_ij| >= max(1, min_covisible), ordered by (D_ij, j). Output rows
// [N][k]: indices int32 (-1 padding when fewer candidates exist) and distances (0 on padding).
//
// trajectory_knn is exact (the same rows as trajectory_knn_brute_force, bit for bit) without
// evaluating all pairs: candidates come from range queries in per-segment bounding-volume trees
// (segment_index.hpp) with a radius that shrinks to node i's current k-th distance; the proof
// is in docs/math/graph.md "Exact trajectory KNN". Work per node is
// O(segments * log N + candidates * T); memory is O(N*T) (a node-major copy of the positions,
// visibility bitsets and the segment trees), never O(N^2).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/core/views.hpp"
#include "smg/graph/segment_index.hpp"
#include "smg/graph/trajectory_distance.hpp"

namespace smg {

struct KnnOptions {
  int k = 16;                             // neighbours per node (>= 1)
  TrajectoryDistanceOptions distance{};   // aggregation, m, min_covisible
  int segment_frames = 0;                 // frames per candidate-index segment; 0 = automatic
  int seed_segments = 2;                  // segments searched first for nearby nodes (>= 1)
  ParallelOptions parallel{};
};

// What a KNN build did (all counts are deterministic).
struct KnnStats {
  Index nodes = 0, frames = 0;
  int segment_frames = 0;            // frames per segment actually used
  Index segments = 0;
  Index pairs_evaluated = 0;         // exact pair distances computed (brute force: N(N-1))
  Index neighbors = 0;               // valid entries written
  Index nodes_without_candidates = 0;
  std::size_t scratch_bytes = 0;     // bytes the builder allocated (store + trees + per-task scratch)
};

// Checks inputs and outputs of trajectory_knn: positions [T][N][3] finite, T >= 1; visibility
// [T][N] of 0/1 or empty (all visible); k >= 1, m >= 1, min_covisible >= 0,
// segment_frames >= 0, seed_segments >= 1; indices and distances of shape [N][k].
template <class S>
Status validate_trajectory_knn(detail::NonDeducedT<PositionsView<const S>> x,
                               VisibilityView<const std::uint8_t> v,
                               const KnnOptions& o,
                               TableView<std::int32_t, Eigen::Dynamic> indices,
                               TableView<S, Eigen::Dynamic> distances) {
  if (o.k < 1) return Status::error("k: must be >= 1, got " + std::to_string(o.k));
  if (o.segment_frames < 0)
    return Status::error("segment_frames: must be >= 0, got " + std::to_string(o.segment_frames));
  if (o.seed_segments < 1)
    return Status::error("seed_segments: must be >= 1, got " + std::to_string(o.seed_segments));
  if (Status s = detail::validate_distance_options(o.distance); !s) return s;
  if (Status s = detail::validate_trajectories<S>(x, v); !s) return s;
  auto check = [&](const char* name, Index rows, Index cols, const void* data) {
    if (rows != x.nodes() || cols != o.k) {
      std::ostringstream s;
      s << name << ": expected shape [N=" << x.nodes() << "][k=" << o.k << "], got [" << rows
        << "][" << cols << "]";
      return Status::error(s.str());
    }
    if (data == nullptr && rows * cols > 0)
      return Status::error(std::string(name) + ": null data pointer for a non-empty array");
    return Status::ok();
  };
  if (Status s = check("indices", indices.rows(), indices.cols(), indices.data()); !s) return s;
  return check("distances", distances.rows(), distances.cols(), distances.data());
}

namespace detail {

// A node's current k best (distance, id), ascending by (distance, id), over caller storage
// (k distances, k ids, a count), so that the state of every node lives in flat arrays.
template <class S>
struct TopK {
  S* d;
  std::int32_t* j;
  int* count;
  int k;

  void reset() { *count = 0; }
  // The current radius U (k-th distance), +inf while fewer than k are known.
  S radius() const { return *count < k ? std::numeric_limits<S>::infinity() : d[k - 1]; }
  void insert(S dist, std::int32_t id) {
    auto less = [](S a, std::int32_t ia, S b, std::int32_t ib) { return a < b || (a == b && ia < ib); };
    int& n = *count;
    if (n == k && !less(dist, id, d[k - 1], j[k - 1])) return;
    int q = n < k ? n++ : k - 1;
    while (q > 0 && less(dist, id, d[q - 1], j[q - 1])) {
      d[q] = d[q - 1];
      j[q] = j[q - 1];
      --q;
    }
    d[q] = dist;
    j[q] = id;
  }
  void write(Index i, TableView<std::int32_t, Eigen::Dynamic> indices, TableView<S, Eigen::Dynamic> distances) const {
    for (int q = 0; q < k; ++q) {
      const bool valid = q < *count;
      indices(i, q) = valid ? j[q] : -1;
      distances(i, q) = valid ? d[q] : S(0);
    }
  }
};

// The automatic segment length (frames per segment) for a store. Segments trade the number of
// range queries per node (T / L) against box looseness (motion within L frames): L is the
// number of frames over which the typical motion reaches twice the typical nearest-neighbour
// spacing (about the radius of a k = 16 neighbourhood), clamped to [1, 64]. On the synthetic
// scenes of bench/bench_graph.cpp this is within 20% of the fastest fixed L. Both quantities
// are medians over a deterministic sample, so L is deterministic.
template <class S>
int automatic_segment_frames(const TrajectoryStore<S>& st) {
  const Index T = st.frames, N = st.nodes;
  if (T <= 1 || N <= 1) return 1;
  // Typical per-frame displacement of visible nodes.
  std::vector<S> step;
  const Index stride_i = std::max<Index>(1, N / 512);
  for (Index i = 0; i < N; i += stride_i) {
    const S* p = st.p(i);
    const Index stride_t = std::max<Index>(1, T / 32);
    for (Index t = 0; t + 1 < T; t += stride_t)
      if (st.is_visible(i, t) && st.is_visible(i, t + 1)) {
        const S dx = p[3 * t + 3] - p[3 * t], dy = p[3 * t + 4] - p[3 * t + 1], dz = p[3 * t + 5] - p[3 * t + 2];
        step.push_back(std::sqrt(dx * dx + dy * dy + dz * dz));
      }
  }
  if (step.empty()) return 1;
  std::nth_element(step.begin(), step.begin() + static_cast<std::ptrdiff_t>(step.size() / 2), step.end());
  const S motion = step[step.size() / 2];
  if (!(motion > S(0))) return static_cast<int>(std::min<Index>(T, 64));
  // Typical spacing: nearest-neighbour distances in the frame with the most visible nodes of
  // a sample (one point tree over that frame).
  Index best_t = 0, best_count = -1;
  const Index stride_t = std::max<Index>(1, T / 16);
  for (Index t = 0; t < T; t += stride_t) {
    Index c = 0;
    for (Index i = 0; i < N; i += stride_i) c += st.is_visible(i, t) ? 1 : 0;
    if (c > best_count) { best_count = c; best_t = t; }
  }
  SegmentTree<S> tree;
  tree.build(st, best_t, best_t + 1);
  std::vector<S> gap;
  std::pair<S, std::int32_t> nn[2];
  for (Index i = 0; i < N; i += stride_i) {
    Box<S> q;
    if (!segment_box(st, i, best_t, best_t + 1, q)) continue;
    if (tree.nearest(q, 1, static_cast<std::int32_t>(i), nn) == 1) gap.push_back(std::sqrt(nn[0].first));
  }
  if (gap.empty()) return 1;
  std::nth_element(gap.begin(), gap.begin() + static_cast<std::ptrdiff_t>(gap.size() / 2), gap.end());
  const S spacing = gap[gap.size() / 2];
  const double ratio = 2.0 * static_cast<double>(spacing) / static_cast<double>(motion);
  const double L = std::floor(std::min(ratio, 64.0));
  return static_cast<int>(std::max(1.0, std::min(L, static_cast<double>(T))));
}

// What trajectory_knn and select_nodes search: the trajectories (TrajectoryStore) and one
// SegmentTree per segment of segment_frames frames (requested, capped at T; automatic when 0).
template <class S>
struct TrajectoryIndex {
  TrajectoryStore<S> store;
  int segment_frames = 0;
  std::vector<SegmentTree<S>> trees;

  TrajectoryIndex(PositionsView<const S> x, VisibilityView<const std::uint8_t> v,
                  int requested_frames, ParallelOptions parallel) {
    store.build(x, v, parallel);
    segment_frames = requested_frames > 0
                         ? std::min<int>(requested_frames, static_cast<int>(x.frames()))
                         : automatic_segment_frames(store);
    trees = build_segment_trees(store, segment_frames, parallel);
  }
  // Bytes allocated by the store and the trees.
  std::size_t bytes() const {
    std::size_t b = store.bytes();
    for (const auto& t : trees) b += t.bytes();
    return b;
  }
};

}  // namespace detail

// Exact trajectory KNN (G4): rows sorted by (D_ij, j), -1/0 padded. Deterministic and
// bit-identical for any thread count. Call validate_trajectory_knn first on untrusted input.
template <class S>
KnnStats trajectory_knn(detail::NonDeducedT<PositionsView<const S>> x,
                        VisibilityView<const std::uint8_t> v,
                        const KnnOptions& o, TableView<std::int32_t, Eigen::Dynamic> indices,
                        TableView<S, Eigen::Dynamic> distances) {
  KnnStats stats;
  const Index N = x.nodes(), T = x.frames();
  stats.nodes = N;
  stats.frames = T;
  const detail::TrajectoryIndex<S> index(x, v, o.segment_frames, o.parallel);
  stats.scratch_bytes = index.bytes();
  stats.segment_frames = index.segment_frames;
  stats.segments = static_cast<Index>(index.trees.size());
  const detail::TrajectoryStore<S>& st = index.store;
  const auto& trees = index.trees;

  const int k = o.k;
  const int seeds = std::max(1, o.seed_segments);
  // Per-node state, indexed by rank in `order` (nodes with nearby trajectories are adjacent):
  // the k best so far and the set of nodes already evaluated.
  const auto order = detail::trajectory_order(st);
  std::vector<S> best_d(static_cast<std::size_t>(N * k));
  std::vector<std::int32_t> best_j(static_cast<std::size_t>(N * k));
  std::vector<int> best_n(static_cast<std::size_t>(N), 0);
  std::vector<detail::IdSet> seen(static_cast<std::size_t>(N));
  auto topk = [&](Index r) {
    return detail::TopK<S>{best_d.data() + r * k, best_j.data() + r * k, best_n.data() + r, k};
  };
  // Evaluates D_ij once per pair (the id set) and keeps it if it is among the k best. The
  // running radius bounds robust_max's early exit.
  auto consider = [&](Index r, std::int32_t j, S* acc, Index& evals) {
    if (!seen[static_cast<std::size_t>(r)].insert(j)) return;
    auto best = topk(r);
    ++evals;
    const S d = detail::pair_distance(st, order[static_cast<std::size_t>(r)], j, o.distance, acc,
                                      detail::widen2(best.radius()));
    if (d < std::numeric_limits<S>::infinity()) best.insert(d, j);
  };
  const Index max_chunks = parallel_chunk_count(N, o.parallel.grain);
  std::vector<Index> evaluated(static_cast<std::size_t>(max_chunks), 0);
  std::size_t task_bytes = 0;

  // 1. Seeds: the k nodes with the nearest boxes in a few segments spread over i's visible
  //    span give every node a first radius U.
  parallel_for_chunks(
      N,
      [&](Index chunk, Index begin, Index end) {
        std::vector<S> acc(static_cast<std::size_t>(o.distance.m));
        std::vector<std::pair<S, std::int32_t>> near(static_cast<std::size_t>(k));
        std::vector<std::int32_t> active;
        detail::Box<S> q;
        Index evals = 0;
        for (Index r = begin; r < end; ++r) {
          const Index i = order[static_cast<std::size_t>(r)];
          topk(r).reset();
          seen[static_cast<std::size_t>(r)].insert(static_cast<std::int32_t>(i));
          active.clear();
          for (std::size_t s = 0; s < trees.size(); ++s)
            if (detail::segment_box(st, i, trees[s].f0, trees[s].f1, q)) active.push_back(static_cast<std::int32_t>(s));
          const auto A = static_cast<Index>(active.size());
          for (int c = 0; c < seeds && c < A; ++c) {
            const auto& tree = trees[static_cast<std::size_t>(active[static_cast<std::size_t>((2 * c + 1) * A / (2 * seeds))])];
            detail::segment_box(st, i, tree.f0, tree.f1, q);
            const int n = tree.nearest(q, k, static_cast<std::int32_t>(i), near.data());
            for (int e = 0; e < n; ++e) consider(r, near[static_cast<std::size_t>(e)].second, acc.data(), evals);
          }
        }
        evaluated[static_cast<std::size_t>(chunk)] += evals;
      },
      o.parallel);

  // 2. Completion: every node within the (shrinking) radius in some segment (G6). Work is
  //    tiled: groups of consecutive segments whose trees fit in cache together, and within a
  //    group blocks of kBlock nodes (nearby trajectories) that visit the group's trees in
  //    turn. In a tree, batches of kBatch nodes share one range query (the union of their
  //    boxes, with the largest radius); each node then filters the collected items with its
  //    own box and radius in a branch-free loop, far cheaper per test than tree traversal.
  //    Nodes whose radius is still infinite, and batches whose union query finds too many
  //    items, fall back to one range query per node.
  constexpr Index kBlock = 256, kBatch = 8;
  constexpr std::size_t kBatchCap = 64 * kBatch;
  constexpr std::size_t kGroupBytes = std::size_t(8) << 20;
  constexpr S kInf = std::numeric_limits<S>::infinity();
  const Index blocks = (N + kBlock - 1) / kBlock;
  std::size_t tree_bytes = 0;
  for (const auto& t : trees) tree_bytes += t.bytes();
  const Index per_group = std::max<Index>(
      1, static_cast<Index>(kGroupBytes / std::max<std::size_t>(1, tree_bytes / std::max<std::size_t>(1, trees.size()))));
  for (Index g0 = 0; g0 < static_cast<Index>(trees.size()); g0 += per_group) {
    const Index g1 = std::min<Index>(static_cast<Index>(trees.size()), g0 + per_group);
    const Index chunks = parallel_chunk_count(blocks, o.parallel.grain);
    std::vector<std::size_t> bytes(static_cast<std::size_t>(chunks), 0);
    parallel_for_chunks(
        blocks,
        [&](Index chunk, Index begin, Index end) {
          std::vector<S> acc(static_cast<std::size_t>(o.distance.m));
          std::array<detail::Box<S>, kBatch> qbox;
          std::array<char, kBatch> active, finite;
          std::vector<std::int32_t> cand;
          detail::ItemList<S> items;
          std::vector<S> dist2;
          Index evals = 0;
          for (Index blk = begin; blk < end; ++blk) {
            const Index first = blk * kBlock, last = std::min(N, first + kBlock);
            for (Index g = g0; g < g1; ++g) {
              const auto& tree = trees[static_cast<std::size_t>(g)];
              for (Index b0 = first; b0 < last; b0 += kBatch) {
                const Index nb = std::min(kBatch, last - b0);
                detail::Box<S> Q = detail::empty_box<S>();
                S R2(0);
                bool any = false;
                for (Index u = 0; u < nb; ++u) {
                  const auto su = static_cast<std::size_t>(u);
                  const S U = topk(b0 + u).radius();
                  active[su] = detail::segment_box(st, order[static_cast<std::size_t>(b0 + u)], tree.f0, tree.f1, qbox[su]);
                  finite[su] = active[su] && U < kInf;
                  if (!finite[su]) continue;
                  detail::box_extend(Q, qbox[su]);
                  R2 = std::max(R2, detail::widen2(U));
                  any = true;
                }
                bool batched = false;
                if (any) {
                  cand.clear();
                  batched = tree.collect(Q, R2, kBatchCap, cand);
                }
                if (batched && !cand.empty()) {
                  items.assign(tree, cand);
                  dist2.resize(items.size());
                  for (Index u = 0; u < nb; ++u) {
                    const auto su = static_cast<std::size_t>(u);
                    if (!finite[su]) continue;
                    const auto best = topk(b0 + u);
                    items.distances2(qbox[su], dist2.data());
                    S bound = detail::widen2(best.radius());
                    for (std::size_t c = 0; c < items.size(); ++c)
                      if (dist2[c] <= bound) {
                        consider(b0 + u, items.id[c], acc.data(), evals);
                        bound = detail::widen2(best.radius());
                      }
                  }
                }
                for (Index u = 0; u < nb; ++u) {
                  const auto su = static_cast<std::size_t>(u);
                  if (!active[su] || (finite[su] && batched)) continue;
                  const auto best = topk(b0 + u);
                  tree.range_query(qbox[su], [&]() { return detail::widen2(best.radius()); },
                                   [&](std::int32_t j) { consider(b0 + u, j, acc.data(), evals); });
                }
              }
            }
          }
          evaluated[static_cast<std::size_t>(chunk)] += evals;
          bytes[static_cast<std::size_t>(chunk)] = acc.capacity() * sizeof(S) + cand.capacity() * sizeof(std::int32_t) +
                                                   dist2.capacity() * sizeof(S) + items.bytes();
        },
        o.parallel);
    for (std::size_t b : bytes) task_bytes = std::max(task_bytes, b);
  }

  // 3. Rows, by node id.
  parallel_for(
      N,
      [&](Index begin, Index end) {
        for (Index r = begin; r < end; ++r) topk(r).write(order[static_cast<std::size_t>(r)], indices, distances);
      },
      o.parallel);
  for (Index r = 0; r < N; ++r) {
    stats.neighbors += best_n[static_cast<std::size_t>(r)];
    if (best_n[static_cast<std::size_t>(r)] == 0) ++stats.nodes_without_candidates;
  }
  for (Index e : evaluated) stats.pairs_evaluated += e;
  std::size_t state_bytes = best_d.capacity() * sizeof(S) + best_j.capacity() * sizeof(std::int32_t) +
                            best_n.capacity() * sizeof(int) + order.capacity() * sizeof(std::int32_t) +
                            seen.capacity() * sizeof(detail::IdSet);
  for (const auto& set : seen) state_bytes += set.bytes();
  const int threads = o.parallel.threads > 0 ? o.parallel.threads : num_threads();
  stats.scratch_bytes += state_bytes + task_bytes * static_cast<std::size_t>(threads);
  return stats;
}

// The all-pairs reference: same contract and bit-identical rows as trajectory_knn, in
// O(N^2 T) time (use for tests and to measure the fast search; memory O(N*T)).
template <class S>
KnnStats trajectory_knn_brute_force(detail::NonDeducedT<PositionsView<const S>> x,
                                    VisibilityView<const std::uint8_t> v,
                                    const KnnOptions& o,
                                    TableView<std::int32_t, Eigen::Dynamic> indices,
                                    TableView<S, Eigen::Dynamic> distances) {
  KnnStats stats;
  const Index N = x.nodes();
  stats.nodes = N;
  stats.frames = x.frames();
  detail::TrajectoryStore<S> st;
  st.build(x, v, o.parallel);
  stats.scratch_bytes = st.bytes();
  const Index chunks = parallel_chunk_count(N, o.parallel.grain);
  std::vector<Index> empty_rows(static_cast<std::size_t>(chunks), 0), found(static_cast<std::size_t>(chunks), 0);
  parallel_for_chunks(
      N,
      [&](Index chunk, Index begin, Index end) {
        std::vector<S> acc(static_cast<std::size_t>(o.distance.m));
        std::vector<S> d_best(static_cast<std::size_t>(o.k));
        std::vector<std::int32_t> j_best(static_cast<std::size_t>(o.k));
        int n_best = 0;
        detail::TopK<S> top{d_best.data(), j_best.data(), &n_best, o.k};
        for (Index i = begin; i < end; ++i) {
          top.reset();
          for (Index j = 0; j < N; ++j) {
            if (j == i) continue;
            const S d = detail::pair_distance(st, i, j, o.distance, acc.data());
            if (d < std::numeric_limits<S>::infinity()) top.insert(d, static_cast<std::int32_t>(j));
          }
          top.write(i, indices, distances);
          found[static_cast<std::size_t>(chunk)] += n_best;
          if (n_best == 0) ++empty_rows[static_cast<std::size_t>(chunk)];
        }
      },
      o.parallel);
  stats.pairs_evaluated = N * (N > 0 ? N - 1 : 0);
  for (Index c = 0; c < chunks; ++c) {
    stats.nodes_without_candidates += empty_rows[static_cast<std::size_t>(c)];
    stats.neighbors += found[static_cast<std::size_t>(c)];
  }
  return stats;
}

}  // namespace smg
