// smg/graph/node_selection.hpp — adaptive node selection: from a dense set of trajectories
// (e.g. lifted 2D tracks), choose the graph nodes so that every trajectory lies within a
// spatial unit, in trajectory distance, of a chosen one (docs/math/graph.md (G13)-(G14)).
//
// Greedy cover in preference order (more visible frames first, then smaller index): a
// trajectory that no chosen node covers yet becomes a node and covers every trajectory j with
// D(node, j) <= unit ((G2)/(G3) with the given aggregation). Hence
//   - coverage: every eligible trajectory has a chosen node within `unit`;
//   - separation: chosen nodes are pairwise more than `unit` apart (D is symmetric), so the
//     node count adapts to the scene: it falls as the unit grows.
// Each trajectory is assigned to its nearest chosen node within the unit (ties: the earlier
// chosen); the coverage error is that distance (0 for chosen nodes).
// Trajectories with fewer than max(1, min_visible) visible frames are not eligible: never
// chosen, never assigned (assignment -1).
//
// Cost: the trajectory store and segment trees as in trajectory_knn (built in parallel), then
// one exact ball query per chosen node, O(segments * log N + |ball candidates| * T) each; the
// greedy pass itself is sequential (its choices depend on every earlier one). Memory O(N*T).
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/core/views.hpp"
#include "smg/graph/knn.hpp"
#include "smg/graph/segment_index.hpp"
#include "smg/graph/trajectory_distance.hpp"

namespace smg {

struct NodeSelectionOptions {
  double unit = 0;                       // spatial unit, world units (> 0)
  TrajectoryDistanceOptions distance{};  // aggregation, m, min_covisible (as for the KNN)
  int min_visible = 1;                   // eligible trajectories have >= max(1, this) visible frames
  int segment_frames = 0;                // candidate index segments; 0 = automatic
  ParallelOptions parallel{};            // store and index construction
};

template <class S>
struct NodeSelectionStats {
  Index trajectories = 0;
  Index eligible = 0;
  Index selected = 0;          // node count
  S max_error = S(0);          // max over eligible trajectories of D(assigned node, j)
  S mean_error = S(0);         // mean over eligible trajectories (chosen ones count as 0)
  Index pairs_evaluated = 0;
  int segment_frames = 0;
  std::size_t scratch_bytes = 0;
};

// Checks positions/visibility (as trajectory_knn), unit finite and > 0, m >= 1,
// min_covisible >= 0, min_visible >= 0, segment_frames >= 0, and the outputs: selected,
// assignment and error of N entries each.
template <class S>
Status validate_node_selection(detail::NonDeducedT<PositionsView<const S>> x,
                               VisibilityView<const std::uint8_t> v,
                               const NodeSelectionOptions& o, TableView<std::int32_t, 1> selected,
                               TableView<std::int32_t, 1> assignment, TableView<S, 1> error) {
  if (!(std::isfinite(o.unit) && o.unit > 0)) {
    std::ostringstream s;
    s << "unit: must be finite and > 0, got " << o.unit;
    return Status::error(s.str());
  }
  if (o.min_visible < 0) return Status::error("min_visible: must be >= 0, got " + std::to_string(o.min_visible));
  if (o.segment_frames < 0)
    return Status::error("segment_frames: must be >= 0, got " + std::to_string(o.segment_frames));
  if (Status s = detail::validate_distance_options(o.distance); !s) return s;
  if (Status s = detail::validate_trajectories<S>(x, v); !s) return s;
  auto check = [&](const char* name, Index rows, const void* data) {
    if (rows != x.nodes()) {
      std::ostringstream s;
      s << name << ": expected " << x.nodes() << " entries (N), got " << rows;
      return Status::error(s.str());
    }
    if (data == nullptr && rows > 0) return Status::error(std::string(name) + ": null data pointer for a non-empty array");
    return Status::ok();
  };
  if (Status s = check("selected", selected.rows(), selected.data()); !s) return s;
  if (Status s = check("assignment", assignment.rows(), assignment.data()); !s) return s;
  return check("error", error.rows(), error.data());
}

// Greedy cover (G13)-(G14). Writes selected[0, count) = the chosen trajectory ids in the order
// they were chosen (preference order) and -1 after; assignment[j] = the chosen id nearest to j
// within the unit (-1 when j is not eligible); error[j] = D(assignment[j], j) (0 when -1).
// Deterministic for any thread count.
template <class S>
NodeSelectionStats<S> select_nodes(detail::NonDeducedT<PositionsView<const S>> x,
                                   VisibilityView<const std::uint8_t> v,
                                   const NodeSelectionOptions& o, TableView<std::int32_t, 1> selected,
                                   TableView<std::int32_t, 1> assignment, TableView<S, 1> error) {
  NodeSelectionStats<S> stats;
  const Index N = x.nodes();
  stats.trajectories = N;
  const detail::TrajectoryIndex<S> index(x, v, o.segment_frames, o.parallel);
  stats.scratch_bytes = index.bytes();
  stats.segment_frames = index.segment_frames;
  const detail::TrajectoryStore<S>& st = index.store;
  const auto& trees = index.trees;

  const int need = std::max(1, o.min_visible);
  std::vector<std::int32_t> pref;
  pref.reserve(static_cast<std::size_t>(N));
  for (Index i = 0; i < N; ++i) {
    selected(i, 0) = -1;
    assignment(i, 0) = -1;
    error(i, 0) = S(0);
    if (st.visible[static_cast<std::size_t>(i)] >= need) pref.push_back(static_cast<std::int32_t>(i));
  }
  std::stable_sort(pref.begin(), pref.end(), [&](std::int32_t a, std::int32_t b) {
    return st.visible[static_cast<std::size_t>(a)] > st.visible[static_cast<std::size_t>(b)];
  });
  stats.eligible = static_cast<Index>(pref.size());

  const S unit = static_cast<S>(o.unit);
  const S bound2 = detail::widen2(unit);
  std::vector<char> eligible(static_cast<std::size_t>(N), 0), chosen(static_cast<std::size_t>(N), 0);
  for (std::int32_t i : pref) eligible[static_cast<std::size_t>(i)] = 1;
  std::vector<std::int32_t> stamp(static_cast<std::size_t>(N), -1);
  std::vector<S> acc(static_cast<std::size_t>(o.distance.m));
  stats.scratch_bytes += pref.capacity() * sizeof(std::int32_t) + 2 * eligible.capacity() +
                         stamp.capacity() * sizeof(std::int32_t);
  Index count = 0;
  detail::Box<S> q;
  for (std::int32_t c : pref) {
    if (assignment(c, 0) >= 0) continue;  // covered
    selected(count++, 0) = c;
    chosen[static_cast<std::size_t>(c)] = 1;
    assignment(c, 0) = c;
    error(c, 0) = S(0);
    stamp[static_cast<std::size_t>(c)] = c;
    // The exact ball {j : D(c, j) <= unit} (G6 with a fixed radius).
    for (const auto& tree : trees) {
      if (!detail::segment_box(st, c, tree.f0, tree.f1, q)) continue;
      tree.range_query(q, [&]() { return bound2; }, [&](std::int32_t j) {
        if (stamp[static_cast<std::size_t>(j)] == c) return;
        stamp[static_cast<std::size_t>(j)] = c;
        if (!eligible[static_cast<std::size_t>(j)] || chosen[static_cast<std::size_t>(j)]) return;
        ++stats.pairs_evaluated;
        const S d = detail::pair_distance(st, c, j, o.distance, acc.data(), bound2);
        if (!(d <= unit)) return;
        // Nearest chosen node; on a tie the earlier chosen one stays.
        if (assignment(j, 0) < 0 || d < error(j, 0)) {
          assignment(j, 0) = c;
          error(j, 0) = d;
        }
      });
    }
  }
  stats.selected = count;
  double sum = 0;
  for (std::int32_t j : pref) {
    stats.max_error = std::max(stats.max_error, error(j, 0));
    sum += static_cast<double>(error(j, 0));
  }
  stats.mean_error = pref.empty() ? S(0) : static_cast<S>(sum / static_cast<double>(pref.size()));
  return stats;
}

}  // namespace smg
