// Loading a case's graph; building it lands with the graph module (issue 3).
#include "graph_case.hpp"

#include "smg/graph/neighbors.hpp"

namespace cli {

std::vector<FlagSpec> graph_flags() {
  return {{"k", "16", "neighbours per node (trajectory-level KNN)"},
          {"tau", "0.75", "semantic gate: keep an edge when cos(f_i, f_j) >= tau"},
          {"aggregation", "paper", "trajectory distance: paper | robust_max"},
          {"m", "3", "co-visible distances aggregated per pair"},
          {"min-covisible", "1", "minimum co-visible frames for a candidate pair"},
          {"isolated", "keep_nearest", "node left without gated edges: keep_nearest | leave"},
          {"rho", "0.5", "descriptor: fraction of most consistent feature samples kept"}};
}

CaseGraph load_or_build_graph(const Invocation& inv, const Tensor<double>& positions) {
  const std::int64_t N = positions.dim(1);
  const CaseDir& c = inv.case_dir;
  if (!c.has("graph_indices.npy"))
    throw RunError("the case has no graph_indices.npy, and building the graph is not available "
                   "yet in this version (planned in issue 3)");
  const auto idx = c.load<std::int32_t>("graph_indices.npy", {{"N", N}, {"K"}});
  const std::int64_t K = idx.dim(1);
  const auto w = c.load<double>("graph_weights.npy", {{"N", N}, {"K", K}});
  const smg::NeighborsView<double> view(idx.ptr(), w.ptr(), N, K);
  if (smg::Status s = smg::validate_neighbors(view, N, "graph_indices.npy/graph_weights.npy"); !s)
    throw RunError(s.message());
  return CaseGraph{N, K, idx.data, w.data, false};
}

}  // namespace cli
