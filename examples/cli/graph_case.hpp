// examples/cli/graph_case.hpp — the graph of a case directory, shared by `graph`, `energies` and
// `dqb`: loaded from graph_indices.npy + graph_weights.npy when the case has them, otherwise
// built from the case's node files with the graph flags.
#pragma once

#include <cstdint>
#include <vector>

#include "subcommand.hpp"

namespace cli {

// Flags of the graph equations (DESIGN.md "Trajectory distance", "KNN and gate",
// "Descriptor"; names and defaults from INTEROP.md).
std::vector<FlagSpec> graph_flags();

struct CaseGraph {
  std::int64_t nodes = 0, k = 0;
  std::vector<std::int32_t> indices;  // [N][K], -1 padded
  std::vector<double> weights;        // [N][K]
  bool built = false;                 // true when built here rather than loaded
};

// positions: the case's positions.npy [T][N][3] (already loaded and checked).
CaseGraph load_or_build_graph(const Invocation& inv, const Tensor<double>& positions);

}  // namespace cli
