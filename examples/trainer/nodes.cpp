// examples/trainer/nodes.cpp — node selection, graph, rotation initialisation and stage 1.
#include "trainer/nodes.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/SVD>

#include "trainer/adam.hpp"
#include "trainer/util.hpp"

namespace trainer {

void build_graph(Nodes& n, const NodeOptions& o, bool semantic, smg::ParallelOptions parallel) {
  const int N = n.count, K = o.k;
  NodeGraph& g = n.graph;
  g.nodes = N;
  g.k = K;
  g.indices.assign(sz(N) * K, -1);
  g.weights.assign(sz(N) * K, 0.0);
  g.distances.assign(sz(N) * K, 0.0);
  smg::GraphOptions go;
  go.knn.k = K;
  go.knn.parallel = parallel;
  go.gate = semantic;
  go.tau = o.tau;
  smg::FeaturesView<const double> f(n.descriptors.data(), N, n.feature_dim);
  smg::TableView<std::int32_t, Eigen::Dynamic> idx(g.indices.data(), N, K);
  smg::TableView<double, Eigen::Dynamic> w(g.weights.data(), N, K), d(g.distances.data(), N, K);
  check(smg::validate_semantic_graph<double>(n.positions_view(), n.visibility_view(), semantic ? f : smg::FeaturesView<const double>{},
                                             go, idx, w, d),
        "build_semantic_graph");
  g.stats = smg::build_semantic_graph<double>(n.positions_view(), n.visibility_view(),
                                              semantic ? f : smg::FeaturesView<const double>{}, go, idx, w, d);
}

Nodes make_nodes(const LiftedTracks& l, const NodeOptions& o, bool semantic, smg::ParallelOptions parallel) {
  const int T = l.frames, M = l.count, C = l.feature_dim;
  // Adaptive selection over the lifted trajectories.
  std::vector<std::int32_t> selected(sz(M), -1), assignment(sz(M), -1);
  std::vector<double> error(sz(M), 0.0);
  smg::NodeSelectionOptions so;
  so.unit = o.unit;
  so.min_visible = o.min_visible;
  so.parallel = parallel;
  smg::TableView<std::int32_t, 1> sel(selected.data(), M), asg(assignment.data(), M);
  smg::TableView<double, 1> err(error.data(), M);
  check(smg::validate_node_selection<double>(l.positions_view(), l.visibility_view(), so, sel, asg, err),
        "select_nodes");
  Nodes n;
  n.selection = smg::select_nodes<double>(l.positions_view(), l.visibility_view(), so, sel, asg, err);
  const int N = static_cast<int>(n.selection.selected);
  if (N == 0) throw std::runtime_error("make_nodes: no node selected (no lifted object track)");
  // Keep the nodes in track order (deterministic, and groups nodes of one track batch).
  for (int k = 0; k < N; ++k) n.track.push_back(selected[sz(k)]);
  std::sort(n.track.begin(), n.track.end());

  n.frames = T;
  n.count = N;
  n.feature_dim = C;
  n.unit = o.unit;
  n.positions.assign(sz(T) * N * 3, 0.0);
  n.rotations.assign(sz(T) * N * 4, 0.0);
  n.visible.assign(sz(T) * N, 0);
  n.observed.assign(sz(T) * N * 3, 0.0);
  n.truth.assign(sz(T) * N * 3, 0.0);
  std::vector<double> samples(sz(T) * N * C, 0.0);
  for (int i = 0; i < N; ++i) {
    const int j = n.track[sz(i)];
    n.body.push_back(l.body[sz(j)]);
    for (int t = 0; t < T; ++t) {
      const std::size_t s = sz(t) * l.count + j, d = sz(t) * N + i;
      for (int c = 0; c < 3; ++c) {
        n.positions[d * 3 + c] = l.positions[s * 3 + c];
        n.truth[d * 3 + c] = l.positions_true[s * 3 + c];
        if (l.visible[s]) n.observed[d * 3 + c] = l.positions[s * 3 + c];
      }
      n.rotations[d * 4] = 1.0;
      n.visible[d] = l.visible[s];
      for (int c = 0; c < C; ++c) samples[d * C + c] = l.feature_samples[s * C + c];
    }
  }
  // Descriptors (G7)-(G8); none without feature channels (a scene without feature files), whose
  // graph can then only be geometric.
  n.descriptors.assign(sz(N) * C, 0.0);
  if (C == 0 && semantic) throw std::invalid_argument("make_nodes: a semantic graph needs feature samples (C = 0)");
  if (C > 0) {
    smg::DescriptorOptions dopt;
    dopt.rho = o.descriptor_rho;
    dopt.parallel = parallel;
    smg::FeatureSamplesView<const double> sv(samples.data(), T, N, C);
    smg::FeaturesView<double> dv(n.descriptors.data(), N, C);
    check(smg::validate_semantic_descriptors<double>(sv, n.visibility_view(), dopt, dv), "semantic_descriptors");
    smg::semantic_descriptors<double>(sv, n.visibility_view(), dopt, dv);
  }
  build_graph(n, o, semantic, parallel);
  return n;
}

void init_rotations(Nodes& n) {
  const int T = n.frames, N = n.count, K = n.graph.k;
  const auto x = [&](int t, int i) { return Eigen::Map<const Eigen::Vector3d>(n.positions.data() + (sz(t) * N + i) * 3); };
  for (int i = 0; i < N; ++i) {
    for (int t = 0; t < T; ++t) {
      Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
      int used = 0;
      for (int k = 0; k < K; ++k) {
        const int j = n.graph.indices[sz(i) * K + k];
        if (j < 0) break;
        const double w = n.graph.weights[sz(i) * K + k];
        H += w * (x(0, j) - x(0, i)) * (x(t, j) - x(t, i)).transpose();
        ++used;
      }
      Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
      if (t > 0 && used >= 2) {
        const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
        const Eigen::Vector3d& s = svd.singularValues();
        if (s(1) > 1e-9 * std::max(1e-30, s(0))) {
          Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
          D(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
          q = Eigen::Quaterniond(Eigen::Matrix3d(svd.matrixV() * D * svd.matrixU().transpose()));
          q.normalize();
        }
      }
      smg::to_wxyz(q, n.rotations.data() + (sz(t) * N + i) * 4);
    }
  }
}

NodeObjective::NodeObjective(const VariantSpec& variant, const NodeLossOptions& options, smg::ParallelOptions parallel)
    : variant_(variant), options_(options), parallel_(parallel) {}

bool NodeObjective::uses_confidence() const {
  return variant_.rigidity == Rigidity::carap || variant_.lrm;
}

std::vector<double> node_confidences(const Nodes& n, const std::vector<double>& positions,
                                     const smg::ConfidenceOptions& options, smg::ParallelOptions parallel,
                                     bool visibility, smg::EnergyWorkspace<double>* workspace) {
  std::vector<double> out(sz(n.frames) * n.count, 0.0);
  const smg::PositionsView<const double> x(positions.data(), n.frames, n.count);
  smg::FrameScalarsView<double> c(out.data(), n.frames, n.count);
  const std::vector<std::uint8_t> all(visibility ? 0 : n.visible.size(), 1);
  const smg::VisibilityView<const std::uint8_t> v =
      visibility ? n.visibility_view() : smg::VisibilityView<const std::uint8_t>(all.data(), n.frames, n.count);
  check(smg::validate_confidence<double>(x, v, n.graph.view(), options, c), "node_confidences");
  smg::node_confidences<double>(x, v, n.graph.view(), options, c, {}, {}, workspace, parallel);
  return out;
}

void NodeObjective::update_confidences(const Nodes& n) {
  if (!uses_confidence()) return;
  // The lifted and the true trajectories do not change: their confidences are computed once.
  if (options_.confidence_source != ConfidenceSource::estimate && confidence_.size() == sz(n.frames) * n.count) return;
  const std::vector<double>* from = &n.positions;
  if (options_.confidence_source == ConfidenceSource::lifted) {
    if (lifted_.empty()) lifted_ = n.positions;
    from = &lifted_;
  } else if (options_.confidence_source == ConfidenceSource::truth) {
    if (n.truth.size() != n.positions.size())
      throw std::invalid_argument("confidences from the truth need the procedural scene's ground truth");
    from = &n.truth;
  }
  confidence_ = node_confidences(n, *from, options_.regularizers.confidence, parallel_, options_.confidence_visibility,
                                 &ws_);
}

namespace {

// Ranks 1..n of xs, ties given their mean rank.
std::vector<double> ranks(const std::vector<double>& xs) {
  std::vector<std::size_t> order(xs.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return xs[a] < xs[b]; });
  std::vector<double> r(xs.size());
  for (std::size_t a = 0; a < order.size();) {
    std::size_t b = a;
    while (b + 1 < order.size() && xs[order[b + 1]] == xs[order[a]]) ++b;
    for (std::size_t k = a; k <= b; ++k) r[order[k]] = 0.5 * static_cast<double>(a + b) + 1.0;
    a = b + 1;
  }
  return r;
}

// Spearman's rank correlation (Pearson's of the ranks); 0 when either side is constant.
double spearman(const std::vector<double>& a, const std::vector<double>& b) {
  const std::vector<double> ra = ranks(a), rb = ranks(b);
  const double n = static_cast<double>(a.size());
  double ma = 0, mb = 0;
  for (std::size_t k = 0; k < ra.size(); ++k) {
    ma += ra[k] / n;
    mb += rb[k] / n;
  }
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t k = 0; k < ra.size(); ++k) {
    sab += (ra[k] - ma) * (rb[k] - mb);
    saa += (ra[k] - ma) * (ra[k] - ma);
    sbb += (rb[k] - mb) * (rb[k] - mb);
  }
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : 0.0;
}

}  // namespace

ConfidenceDiagnostics confidence_diagnostics(const Nodes& n, const std::vector<double>& positions,
                                             const smg::ConfidenceOptions& options, double alpha,
                                             smg::ParallelOptions parallel) {
  ConfidenceDiagnostics d;
  const int T = n.frames, N = n.count, K = n.graph.k;
  if (n.truth.size() != positions.size() || N == 0) return d;
  const std::vector<double> c = node_confidences(n, positions, options, parallel);
  const auto dist = [](const double* a, const double* b) {
    return (Eigen::Map<const Eigen::Vector3d>(a) - Eigen::Map<const Eigen::Vector3d>(b)).norm();
  };
  const std::vector<double> c_truth = node_confidences(n, n.truth, options, parallel);
  std::vector<double> conf, err, obs_err;
  double sum[4] = {0, 0, 0, 0};
  for (std::size_t s = 0; s < n.visible.size(); ++s) {
    if (!n.visible[s]) continue;
    d.mean_observed += c[s];
    d.low_observed += c[s] < 0.3;
    d.mean_observed_truth += c_truth[s];
    d.low_observed_truth += c_truth[s] < 0.3;
    conf.push_back(c[s]);
    err.push_back(dist(positions.data() + 3 * s, n.truth.data() + 3 * s));
    const double e = dist(n.observed.data() + 3 * s, n.truth.data() + 3 * s);
    obs_err.push_back(e);
    const int bin = e < 0.03 ? 0 : e < 0.10 ? 1 : e < 0.30 ? 2 : 3;
    sum[bin] += c[s];
    ++d.count_by_observation_error[bin];
  }
  for (int b = 0; b < 4; ++b)
    d.mean_by_observation_error[b] = d.count_by_observation_error[b] > 0 ? sum[b] / d.count_by_observation_error[b] : 0;
  if (!conf.empty()) {
    const double m = static_cast<double>(conf.size());
    d.mean_observed /= m;
    d.low_observed /= m;
    d.mean_observed_truth /= m;
    d.low_observed_truth /= m;
  }
  d.spearman_error = spearman(conf, err);
  d.spearman_observation = spearman(conf, obs_err);
  // Weight acting on each sample under both readings, relative to plain ARAP.
  const auto wt = [&](int t, int j) { return alpha + (1 - alpha) * c[sz(t) * N + j]; };
  double sym[2] = {0, 0}, dir[2] = {0, 0};
  long long cnt[2] = {0, 0}, low = 0;
  std::vector<double> own(sz(N)), own_arap(sz(N)), in(sz(N)), in_arap(sz(N));
  for (int t = 0; t < T; ++t) {
    for (std::vector<double>* v : {&own, &own_arap, &in, &in_arap}) std::fill(v->begin(), v->end(), 0.0);
    for (int i = 0; i < N; ++i)
      for (int k = 0; k < K; ++k) {
        const int j = n.graph.indices[sz(i) * K + k];
        if (j < 0) break;
        const double w = n.graph.weights[sz(i) * K + k];
        own[sz(i)] += w * wt(t, j);
        own_arap[sz(i)] += w;
        in[sz(j)] += w * wt(t, j);
        in_arap[sz(j)] += w;
      }
    for (int i = 0; i < N; ++i) {
      const double ci = c[sz(t) * N + i];
      low += ci < 0.3;
      if (ci >= 0.3 && ci < 0.7) continue;
      const int g = ci < 0.3 ? 0 : 1;
      const double arap = own_arap[sz(i)] + in_arap[sz(i)];
      if (arap <= 0 || own_arap[sz(i)] <= 0) continue;
      sym[g] += (own[sz(i)] + in[sz(i)]) / arap;
      dir[g] += own[sz(i)] / own_arap[sz(i)];
      ++cnt[g];
    }
  }
  d.low_fraction = static_cast<double>(low) / (static_cast<double>(T) * N);
  if (n.failed_report.size() == n.visible.size()) {
    double f = 0, g = 0;
    long long nf = 0, ng = 0;
    for (std::size_t s = 0; s < n.visible.size(); ++s) {
      if (!n.visible[s]) continue;
      if (n.failed_report[s]) {
        f += c[s];
        ++nf;
      } else {
        g += c[s];
        ++ng;
      }
    }
    d.failed_observed = nf ? f / static_cast<double>(nf) : 0;
    d.clean_observed = ng ? g / static_cast<double>(ng) : 0;
    d.count_failed_observed = nf;
  }
  if (n.semantic_class.size() == sz(N) && n.body.size() == sz(N)) {
    double bend = 0, rigid = 0;
    long long nb = 0, nr = 0;
    for (int i = 0; i < N; ++i)
      for (int k = 0; k < K; ++k) {
        const int j = n.graph.indices[sz(i) * K + k];
        if (j < 0) break;
        const bool same_body = n.body[sz(i)] == n.body[sz(j)];
        if (!same_body && n.semantic_class[sz(i)] != n.semantic_class[sz(j)]) continue;
        double sum = 0;
        for (int t = 0; t < T; ++t) sum += c[sz(t) * N + j];
        (same_body ? rigid : bend) += sum;
        (same_body ? nr : nb) += T;
      }
    d.edge_bending = nb ? bend / static_cast<double>(nb) : 0;
    d.edge_rigid = nr ? rigid / static_cast<double>(nr) : 0;
    d.count_edge_bending = nb / std::max(1, T);
  }
  d.symmetric_low = cnt[0] ? sym[0] / cnt[0] : 0;
  d.symmetric_high = cnt[1] ? sym[1] / cnt[1] : 0;
  d.directed_low = cnt[0] ? dir[0] / cnt[0] : 0;
  d.directed_high = cnt[1] ? dir[1] / cnt[1] : 0;
  return d;
}

NodeLossTerms NodeObjective::evaluate(const Nodes& n, double scale, double* gp, double* gr) {
  const int T = n.frames, N = n.count;
  NodeLossTerms out;
  if (scale == 0) {  // nothing to add: report the unscaled terms (the energies run with weight = scale)
    gp = nullptr;
    gr = nullptr;
    scale = 1.0;
  }
  const double per_node_frame = 1.0 / (static_cast<double>(T) * N);
  // Data term: Huber on the distance to the lifted observation, where observed.
  {
    const double d = options_.data_huber, w = options_.data_weight * per_node_frame;
    double e = 0;
    for (std::size_t s = 0; s < n.visible.size(); ++s) {
      if (!n.visible[s]) continue;
      const Eigen::Vector3d r = Eigen::Map<const Eigen::Vector3d>(n.positions.data() + 3 * s) -
                                Eigen::Map<const Eigen::Vector3d>(n.observed.data() + 3 * s);
      const double len = r.norm();
      e += len <= d ? 0.5 * len * len : d * (len - 0.5 * d);
      if (gp) {
        const Eigen::Vector3d g = (len <= d ? r : (d / len) * r) * (scale * w);
        for (int c = 0; c < 3; ++c) gp[3 * s + c] += g(c);
      }
    }
    out.data = w * e;
  }
  // The regularisers: one call of the library's fused step, smg::regularizers, with the options
  // regularizer_options() builds from the settings (the scale through each term's weight). The
  // energies add their gradient into the buffers. The directed reading of C-ARAP is no term of
  // the fused step (an update, not a gradient, E20): it stays the separate carap_directed().
  const smg::RegularizerOptions ro = regularizer_options(T, N, scale);
  bool any = false;
  smg::for_each_term(ro, [&](const char*, bool on, const auto&) { any = any || on; });
  const bool directed = directed_carap();
  if (!any && !directed) return out;
  smg::PositionsView<double> gpv(gp, gp ? T : 0, gp ? N : 0);
  smg::TangentsView<double> grv(gr, gr ? T : 0, gr ? N : 0);
  const bool conf = uses_confidence();
  if (conf && confidence_.size() != sz(T) * N) update_confidences(n);
  // The trainer's confidences (refreshed every few iterations, or from the truth) as the caller's
  // c of the fused step, which computes none itself here (ro.terms.confidence is off).
  smg::FrameScalarsView<double> cview(conf ? confidence_.data() : nullptr, conf ? T : 0, conf ? N : 0);
  if (any) {
    check(smg::validate_regularizers<double>(n.positions_view(), n.rotations_view(), {}, n.graph.view(), ro, cview,
                                             gpv, grv),
          "regularizers");
    const smg::RegularizerResult<double> r = smg::regularizers<double>(
        n.positions_view(), n.rotations_view(), {}, n.graph.view(), ro, cview, gpv, grv, &ws_, parallel_);
    // Every energy unscaled (a term that is off is 0 and stays 0).
    smg::RegularizerResult<double>::each_energy([&](const char*, double& e, double v) { e = v / scale; }, out.energy,
                                                r);
  }
  if (directed) {
    smg::CarapOptions co = ro.carap;  // configured as for the fused step's C-ARAP
    const smg::FrameScalarsView<const double> c(cview.data(), cview.frames(), cview.nodes());
    check(smg::validate_carap<double>(n.positions_view(), n.rotations_view(), c, n.graph.view(), co, gpv, grv), "carap");
    out.energy.carap = smg::carap_directed<double>(n.positions_view(), n.rotations_view(), c, n.graph.view(), co, gpv,
                                                   grv, parallel_) /
                       scale;
  }
  return out;
}

bool NodeObjective::directed_carap() const {
  return variant_.rigidity == Rigidity::carap && options_.carap_reading == CarapReading::directed;
}

namespace {

// Whether a term's options have temporal gaps (C-ARAP, plain ARAP): its weight is normalised per
// weighted frame pair instead of per frame.
template <class O, class = void>
struct has_gaps : std::false_type {};
template <class O>
struct has_gaps<O, std::void_t<decltype(std::declval<O&>().gaps)>> : std::true_type {};

// The terms of the stage-1 log line: data and rigidity (C-ARAP or plain ARAP), then every other
// term of the fused step that is on, by the library's name, so that a new term shows itself.
std::string terms_line(const NodeLossTerms& l, const smg::RegularizerOptions& ro) {
  std::string s = format("data %.3e  rigidity %.3e", l.data, l.rigidity());
  std::vector<std::string> on;
  smg::for_each_term(ro, [&](const char* name, bool is_on, const auto&) {
    if (is_on) on.emplace_back(name);
  });
  smg::RegularizerResult<double>::each_energy(
      [&](const char* name, double e) {
        const std::string n = name;
        if (n != "carap" && n != "arap" && std::find(on.begin(), on.end(), n) != on.end())
          s += format("  %s %.3e", name, e);
      },
      l.energy);
  return s;
}

}  // namespace

smg::RegularizerOptions NodeObjective::regularizer_options(int T, int N, double scale) const {
  // The settings hold every term's options with its weight per node and frame; here only what
  // depends on the variant and on T and N is decided, the same way for every term, so that a new
  // term of the fused step reaches stage 1 through its flag alone.
  smg::RegularizerOptions ro = options_.regularizers;
  const double per_node_frame = 1.0 / (static_cast<double>(T) * N);
  smg::for_each_term(ro, [&](const char* name, bool& on, auto& o) {
    using O = std::decay_t<decltype(o)>;
    if constexpr (has_weight<O>::value) {
      // Normalised per node and frame; a term over temporal gaps (the rigidity) per node and
      // weighted frame pair, Σ_δ γ_δ (T − δ).
      if constexpr (has_gaps<O>::value) {
        double frames_gaps = 0;
        for (const smg::Gap& g : o.gaps) frames_gaps += g.weight * std::max(0, T - g.delta);
        o.weight = frames_gaps > 0 ? o.weight / (N * frames_gaps) * scale : 0.0;
      } else {
        o.weight = o.weight * per_node_frame * scale;
      }
      if (!variant_term(name)) on = o.weight > 0;
    }
  });
  ro.terms.confidence = false;  // the trainer's own (update_confidences), passed as the caller's
  // The variant's rungs; the directed reading of C-ARAP is configured in `carap` but run apart.
  ro.terms.carap = variant_.rigidity == Rigidity::carap && !directed_carap();
  ro.terms.arap = variant_.rigidity == Rigidity::arap;
  ro.terms.lrm = variant_.lrm;
  return ro;
}

Stage1Result fit_nodes(Nodes& n, NodeObjective& obj, const Stage1Options& o, const Progress& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  const int T = n.frames, N = n.count;
  Stage1Result r;
  obj.update_confidences(n);
  r.initial = obj.evaluate(n);
  Adam<double> adam_x(sz(T) * N * 3, o.lr_position), adam_q(sz(T) * N * 3, o.lr_rotation);
  std::vector<double> gx(sz(T) * N * 3), gq(sz(T) * N * 3);
  const bool rotations_matter = obj.variant().rigidity != Rigidity::none;
  NodeLossTerms last = r.initial;
  const smg::RegularizerOptions on = obj.regularizer_options(T, N);  // the log names the terms that are on
  for (int it = 0; it < o.iterations; ++it) {
    if (o.confidence_every > 0 && it > 0 && it % o.confidence_every == 0) obj.update_confidences(n);
    std::fill(gx.begin(), gx.end(), 0.0);
    std::fill(gq.begin(), gq.end(), 0.0);
    last = obj.evaluate(n, 1.0, gx.data(), gq.data());
    const double p = o.iterations > 1 ? static_cast<double>(it) / (o.iterations - 1) : 1.0;
    adam_x.set_lr(log_lerp(o.lr_position, o.lr_position_final, p));
    adam_q.set_lr(log_lerp(o.lr_rotation, o.lr_rotation_final, p));
    adam_x.step(n.positions.data(), gx.data());
    if (rotations_matter) adam_q.step_rotations(n.rotations.data(), gq.data());
    if (o.log_every > 0 && (it % o.log_every == 0 || it + 1 == o.iterations))
      progress.line("stage1",
                    format("it %4d/%d  loss %.4e  (", it + 1, o.iterations, last.total()) + terms_line(last, on) + ")");
  }
  obj.update_confidences(n);
  r.final = obj.evaluate(n);
  r.iterations = o.iterations;
  r.seconds = seconds_since(t0);
  return r;
}

}  // namespace trainer
