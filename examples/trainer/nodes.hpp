// examples/trainer/nodes.hpp — the motion graph's nodes: selection, graph, and stage 1 (fitting
// the node trajectories to the lifted tracks under the variant's regularisers).
//
// Stage 0 (make_nodes):
//   * adaptive node selection (smg::select_nodes) over the lifted object tracks: every track
//     lies within `unit` (trajectory distance) of a node, nodes are more than `unit` apart;
//   * a node is one lifted track: its trajectory starts at that track's lifted positions (with
//     the lifting's interpolation where the track was not observed), its observations are the
//     track's lifted samples, its ground truth is the track's true 3D motion;
//   * the graph: trajectory KNN (k = 16, the paper's aggregation) on the node trajectories,
//     gated by the node descriptors (smg::semantic_descriptors of the track's feature samples,
//     tau = 0.75) for the semantic variants, ungated (MoSca's topology) otherwise; uniform
//     topology weights; a node left without a gated edge keeps its nearest neighbour;
//   * rotations: identity at frame 0, then per frame the weighted Kabsch rotation that best
//     maps the node's frame-0 neighbour offsets onto its frame-t offsets (init_rotations).
//
// Stage 1 (fit_nodes): Adam on positions and on rotations (right-tangent steps) minimising
//   E = w_data * (1/(T N)) Σ_{t,i observed} ρ_H(|x_i^t − y_i^t|)                (data)
//     + w_rig  * rigidity / (N Σ_δ (T − δ))      plain ARAP or C-ARAP (E9)         (per variant)
//     + w_lrm  * LRM / (T N)                     (E14)                             (per variant)
//     + w_accel * smoothness / (T N)             (E21, squared accelerations; off by default)
// Each term is normalised to "per node and frame" so that the weights do not depend on N, T or
// the graph's degree. Confidences (E6) are recomputed from the current positions every few
// iterations and held constant in between (stop-gradient, as the library defines them).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/energy.hpp"
#include "smg/graph.hpp"
#include "trainer/priors.hpp"
#include "trainer/progress.hpp"
#include "trainer/variant.hpp"

namespace trainer {

struct NodeOptions {
  double unit = 0.04;          // node selection unit (metres, trajectory distance)
  int min_visible = 3;         // a track needs this many lifted frames to become a node
  int k = 16;                  // graph neighbours (the paper's top-16)
  double tau = 0.75;           // semantic gate (the paper's Dycheck value)
  double descriptor_rho = 0.5; // fraction of consistent feature samples kept per descriptor
};

// A graph over the nodes in smg's NeighborsView layout.
struct NodeGraph {
  int nodes = 0, k = 0;
  std::vector<std::int32_t> indices;  // [N][k], -1 padded
  std::vector<double> weights;        // [N][k]
  std::vector<double> distances;      // [N][k] trajectory distances
  smg::GraphStats stats;
  smg::NeighborsView<double> view() const { return {indices.data(), weights.data(), nodes, k}; }
};

struct Nodes {
  int frames = 0, count = 0, feature_dim = 0;
  double unit = 0;                    // the selection unit
  std::vector<int> track;             // [N] index into LiftedTracks
  std::vector<double> positions;      // [T][N][3] current estimate
  std::vector<double> rotations;      // [T][N][4] (w, x, y, z), unit
  std::vector<std::uint8_t> visible;  // [T][N] observed (lifted) samples
  std::vector<double> observed;       // [T][N][3] lifted observations (valid where visible)
  std::vector<double> truth;          // [T][N][3] ground truth (evaluation only)
  std::vector<int> body;              // [N] ground-truth body (diagnostics only)
  // Procedural scenes (diagnostics only; empty from disk): the node's semantic class, and per
  // sample whether the tracker's report there is a failure (priors.hpp: outlier, occluded
  // reported visible, stuck, switched).
  std::vector<int> semantic_class;           // [N]
  std::vector<std::uint8_t> failed_report;   // [T][N]
  std::vector<double> descriptors;    // [N][C]
  NodeGraph graph;                    // the variant's graph
  smg::NodeSelectionStats<double> selection;

  smg::PositionsView<const double> positions_view() const { return {positions.data(), frames, count}; }
  smg::QuaternionsView<const double> rotations_view() const { return {rotations.data(), frames, count}; }
  smg::VisibilityView<const std::uint8_t> visibility_view() const { return {visible.data(), frames, count}; }
  smg::PositionsView<const double> truth_view() const { return {truth.data(), frames, count}; }
};

// Stage 0: selects nodes among the lifted tracks and builds the graph (semantic = gated).
// Throws std::runtime_error if no node can be selected.
Nodes make_nodes(const LiftedTracks& lifted, const NodeOptions& options, bool semantic,
                 smg::ParallelOptions parallel = {});

// Builds `nodes.graph` from the current trajectories (replaces it).
void build_graph(Nodes& nodes, const NodeOptions& options, bool semantic, smg::ParallelOptions parallel = {});

// Rotations: identity at frame 0; at frame t the rotation R minimising
// Σ_j w_ij |R (x_j^0 − x_i^0) − (x_j^t − x_i^t)|² over the graph neighbours (weighted Kabsch);
// identity where the neighbourhood is degenerate (fewer than two neighbours or rank < 2).
void init_rotations(Nodes& nodes);

// How the C-ARAP term moves the nodes (docs/results.md, "C-ARAP"): `symmetric` follows the
// gradient of (E9), every term moving both of its nodes (the paper's energy, the default);
// `directed` follows smg::carap_directed's update (E20), term (i, j) moving node i only.
enum class CarapReading { symmetric, directed };
// What the confidences (E6) are computed from: the current estimate, every confidence_every
// stage-1 iterations (the paper's reading, the default); the lifted trajectories stage 1 starts
// from, once; or the ground-truth trajectories (an oracle for the procedural scene: what C-ARAP
// does when the confidences are as good as they can be).
enum class ConfidenceSource { estimate, lifted, truth };
inline const std::vector<std::string>& carap_reading_names() {
  static const std::vector<std::string> names = {"symmetric", "directed"};
  return names;
}
inline const std::vector<std::string>& confidence_source_names() {
  static const std::vector<std::string> names = {"estimate", "lifted", "truth"};
  return names;
}

// Whether the variant switches this term of the fused step (C-ARAP, plain ARAP, LRM) rather
// than its weight (every other term), and the confidences, which the trainer computes itself.
inline bool variant_term(const std::string& name) {
  return name == "confidence" || name == "carap" || name == "arap" || name == "lrm";
}

// Whether a term's options have an overall factor `weight` (every energy; not the confidences).
template <class O, class = void>
struct has_weight : std::false_type {};
template <class O>
struct has_weight<O, std::void_t<decltype(std::declval<O&>().weight)>> : std::true_type {};

// The regularisers' settings in the library's own options (smg::RegularizerOptions), so that a
// flag writes straight into them and a new term of the fused step needs no trainer code beyond
// its flag row (settings.cpp). Each term's `weight` is the trainer's weight per node and frame
// (per node and weighted frame pair for a term with gaps, the rigidity); regularizer_options
// normalises it. C-ARAP, plain ARAP and LRM are switched by the variant; every other term is on
// when its weight is above 0. `terms` is not read (the variant and the weights decide).
inline smg::RegularizerOptions default_node_regularizers() {
  smg::RegularizerOptions r;
  // Tuned once on seed 0 (quick scene, full variant) for the lowest stage-1 node EPE and used
  // unchanged by every variant and seed: at 1.0 the rigidity term wins against the Huber data
  // term and shrinks the node cloud (ARAP's energy falls as s^2 under a uniform scaling s of
  // every frame, the data term's Huber tail only as s).
  r.carap.weight = 0.1;  // plain ARAP or C-ARAP (one setting, --w-rigidity)
  r.arap.weight = 0.1;
  r.lrm.weight = 0.1;
  r.lrm.huber_delta = 0.01;  // metres per frame
  // The terms the paper does not have are off (weight 0) until a flag sets them; trajectory
  // smoothness (E21, unweighted accelerations, as MoSca and Shape-of-Motion) is --w-accel.
  smg::for_each_term(r, [](const char* name, bool, auto& o) {
    if constexpr (has_weight<std::decay_t<decltype(o)>>::value)
      if (!variant_term(name)) o.weight = 0.0;
  });
  return r;
}

struct NodeLossOptions {
  double data_weight = 1.0;
  double data_huber = 0.02;        // metres: lifted depth noise is ~3 cm at 1.5 m
  // The regularisers (above): weights per node and frame, alpha (E7) of C-ARAP and LRM, the
  // gaps, LRM's Huber width and the confidence options (E6).
  smg::RegularizerOptions regularizers = default_node_regularizers();
  CarapReading carap_reading = CarapReading::symmetric;
  ConfidenceSource confidence_source = ConfidenceSource::estimate;
  // E6's visibility factor v_{t,i}: off computes the confidences as if every sample were
  // observed (c = c^m c^r), so that an unobserved node keeps the weight its motion earns.
  bool confidence_visibility = true;
};

// The energies of one evaluation, unscaled: the data term and every regulariser as the fused
// step names them (the directed reading of C-ARAP under carap).
struct NodeLossTerms {
  double data = 0;
  smg::RegularizerResult<double> energy;
  double rigidity() const { return energy.carap + energy.arap; }  // C-ARAP or plain ARAP
  // In the order the terms were summed before the fused step (data first), so that logs compare.
  double total() const {
    double t = data;
    smg::RegularizerResult<double>::each_energy([&](const char*, double e) { t += e; }, energy);
    return t;
  }
};

// Data term + the variant's regularisers over the node trajectories, with exact gradients
// (positions [T][N][3], rotations in the right tangent [T][N][3]).
class NodeObjective {
 public:
  NodeObjective(const VariantSpec& variant, const NodeLossOptions& options, smg::ParallelOptions parallel = {});

  // Recomputes the confidences c_{t,i} (E6) from the observation visibility and the trajectories
  // options().confidence_source names (the current positions by default; the lifted ones are
  // those of the first call); a no-op for variants that do not use them.
  void update_confidences(const Nodes& nodes);
  const std::vector<double>& confidences() const { return confidence_; }

  // Energy terms; when the gradient buffers are given, adds scale * gradient to them.
  NodeLossTerms evaluate(const Nodes& nodes, double scale = 1.0, double* grad_positions = nullptr,
                         double* grad_rotations = nullptr);

  const VariantSpec& variant() const { return variant_; }
  const NodeLossOptions& options() const { return options_; }

  // The options of the library's fused step (smg::regularizers) that evaluate() calls for T frames
  // and N nodes, every weight times `scale`: the variant's rigidity (C-ARAP or plain ARAP, over
  // the gaps, per node and weighted frame pair), LRM and smoothness (per node and frame), the
  // confidences off (the trainer passes its own). The directed reading of C-ARAP is configured in
  // `carap` but off: evaluate() runs it apart (carap_directed, no term of the fused step).
  smg::RegularizerOptions regularizer_options(int frames, int nodes, double scale = 1.0) const;

 private:
  bool uses_confidence() const;
  bool directed_carap() const;
  VariantSpec variant_;
  NodeLossOptions options_;
  smg::ParallelOptions parallel_;
  std::vector<double> confidence_;  // [T][N]
  std::vector<double> lifted_;      // [T][N][3] the positions of the first update (source lifted)
  smg::EnergyWorkspace<double> ws_;
};

// Confidences c_{t,i} (E6) of trajectories `positions` [T][N][3] with the nodes' graph and their
// visibility (every sample visible when `visibility` is false), [T][N].
std::vector<double> node_confidences(const Nodes& nodes, const std::vector<double>& positions,
                                     const smg::ConfidenceOptions& options, smg::ParallelOptions parallel = {},
                                     bool visibility = true, smg::EnergyWorkspace<double>* workspace = nullptr);

// What the confidences measure, against the ground truth (procedural scenes; docs/results.md).
// Over the observed samples (t, i) of the nodes, with c the confidences (E6) of `positions`:
//   spearman_error: rank correlation of c with the true error |x_i^t − truth| of `positions`;
//   spearman_observation: the same with the error of the lifted observation y_i^t;
//   mean_by_observation_error[b]: mean c over the samples whose observation error is below 3 cm,
//     3-10 cm, 10-30 cm and above 30 cm (count_by_observation_error[b] samples);
//   mean_observed / low_observed: mean c and the fraction with c < 0.3, and *_truth the same
//     for the confidences of the true trajectories (what a perfect estimate would get);
// and over all samples (observed or not), split into low (c < 0.3) and high (c >= 0.7)
// confidence, the rigidity weight acting on a sample relative to plain ARAP (E7, uniform w):
//   symmetric reading: Σ_{j∈N(i)} w̃_ij + Σ_{k: i∈N(k)} w̃_ki over Σ w_ij + Σ w_ki (own terms and
//     the terms naming i as neighbour both move node i);
//   directed reading: Σ_{j∈N(i)} w̃_ij over Σ w_ij (own terms only, E20).
struct ConfidenceDiagnostics {
  double spearman_error = 0, spearman_observation = 0;
  double mean_by_observation_error[4] = {0, 0, 0, 0};
  long long count_by_observation_error[4] = {0, 0, 0, 0};
  double mean_observed = 0, low_observed = 0, mean_observed_truth = 0, low_observed_truth = 0;
  double low_fraction = 0;  // samples with c < 0.3 (all samples)
  double symmetric_low = 0, symmetric_high = 0, directed_low = 0, directed_high = 0;
  // With Nodes::failed_report: mean c over observed samples whose report is a tracker failure,
  // and over the others. With Nodes::semantic_class: mean c_j^t (the confidence that weights edge
  // i-j in E7) over edges joining two different bodies of one class (bending edges: the
  // bending scene's arm links, the two-link arm's elbow) and over edges inside one body (rigid).
  double failed_observed = 0, clean_observed = 0;
  long long count_failed_observed = 0;
  double edge_bending = 0, edge_rigid = 0;
  long long count_edge_bending = 0;
};
ConfidenceDiagnostics confidence_diagnostics(const Nodes& nodes, const std::vector<double>& positions,
                                             const smg::ConfidenceOptions& options, double alpha,
                                             smg::ParallelOptions parallel = {});

struct Stage1Options {
  int iterations = 500;
  // Adam's step is bounded by the learning rate, so lr * iterations must exceed the lifting's
  // depth outliers (tens of cm): 2e-3 left them in place.
  double lr_position = 2e-2, lr_position_final = 2e-3;  // metres per step, log-decayed
  double lr_rotation = 1e-2, lr_rotation_final = 1e-3;  // radians per step
  int confidence_every = 20;
  int log_every = 100;
};

struct Stage1Result {
  NodeLossTerms initial, final;
  int iterations = 0;
  double seconds = 0;
};

// Stage 1: Adam on node positions and rotations.
Stage1Result fit_nodes(Nodes& nodes, NodeObjective& objective, const Stage1Options& options,
                       const Progress& progress);

}  // namespace trainer
