// smg_cli graph CASE OUT — builds the semantic motion graph of a case directory (docs/interop.md):
// exact trajectory KNN, semantic descriptors (from feature_samples.npy, or features.npy as
// given), the gate, isolated-node policy and topology weights. A case without features gives a
// purely geometric graph ("gated": false in the summary).
//
// Writes graph_indices.npy [N,K] int32 (-1 = none), graph_weights.npy [N,K],
// distances.npy [N,K] (trajectory distances, 0 on padding) and features.npy [N,C] (the
// descriptors used; C = 0 when the case has none), float64 or float32 with --float.
#include <chrono>
#include <cstdint>

#include "graph_case.hpp"
#include "subcommand.hpp"

namespace cli {

namespace {

template <class S>
std::vector<S> as(const std::vector<double>& v) {
  return std::vector<S>(v.begin(), v.end());
}

void run_graph(const Invocation& inv, JsonLine& summary) {
  const auto positions = inv.case_dir.load<double>("positions.npy", {{"T"}, {"N"}, {"", 3}});
  const CaseGraph g = build_case_graph(inv, positions);
  const std::int64_t N = g.nodes, K = g.k, C = g.channels;
  OutputSet out;
  out.add("graph_indices.npy", g.indices, {N, K});
  if (inv.use_float) {
    out.add("graph_weights.npy", as<float>(g.weights), {N, K});
    out.add("distances.npy", as<float>(g.distances), {N, K});
    out.add("features.npy", as<float>(g.features), {N, C});
  } else {
    out.add("graph_weights.npy", g.weights, {N, K});
    out.add("distances.npy", g.distances, {N, K});
    out.add("features.npy", g.features, {N, C});
  }
  out.commit(inv.out_dir);
  summary.add("N", N).add("T", g.frames).add("C", C);
  add_graph_summary(g, summary);
  summary.add("precision", inv.use_float ? "float32" : "float64").add("seconds", g.seconds);
}

}  // namespace

Subcommand graph_subcommand() {
  return {"graph", "build the semantic motion graph (graph_indices, graph_weights, features, distances)", graph_flags(),
          /*writes_output=*/true, run_graph};
}

}  // namespace cli
