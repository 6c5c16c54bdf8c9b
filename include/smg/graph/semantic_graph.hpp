// smg/graph/semantic_graph.hpp — the semantic motion graph: trajectory KNN, semantic gate,
// isolated-node policy and topology weights (docs/design.md "KNN and gate"; the paper's eq. (1);
// docs/math/graph.md (G9)-(G12)).
//
//   E_ij = 1[j in KNN(i)] * 1[cos(f_i, f_j) >= tau]                                    (G9)
//   w_ij = 1 / |N(i)|                                    uniform topology weights     (G10)
//   w_ij = exp(-D_ij^2 / (2 sigma_i^2)) / sum, sigma_i = mean_{j in N(i)} D_ij        (G11)
//   keep_nearest: a node with KNN candidates but no gated edge keeps its nearest one,
//   with weight 1; leave: it stays isolated                                            (G12)
//
// Outputs, [N][K] each (K = options.knn.k), rows sorted by (D_ij, j), -1 padded with weight 0
// and distance 0: neighbour indices (int32), topology weights and trajectory distances. The
// indices and weights form a NeighborsView, the input of every graph consumer.
// Weights are constants for gradients (docs/design.md "Conventions").
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/graph/descriptor.hpp"
#include "smg/graph/knn.hpp"

namespace smg {

enum class IsolatedPolicy {
  keep_nearest,  // a node left with no gated edge keeps its nearest KNN candidate (weight 1)
  leave,         // it stays without edges
};

enum class TopologyWeighting {
  uniform,   // (G10) 1 / |N(i)|
  distance,  // (G11) Gaussian in D_ij with sigma_i = mean kept distance, normalised
};

inline const char* to_string(IsolatedPolicy p) {
  return p == IsolatedPolicy::keep_nearest ? "keep_nearest" : "leave";
}
inline const char* to_string(TopologyWeighting w) {
  return w == TopologyWeighting::uniform ? "uniform" : "distance";
}

struct GraphOptions {
  KnnOptions knn{};                       // k, distance aggregation, search, threads
  bool gate = true;                       // apply the semantic gate (needs features); false:
                                          // purely geometric graph (MoSca's topology)
  double tau = 0.75;                      // gate threshold, inclusive (0.85 for ego-exo scenes)
  IsolatedPolicy isolated = IsolatedPolicy::keep_nearest;
  TopologyWeighting weighting = TopologyWeighting::uniform;
};

// Graph statistics (deterministic).
struct GraphStats {
  Index nodes = 0;
  Index edges = 0;                     // directed edges kept (sum of row degrees)
  double mean_degree = 0;              // edges / nodes
  Index isolated_nodes = 0;            // rows without any edge in the output
  Index nodes_without_candidates = 0;  // rows whose KNN found nobody (no co-visible partner)
  Index gate_removed_edges = 0;        // KNN edges the gate removed (before keep_nearest)
  Index kept_nearest = 0;              // nodes that kept their nearest candidate (policy)
  Index zero_feature_nodes = 0;        // gated nodes whose descriptor is zero (cos = 0)
  bool gated = false;
  KnnStats knn{};                      // filled by build_semantic_graph
};

namespace detail {
inline Status check_table(const char* name, Index rows, Index cols, Index want_rows, Index want_cols,
                          const void* data) {
  if (rows != want_rows || cols != want_cols) {
    std::ostringstream s;
    s << name << ": expected shape [N=" << want_rows << "][K=" << want_cols << "], got [" << rows
      << "][" << cols << "]";
    return Status::error(s.str());
  }
  if (data == nullptr && rows * cols > 0)
    return Status::error(std::string(name) + ": null data pointer for a non-empty array");
  return Status::ok();
}
}  // namespace detail

// Checks the inputs of gate_and_weight: KNN rows [N][K] (ids in [0, N) or -1, no self edge,
// padding only at the end, finite distances >= 0), features [N][C] finite when the gate is on,
// tau finite, and outputs [N][K].
template <class S>
Status validate_gate_and_weight(TableView<const std::int32_t, Eigen::Dynamic> knn_indices,
                                detail::NonDeducedT<TableView<const S, Eigen::Dynamic>> knn_distances,
                                detail::NonDeducedT<FeaturesView<const S>> features,
                                const GraphOptions& o,
                                TableView<std::int32_t, Eigen::Dynamic> indices,
                                TableView<S, Eigen::Dynamic> weights,
                                TableView<S, Eigen::Dynamic> distances) {
  const Index N = knn_indices.rows(), K = knn_indices.cols();
  if (K < 1) return Status::error("knn_indices: needs at least one column (k >= 1)");
  if (Status s = detail::check_table("knn_distances", knn_distances.rows(), knn_distances.cols(), N, K,
                                     knn_distances.data());
      !s)
    return s;
  if (knn_indices.data() == nullptr && N * K > 0)
    return Status::error("knn_indices: null data pointer for a non-empty array");
  auto fail = [](const char* name, Index i, Index q, const std::string& what) {
    std::ostringstream s;
    s << name << ": entry [i=" << i << "][k=" << q << "] " << what;
    return Status::error(s.str());
  };
  for (Index i = 0; i < N; ++i) {
    bool padding = false;
    for (Index q = 0; q < K; ++q) {
      const std::int32_t j = knn_indices(i, q);
      const S d = knn_distances(i, q);
      if (j == -1) {
        padding = true;
        continue;
      }
      if (padding) return fail("knn_indices", i, q, "is a neighbour after -1 padding");
      if (j < -1 || j >= N) return fail("knn_indices", i, q, "is out of range: " + std::to_string(j));
      if (j == i) return fail("knn_indices", i, q, "is a self edge");
      if (!std::isfinite(d) || d < S(0)) return fail("knn_distances", i, q, "is negative or not finite");
    }
  }
  if (o.gate) {
    if (Status s = validate_features<S>(features, N, -1); !s) return s;
    if (!std::isfinite(o.tau)) return Status::error("tau: must be finite");
  }
  if (Status s = detail::check_table("indices", indices.rows(), indices.cols(), N, K, indices.data()); !s) return s;
  if (Status s = detail::check_table("weights", weights.rows(), weights.cols(), N, K, weights.data()); !s) return s;
  return detail::check_table("distances", distances.rows(), distances.cols(), N, K, distances.data());
}

// Gate (G9), isolated policy (G12) and topology weights (G10)/(G11) applied to KNN rows. The
// outputs may alias the KNN inputs (each row is read before it is written). With
// options.gate == false, features are not read (pass an empty view). cos(f_i, f_j) with a
// zero descriptor is 0.
template <class S>
GraphStats gate_and_weight(TableView<const std::int32_t, Eigen::Dynamic> knn_indices,
                           detail::NonDeducedT<TableView<const S, Eigen::Dynamic>> knn_distances,
                           detail::NonDeducedT<FeaturesView<const S>> features,
                           const GraphOptions& o,
                           TableView<std::int32_t, Eigen::Dynamic> indices,
                           TableView<S, Eigen::Dynamic> weights,
                           TableView<S, Eigen::Dynamic> distances) {
  const Index N = knn_indices.rows(), K = knn_indices.cols();
  GraphStats stats;
  stats.nodes = N;
  stats.gated = o.gate;
  // Unit descriptors (zero rows stay zero), so cos(f_i, f_j) is one dot product and cannot
  // overflow for huge or tiny features.
  const Index C = o.gate ? features.cols() : 0;
  std::vector<S> unit(static_cast<std::size_t>(N * C), S(0));
  if (o.gate) {
    for (Index i = 0; i < N; ++i) {
      const S n = detail::safe_norm(features.row(i));
      if (n > S(0)) {
        Eigen::Map<Eigen::Matrix<S, Eigen::Dynamic, 1>>(unit.data() + i * C, C) = features.row(i) / n;
      } else {
        ++stats.zero_feature_nodes;
      }
    }
  }
  const S tau = static_cast<S>(o.tau);
  struct Counts {
    Index edges = 0, isolated = 0, empty = 0, removed = 0, rescued = 0;
  };
  const Index chunks = parallel_chunk_count(N, o.knn.parallel.grain);
  std::vector<Counts> counts(static_cast<std::size_t>(chunks));
  parallel_for_chunks(
      N,
      [&](Index chunk, Index begin, Index end) {
        std::vector<std::int32_t> row_j(static_cast<std::size_t>(K));
        std::vector<S> row_d(static_cast<std::size_t>(K)), row_w(static_cast<std::size_t>(K));
        Counts& c = counts[static_cast<std::size_t>(chunk)];
        for (Index i = begin; i < end; ++i) {
          Index r = 0;  // KNN candidates
          while (r < K && knn_indices(i, r) >= 0) ++r;
          Index kept = 0;
          for (Index q = 0; q < r; ++q) {
            const std::int32_t j = knn_indices(i, q);
            bool pass = true;
            if (o.gate) {
              const S cosine = Eigen::Map<const Eigen::Matrix<S, Eigen::Dynamic, 1>>(unit.data() + i * C, C)
                                   .dot(Eigen::Map<const Eigen::Matrix<S, Eigen::Dynamic, 1>>(unit.data() + j * C, C));
              pass = cosine >= tau;
            }
            if (pass) {
              row_j[static_cast<std::size_t>(kept)] = j;
              row_d[static_cast<std::size_t>(kept)] = knn_distances(i, q);
              ++kept;
            }
          }
          c.removed += r - kept;
          if (r == 0) ++c.empty;
          if (kept == 0 && r > 0 && o.isolated == IsolatedPolicy::keep_nearest) {
            row_j[0] = knn_indices(i, 0);
            row_d[0] = knn_distances(i, 0);
            kept = 1;
            ++c.rescued;
          }
          // Topology weights over the kept edges.
          if (kept > 0) {
            S sigma(0);
            if (o.weighting == TopologyWeighting::distance) {
              for (Index q = 0; q < kept; ++q) sigma += row_d[static_cast<std::size_t>(q)];
              sigma /= S(kept);
            }
            if (o.weighting == TopologyWeighting::distance && sigma > S(0)) {
              S total(0);
              for (Index q = 0; q < kept; ++q) {
                const S z = row_d[static_cast<std::size_t>(q)] / sigma;
                row_w[static_cast<std::size_t>(q)] = std::exp(-z * z / S(2));
                total += row_w[static_cast<std::size_t>(q)];
              }
              for (Index q = 0; q < kept; ++q) row_w[static_cast<std::size_t>(q)] /= total;
            } else {
              for (Index q = 0; q < kept; ++q) row_w[static_cast<std::size_t>(q)] = S(1) / S(kept);
            }
          }
          for (Index q = 0; q < K; ++q) {
            const bool valid = q < kept;
            indices(i, q) = valid ? row_j[static_cast<std::size_t>(q)] : -1;
            weights(i, q) = valid ? row_w[static_cast<std::size_t>(q)] : S(0);
            distances(i, q) = valid ? row_d[static_cast<std::size_t>(q)] : S(0);
          }
          c.edges += kept;
          if (kept == 0) ++c.isolated;
        }
      },
      o.knn.parallel);
  for (const Counts& c : counts) {
    stats.edges += c.edges;
    stats.isolated_nodes += c.isolated;
    stats.nodes_without_candidates += c.empty;
    stats.gate_removed_edges += c.removed;
    stats.kept_nearest += c.rescued;
  }
  stats.mean_degree = N > 0 ? static_cast<double>(stats.edges) / static_cast<double>(N) : 0.0;
  return stats;
}

// Checks the inputs of build_semantic_graph: those of trajectory_knn, features [N][C] finite
// when the gate is on, tau finite, and outputs of shape [N][k].
template <class S>
Status validate_semantic_graph(detail::NonDeducedT<PositionsView<const S>> x,
                               VisibilityView<const std::uint8_t> v,
                               detail::NonDeducedT<FeaturesView<const S>> features,
                               const GraphOptions& o,
                               TableView<std::int32_t, Eigen::Dynamic> indices,
                               TableView<S, Eigen::Dynamic> weights,
                               TableView<S, Eigen::Dynamic> distances) {
  if (Status s = validate_trajectory_knn<S>(x, v, o.knn, indices, distances); !s) return s;
  if (Status s = detail::check_table("weights", weights.rows(), weights.cols(), x.nodes(), o.knn.k, weights.data()); !s)
    return s;
  if (o.gate) {
    if (features.data() == nullptr && features.rows() == 0 && features.cols() == 0)
      return Status::error("features: the semantic gate needs features [N][C] (or disable the gate)");
    if (Status s = validate_features<S>(features, x.nodes(), -1); !s) return s;
    if (!std::isfinite(o.tau)) return Status::error("tau: must be finite");
  }
  return Status::ok();
}

// The semantic motion graph (G4), (G9)-(G12): exact trajectory KNN, then the gate, isolated
// policy and topology weights, into indices/weights/distances [N][k]. features [N][C] are the
// node descriptors (semantic_descriptors, or the caller's own); with options.gate == false
// they are not read. Deterministic for any thread count.
template <class S>
GraphStats build_semantic_graph(detail::NonDeducedT<PositionsView<const S>> x,
                                VisibilityView<const std::uint8_t> v,
                                detail::NonDeducedT<FeaturesView<const S>> features,
                                const GraphOptions& o,
                                TableView<std::int32_t, Eigen::Dynamic> indices,
                                TableView<S, Eigen::Dynamic> weights,
                                TableView<S, Eigen::Dynamic> distances) {
  const KnnStats knn = trajectory_knn<S>(x, v, o.knn, indices, distances);
  GraphStats stats = gate_and_weight<S>(TableView<const std::int32_t, Eigen::Dynamic>(indices),
                                        TableView<const S, Eigen::Dynamic>(distances), features, o,
                                        indices, weights, distances);
  stats.knn = knn;
  return stats;
}

}  // namespace smg
