// examples/cli/graph_case.hpp — the graph of a case directory, shared by `graph`, `energies` and
// `dqb`: loaded from graph_indices.npy + graph_weights.npy when the case has them, otherwise
// built from the case's node files with the graph flags.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "smg/energy/options.hpp"
#include "subcommand.hpp"

namespace cli {

// Flags of the graph equations (docs/design.md "Trajectory distance", "KNN and gate",
// "Descriptor"; names and defaults from docs/interop.md), plus --weighting, --no-gate and
// --segment-frames.
std::vector<FlagSpec> graph_flags();

struct CaseGraph {
  std::int64_t nodes = 0, k = 0;
  std::vector<std::int32_t> indices;  // [N][K], -1 padded
  std::vector<double> weights;        // [N][K]
  bool built = false;                 // true when built here rather than loaded

  // Filled only when built (build_case_graph):
  std::int64_t frames = 0, channels = 0;  // T, and C of the descriptors (0: none)
  std::vector<double> distances;          // [N][K] trajectory distances, 0 on padding
  std::vector<double> features;           // [N][C] node descriptors (empty when C = 0)
  std::string features_source = "none";  // "features.npy", "feature_samples.npy" or "none"
  bool gated = false;                     // false: purely geometric graph (no features, or --no-gate)
  std::string aggregation;                // "paper" | "robust_max"
  std::int64_t edges = 0, isolated_nodes = 0, nodes_without_candidates = 0, gate_removed_edges = 0,
               kept_nearest = 0, zero_feature_nodes = 0, pairs_evaluated = 0, segment_frames = 0;
  double mean_degree = 0, seconds = 0;  // seconds: descriptors + KNN + gate, no file I/O
};

// positions: the case's positions.npy [T][N][3] (already loaded and checked).
CaseGraph load_or_build_graph(const Invocation& inv, const Tensor<double>& positions);

// Builds the semantic motion graph from the case's node files, ignoring any graph_indices.npy:
// visibility.npy [T][N] (absent: all visible); features.npy [N][C] used as the descriptors, else
// descriptors computed from feature_samples.npy [T][N][C]; with neither (or with --no-gate) the
// graph is purely geometric (no semantic gate, gated = false). Computes in float with --float.
CaseGraph build_case_graph(const Invocation& inv, const Tensor<double>& positions);

// The inputs of the energy subcommands (`energies`, `regularizers`): positions.npy [T][N][3]
// (required, checked, within max_coordinate of the precision), quats.npy [T][N][4] (absent:
// identity), visibility.npy [T][N] (absent: all visible) and the graph (load_or_build_graph).
// `bytes_per_frame_node` is the subcommand's estimate of its memory per (frame, node) for
// --max-memory-gb, checked before anything but positions is read.
struct EnergyCase {
  Tensor<double> x;
  std::vector<double> q;
  std::vector<std::uint8_t> vis;
  CaseGraph g;
};
EnergyCase load_energy_case(const Invocation& inv, double bytes_per_frame_node);

// The gap list of the flags `gaps_flag` (deltas) and `weights_flag` (one weight per gap), as
// `energies` and `regularizers` read them: at least one gap, as many weights as gaps, each delta
// range-checked before narrowing to int. Their rules (delta >= 1, weight >= 0, at most
// GapList::kCapacity) are the library's, checked by smg::validate_options.
smg::GapList read_gap_list(const Args& a, const std::string& gaps_flag, const std::string& weights_flag);

// Adds the build statistics of a built graph to a summary line ("gated", "edges", ...).
void add_graph_summary(const CaseGraph& g, JsonLine& summary);

}  // namespace cli
