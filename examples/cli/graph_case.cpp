// The graph of a case: loaded from graph_indices.npy/graph_weights.npy, or built with smg/graph.
#include "graph_case.hpp"

#include <chrono>
#include <limits>
#include <string>

#include "smg/graph.hpp"

namespace cli {

std::vector<FlagSpec> graph_flags() {
  return {{"k", "16", "neighbours per node (trajectory-level KNN)"},
          {"tau", "0.75", "semantic gate: keep an edge when cos(f_i, f_j) >= tau"},
          {"aggregation", "paper", "trajectory distance: paper | robust_max"},
          {"m", "3", "co-visible distances aggregated per pair"},
          {"min-covisible", "1", "minimum co-visible frames for a candidate pair"},
          {"isolated", "keep_nearest", "node left without gated edges: keep_nearest | leave"},
          {"rho", "0.5", "descriptor: fraction of most consistent feature samples kept"},
          {"weighting", "uniform", "topology weights: uniform (1/|N(i)|) | distance (Gaussian in D_ij)"},
          {"no-gate", "", "build a purely geometric graph even when the case has features", true},
          {"segment-frames", "0", "frames per segment of the exact KNN's candidate index, 0 = automatic"}};
}

namespace {

long long int_flag(const Args& a, const std::string& name, long long lo, long long hi) {
  const long long v = a.get_int(name);
  if (v < lo || v > hi)
    throw UsageError("--" + name + " must be between " + std::to_string(lo) + " and " + std::to_string(hi) +
                     ", got " + std::to_string(v));
  return v;
}

struct Config {
  smg::GraphOptions graph;
  smg::DescriptorOptions descriptor;
  bool no_gate = false;
};

Config parse(const Invocation& inv) {
  const Args& a = inv.args;
  Config c;
  constexpr long long kIntMax = std::numeric_limits<int>::max();
  c.graph.knn.k = static_cast<int>(int_flag(a, "k", 1, 1 << 20));
  c.graph.knn.distance.m = static_cast<int>(int_flag(a, "m", 1, kIntMax));
  c.graph.knn.distance.min_covisible = static_cast<int>(int_flag(a, "min-covisible", 0, kIntMax));
  c.graph.knn.distance.aggregation = a.get_choice("aggregation", {"paper", "robust_max"}) == "paper"
                                         ? smg::Aggregation::paper
                                         : smg::Aggregation::robust_max;
  c.graph.knn.segment_frames = static_cast<int>(int_flag(a, "segment-frames", 0, kIntMax));
  c.graph.knn.parallel.threads = inv.threads;
  c.graph.tau = a.get_double("tau");
  c.graph.isolated = a.get_choice("isolated", {"keep_nearest", "leave"}) == "keep_nearest"
                         ? smg::IsolatedPolicy::keep_nearest
                         : smg::IsolatedPolicy::leave;
  c.graph.weighting = a.get_choice("weighting", {"uniform", "distance"}) == "uniform"
                          ? smg::TopologyWeighting::uniform
                          : smg::TopologyWeighting::distance;
  c.descriptor.rho = a.get_double("rho");
  if (!(c.descriptor.rho > 0 && c.descriptor.rho <= 1))
    throw UsageError("--rho must be in (0, 1], got '" + a.get("rho") + "'");
  c.descriptor.parallel.threads = inv.threads;
  c.no_gate = a.get_switch("no-gate");
  return c;
}

void check(const smg::Status& s) {
  if (!s) throw RunError(s.message());
}

template <class S>
std::vector<S> cast(const std::vector<double>& v) {
  return std::vector<S>(v.begin(), v.end());
}

template <class S>
CaseGraph build_typed(const Invocation& inv, const Tensor<double>& positions, Config cfg) {
  const CaseDir& c = inv.case_dir;
  const std::int64_t T = positions.dim(0), N = positions.dim(1);
  const auto vis = c.load_optional<std::uint8_t>("visibility.npy", {{"T", T}, {"N", N}});
  const smg::VisibilityView<const std::uint8_t> v =
      vis ? smg::VisibilityView<const std::uint8_t>(vis->ptr(), T, N) : smg::VisibilityView<const std::uint8_t>();

  CaseGraph g;
  g.nodes = N;
  g.frames = T;
  g.k = cfg.graph.knn.k;
  g.built = true;
  g.aggregation = smg::to_string(cfg.graph.knn.distance.aggregation);

  // Inputs in the computation's precision (loading and conversion are not timed).
  const std::vector<S> x = cast<S>(positions.data);
  std::vector<S> features, samples;
  if (c.has("features.npy")) {
    const auto f = c.load<double>("features.npy", {{"N", N}, {"C"}});
    g.channels = f.dim(1);
    g.features_source = "features.npy";
    features = cast<S>(f.data);
  } else if (c.has("feature_samples.npy")) {
    const auto s = c.load<double>("feature_samples.npy", {{"T", T}, {"N", N}, {"C"}});
    g.channels = s.dim(2);
    g.features_source = "feature_samples.npy";
    samples = cast<S>(s.data);
  }
  if (g.features_source != "none" && g.channels < 1)
    throw RunError((c.path() / g.features_source).string() + ": needs at least one channel (C >= 1)");

  const auto t0 = std::chrono::steady_clock::now();
  if (!samples.empty()) {
    features.resize(static_cast<std::size_t>(N * g.channels));
    const smg::FeatureSamplesView<const S> sv(samples.data(), T, N, g.channels);
    const smg::FeaturesView<S> out(features.data(), N, g.channels);
    check(smg::validate_semantic_descriptors<S>(sv, v, cfg.descriptor, out));
    smg::semantic_descriptors<S>(sv, v, cfg.descriptor, out);
  }
  cfg.graph.gate = !cfg.no_gate && g.channels > 0;
  g.gated = cfg.graph.gate;
  const smg::FeaturesView<const S> fv = cfg.graph.gate ? smg::FeaturesView<const S>(features.data(), N, g.channels)
                                                       : smg::FeaturesView<const S>();
  const std::size_t NK = static_cast<std::size_t>(N * g.k);
  std::vector<std::int32_t> idx(NK);
  std::vector<S> w(NK), d(NK);
  const smg::TableView<std::int32_t, Eigen::Dynamic> iv(idx.data(), N, g.k);
  const smg::TableView<S, Eigen::Dynamic> wv(w.data(), N, g.k), dv(d.data(), N, g.k);
  check(smg::validate_semantic_graph<S>({x.data(), T, N}, v, fv, cfg.graph, iv, wv, dv));
  const smg::GraphStats st = smg::build_semantic_graph<S>({x.data(), T, N}, v, fv, cfg.graph, iv, wv, dv);
  g.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  g.indices = std::move(idx);
  g.weights.assign(w.begin(), w.end());
  g.distances.assign(d.begin(), d.end());
  g.features.assign(features.begin(), features.end());
  g.edges = st.edges;
  g.mean_degree = st.mean_degree;
  g.isolated_nodes = st.isolated_nodes;
  g.nodes_without_candidates = st.nodes_without_candidates;
  g.gate_removed_edges = st.gate_removed_edges;
  g.kept_nearest = st.kept_nearest;
  g.zero_feature_nodes = st.zero_feature_nodes;
  g.pairs_evaluated = st.knn.pairs_evaluated;
  g.segment_frames = st.knn.segment_frames;
  return g;
}

}  // namespace

CaseGraph build_case_graph(const Invocation& inv, const Tensor<double>& positions) {
  const Config cfg = parse(inv);
  return inv.use_float ? build_typed<float>(inv, positions, cfg) : build_typed<double>(inv, positions, cfg);
}

CaseGraph load_or_build_graph(const Invocation& inv, const Tensor<double>& positions) {
  const std::int64_t N = positions.dim(1);
  const CaseDir& c = inv.case_dir;
  if (!c.has("graph_indices.npy")) return build_case_graph(inv, positions);
  const auto idx = c.load<std::int32_t>("graph_indices.npy", {{"N", N}, {"K"}});
  const std::int64_t K = idx.dim(1);
  const auto w = c.load<double>("graph_weights.npy", {{"N", N}, {"K", K}});
  const smg::NeighborsView<double> view(idx.ptr(), w.ptr(), N, K);
  if (smg::Status s = smg::validate_neighbors(view, N, "graph_indices.npy/graph_weights.npy"); !s)
    throw RunError(s.message());
  CaseGraph g;
  g.nodes = N;
  g.k = K;
  g.indices = idx.data;
  g.weights = w.data;
  g.built = false;
  return g;
}

void add_graph_summary(const CaseGraph& g, JsonLine& summary) {
  summary.add("K", g.k)
      .add("gated", g.gated)
      .add("features", g.features_source)
      .add("aggregation", g.aggregation)
      .add("edges", g.edges)
      .add("mean_degree", g.mean_degree)
      .add("isolated_nodes", g.isolated_nodes)
      .add("nodes_without_candidates", g.nodes_without_candidates)
      .add("gate_removed_edges", g.gate_removed_edges)
      .add("kept_nearest", g.kept_nearest)
      .add("zero_feature_nodes", g.zero_feature_nodes)
      .add("pairs_evaluated", g.pairs_evaluated)
      .add("segment_frames", g.segment_frames);
}

}  // namespace cli
