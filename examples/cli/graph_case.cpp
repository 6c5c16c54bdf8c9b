// The graph of a case: loaded from graph_indices.npy/graph_weights.npy, or built with smg/graph.
#include "graph_case.hpp"

#include <chrono>
#include <limits>
#include <utility>
#include <string>

#include "smg/core/validate.hpp"
#include "smg/graph.hpp"

namespace cli {

std::vector<FlagSpec> graph_flags() {
  // Defaults come from the library's option structs, so each exists once.
  const smg::GraphOptions g{};
  const smg::DescriptorOptions d{};
  return {{"k", format_number(g.knn.k), "neighbours per node (trajectory-level KNN)"},
          {"tau", format_number(g.tau), "semantic gate: keep an edge when cos(f_i, f_j) >= tau"},
          {"aggregation", smg::to_string(g.knn.distance.aggregation), "trajectory distance: paper | robust_max"},
          {"m", format_number(g.knn.distance.m), "co-visible distances aggregated per pair"},
          {"min-covisible", format_number(g.knn.distance.min_covisible), "minimum co-visible frames for a candidate pair"},
          {"isolated", smg::to_string(g.isolated), "node left without gated edges: keep_nearest | leave"},
          {"rho", format_number(d.rho), "descriptor: fraction of most consistent feature samples kept"},
          {"weighting", smg::to_string(g.weighting), "topology weights: uniform (1/|N(i)|) | distance (Gaussian in D_ij)"},
          {"no-gate", "", "build a purely geometric graph even when the case has features", true},
          {"segment-frames", format_number(g.knn.segment_frames),
           "frames per segment of the exact KNN's candidate index, 0 = automatic"}};
}

namespace {

// Library option names -> flags.
const NameMap& graph_flag_names() {
  static const NameMap names = {{"k", "--k"},
                                {"tau", "--tau"},
                                {"m", "--m"},
                                {"min_covisible", "--min-covisible"},
                                {"aggregation", "--aggregation"},
                                {"segment_frames", "--segment-frames"},
                                {"rho", "--rho"}};
  return names;
}

struct Config {
  smg::GraphOptions graph;
  smg::DescriptorOptions descriptor;
  bool no_gate = false;
};

Config parse(const Invocation& inv) {
  const Args& a = inv.args;
  Config c;
  // Integer flags: parsed as 64-bit, range-checked to int before narrowing; the option rules
  // themselves are the library's (validate_distance_options, validate_semantic_descriptors).
  c.graph.knn.k = a.get_int32_in("k", 1);
  c.graph.knn.distance.m = a.get_int32_in("m");
  c.graph.knn.distance.min_covisible = a.get_int32_in("min-covisible");
  c.graph.knn.distance.aggregation = a.get_choice("aggregation", {"paper", "robust_max"}) == "paper"
                                         ? smg::Aggregation::paper
                                         : smg::Aggregation::robust_max;
  c.graph.knn.segment_frames = a.get_int32_in("segment-frames");
  c.graph.knn.parallel.threads = inv.threads;
  c.graph.tau = a.get_double("tau");
  c.graph.isolated = a.get_choice("isolated", {"keep_nearest", "leave"}) == "keep_nearest"
                         ? smg::IsolatedPolicy::keep_nearest
                         : smg::IsolatedPolicy::leave;
  c.graph.weighting = a.get_choice("weighting", {"uniform", "distance"}) == "uniform"
                          ? smg::TopologyWeighting::uniform
                          : smg::TopologyWeighting::distance;
  c.descriptor.rho = a.get_double("rho");
  c.descriptor.parallel.threads = inv.threads;
  c.no_gate = a.get_switch("no-gate");
  check_mapped(smg::detail::validate_distance_options(c.graph.knn.distance), graph_flag_names(), "graph options");
  if (c.graph.knn.segment_frames < 0)  // the library's own rule, checked again by validate_semantic_graph
    check_mapped(smg::Status::error("segment_frames: must be >= 0, got " + std::to_string(c.graph.knn.segment_frames)),
                 graph_flag_names(), "graph options");
  {  // rho: the library's rule, on a 1x1x1 dummy input
    const double sample = 1, visible_out = 0;
    double out = visible_out;
    check_mapped(smg::validate_semantic_descriptors<double>({&sample, 1, 1, 1}, {}, c.descriptor, {&out, 1, 1}),
                 graph_flag_names(), "graph options");
  }
  return c;
}

// Library data names -> the case's files.
NameMap data_names(const CaseDir& c) {
  NameMap n = graph_flag_names();
  for (const char* f : {"positions", "visibility", "features", "feature_samples", "samples"})
    n.push_back({f, c.file(std::string(f == std::string("samples") ? "feature_samples" : f) + ".npy")});
  return n;
}

template <class S>
CaseGraph build_typed(const Invocation& inv, const Tensor<double>& positions, Config cfg) {
  const CaseDir& c = inv.case_dir;
  const std::int64_t T = positions.dim(0), N = positions.dim(1);
  const NameMap names = data_names(c);
  auto check = [&](const smg::Status& s) { check_mapped(s, names, c.file("positions.npy")); };
  require_coordinates<S>(positions.data, c.file("positions.npy"));
  {
    // Outputs (indices, weights, distances; kept as double and converted) + the KNN's node-major
    // trajectory copy and candidate buffers + the converted inputs.
    const double K = double(cfg.graph.knn.k), n = double(N), t = double(T), s = double(sizeof(S));
    const double bytes = n * K * (4 + 3 * s + 3 * 8) * 2 + n * t * (3 * s * 3 + 8);
    check_memory(bytes, inv.max_bytes, "--k: k = " + std::to_string(cfg.graph.knn.k) + " neighbours of N = " +
                                           std::to_string(N) + " nodes over T = " + std::to_string(T) + " frames");
  }
  const AllocContext ctx("graph of " + c.file("positions.npy"));
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
  if (g.features_source != "none")
    require_coordinates<S>(g.features_source == "features.npy" ? features : samples, c.file(g.features_source));

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

  // Finite inputs must give finite results (docs/interop.md "Overflow").
  require_finite(d, c.file("positions.npy") +
                        ": coordinates too large: the trajectory distances overflow (non-finite distance)");
  require_finite(w, c.file("positions.npy") + ": coordinates too large: the graph weights overflow (non-finite weight)");
  require_finite(features, c.file(g.features_source) + ": values too large: the descriptors overflow (non-finite descriptor)");
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
  // Loaded as int32 through a range-checked conversion (an int64 value beyond int32 is an error,
  // never wrapped); validate_neighbors then checks each index against [-1, N).
  const auto idx = c.load<std::int32_t>("graph_indices.npy", {{"N", N}, {"K"}});
  const std::int64_t K = idx.dim(1);
  const auto w = c.load<double>("graph_weights.npy", {{"N", N}, {"K", K}});
  const smg::NeighborsView<double> view(idx.ptr(), w.ptr(), N, K);
  if (smg::Status s = smg::validate_neighbors(view, N, c.file("graph_indices.npy")); !s)
    throw RunError(s.message());
  CaseGraph g;
  g.nodes = N;
  g.k = K;
  g.indices = idx.data;
  g.weights = w.data;
  g.built = false;
  return g;
}

EnergyCase load_energy_case(const Invocation& inv, double bytes_per_frame_node) {
  const CaseDir& c = inv.case_dir;
  EnergyCase e;
  e.x = c.load<double>("positions.npy", {{"T"}, {"N"}, {"", 3}});
  const std::int64_t T = e.x.dim(0), N = e.x.dim(1);
  ok(smg::validate_positions<double>({e.x.ptr(), T, N}, T, N, c.file("positions.npy")));
  if (inv.use_float)
    require_coordinates<float>(e.x.data, c.file("positions.npy"));
  else
    require_coordinates<double>(e.x.data, c.file("positions.npy"));
  check_memory(double(T) * double(N) * bytes_per_frame_node, inv.max_bytes,
               c.file("positions.npy") + ": T = " + std::to_string(T) + " frames x N = " + std::to_string(N) + " nodes");
  if (auto qs = c.load_optional<double>("quats.npy", {{"T", T}, {"N", N}, {"", 4}})) {
    ok(smg::validate_quaternions<double>({qs->ptr(), T, N}, T, N,
                                         smg::QuaternionNorm::normalize_on_entry, c.file("quats.npy")));
    e.q = std::move(qs->data);
  } else {
    e.q.assign(static_cast<std::size_t>(T * N * 4), 0.0);
    for (std::int64_t k = 0; k < T * N; ++k) e.q[static_cast<std::size_t>(4 * k)] = 1.0;
  }
  if (auto v = c.load_optional<std::uint8_t>("visibility.npy", {{"T", T}, {"N", N}}))
    e.vis = std::move(v->data);
  else
    e.vis.assign(static_cast<std::size_t>(T * N), 1);
  e.g = load_or_build_graph(inv, e.x);
  return e;
}

smg::GapList read_gap_list(const Args& a, const std::string& gaps_flag, const std::string& weights_flag) {
  const auto gaps = a.get_ints(gaps_flag);
  const auto weights = a.get_doubles(weights_flag);
  if (gaps.empty()) throw UsageError("--" + gaps_flag + ": needs at least one gap");
  if (weights.size() != gaps.size())
    throw UsageError("--" + weights_flag + ": needs one weight per gap (" + std::to_string(gaps.size()) + "), got " +
                     std::to_string(weights.size()));
  smg::GapList list;
  for (std::size_t k = 0; k < gaps.size(); ++k) {
    const long long delta = Args::in_range(gaps_flag, gaps[k], std::numeric_limits<int>::min(),
                                           std::numeric_limits<int>::max());
    list.push_back({static_cast<int>(delta), weights[k]});
  }
  return list;
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
