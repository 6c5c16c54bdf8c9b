// Stage 0 + stage 1 on the real quick scene (default_config(true)): stage 1 with the full
// variant lowers the node tracking error below the lifted one; the base variant (data term only)
// leaves observed samples at their lifted value; results are bit-identical for any thread count.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <utility>
#include <vector>

#include "trainer/evaluate.hpp"
#include "trainer/nodes.hpp"
#include "trainer/pipeline.hpp"

namespace {

struct QuickStage0 {
  trainer::TrainerConfig config;
  trainer::Dataset data;
  trainer::LiftedTracks lifted;
};

// The quick scene and its lifted tracks, built once per process (make_dataset is the slow part).
const QuickStage0& quick() {
  static const QuickStage0 q = [] {
    QuickStage0 s;
    s.config = trainer::default_config(true);
    trainer::resolve_frames(s.config);
    s.data = trainer::make_dataset(s.config.dataset, smg::ParallelOptions{2, 0});
    s.lifted = trainer::lift_tracks(s.data.cameras, s.data.priors, s.config.lift);
    return s;
  }();
  return q;
}

// Stage 1's starting point: the nodes of the lifted tracks (with or without the semantic graph),
// their rotations initialised.
trainer::Nodes initial_nodes(const QuickStage0& q, bool semantic_graph, const smg::ParallelOptions& par) {
  trainer::Nodes nodes = trainer::make_nodes(q.lifted, q.config.nodes, semantic_graph, par);
  trainer::init_rotations(nodes);
  return nodes;
}

const trainer::Progress& stage1_silent() {
  static const trainer::Progress p(nullptr, true);
  return p;
}

}  // namespace

TEST_CASE("stage 1 (full variant, quick scene): node EPE below the lifted EPE") {
  const QuickStage0& q = quick();
  const trainer::TrainerConfig& c = q.config;
  REQUIRE(c.variant.variant == trainer::Variant::full);
  const smg::ParallelOptions par{2, 0};
  trainer::Nodes nodes = initial_nodes(q, c.variant.semantic_graph, par);
  REQUIRE(nodes.count > 10);
  const trainer::TrackMetrics lifted = trainer::track_metrics(q.data.truth->scene, nodes);
  trainer::NodeObjective objective(c.variant, c.node_loss, par);
  const trainer::Stage1Result r = trainer::fit_nodes(nodes, objective, c.stage1, stage1_silent());
  const trainer::TrackMetrics fitted = trainer::track_metrics(q.data.truth->scene, nodes);
  CAPTURE(nodes.count);
  CAPTURE(lifted.all.epe);
  CAPTURE(fitted.all.epe);
  CAPTURE(lifted.hidden.epe);
  CAPTURE(fitted.hidden.epe);
  CAPTURE(r.initial.total());
  CAPTURE(r.final.total());
  MESSAGE("quick scene, full variant: " << nodes.count << " nodes, node EPE lifted " << lifted.all.epe
                                        << " m -> stage 1 " << fitted.all.epe << " m (hidden " << lifted.hidden.epe
                                        << " -> " << fitted.hidden.epe << ")");
  CHECK(r.iterations == c.stage1.iterations);
  CHECK(std::isfinite(fitted.all.epe));
  CHECK(fitted.all.samples == lifted.all.samples);
  CHECK(fitted.all.epe < lifted.all.epe);
  CHECK(r.final.total() < r.initial.total());
  CHECK(r.final.rigidity() > 0);
  CHECK(r.final.energy.lrm > 0);
  for (std::size_t s = 0; s < nodes.rotations.size() / 4; ++s) {
    const double norm = std::sqrt(nodes.rotations[4 * s] * nodes.rotations[4 * s] +
                                  nodes.rotations[4 * s + 1] * nodes.rotations[4 * s + 1] +
                                  nodes.rotations[4 * s + 2] * nodes.rotations[4 * s + 2] +
                                  nodes.rotations[4 * s + 3] * nodes.rotations[4 * s + 3]);
    if (std::abs(norm - 1.0) > 1e-12) {
      CHECK(norm == doctest::Approx(1.0).epsilon(1e-12));
      break;
    }
  }
}

TEST_CASE("stage 1 (base variant): observed samples stay at their lifted value") {
  const QuickStage0& q = quick();
  trainer::TrainerConfig c = q.config;
  REQUIRE(trainer::parse_variant("base", &c.variant));
  const smg::ParallelOptions par{2, 0};
  trainer::Nodes nodes = initial_nodes(q, c.variant.semantic_graph, par);
  const trainer::TrackMetrics lifted = trainer::track_metrics(q.data.truth->scene, nodes);
  const std::vector<double> start = nodes.positions;
  trainer::Stage1Options s1 = c.stage1;
  s1.iterations = 100;
  trainer::NodeObjective objective(c.variant, c.node_loss, par);
  const trainer::Stage1Result r = trainer::fit_nodes(nodes, objective, s1, stage1_silent());
  CHECK(r.final.rigidity() == 0.0);
  CHECK(r.final.energy.lrm == 0.0);
  double worst = 0;
  long long observed = 0;
  for (std::size_t s = 0; s < nodes.visible.size(); ++s) {
    if (!nodes.visible[s]) continue;
    ++observed;
    for (int k = 0; k < 3; ++k) worst = std::max(worst, std::abs(nodes.positions[3 * s + k] - nodes.observed[3 * s + k]));
  }
  CAPTURE(worst);
  CHECK(observed > 0);
  CHECK(worst < 1e-9);
  const trainer::TrackMetrics fitted = trainer::track_metrics(q.data.truth->scene, nodes);
  CHECK(fitted.all.epe == doctest::Approx(lifted.all.epe).epsilon(1e-9));
}

TEST_CASE("stage 0 + stage 1 are bit-identical for 1, 2 and 7 threads") {
  const QuickStage0& q = quick();
  const trainer::TrainerConfig& c = q.config;
  trainer::Stage1Options s1 = c.stage1;
  s1.iterations = 30;
  s1.confidence_every = 10;  // confidences recomputed during the run too
  std::vector<std::vector<double>> positions, rotations;
  std::vector<std::vector<std::int32_t>> graphs;
  for (int threads : {1, 2, 7}) {
    const smg::ParallelOptions par{threads, 0};
    trainer::Nodes nodes = initial_nodes(q, c.variant.semantic_graph, par);
    trainer::NodeObjective objective(c.variant, c.node_loss, par);
    trainer::fit_nodes(nodes, objective, s1, stage1_silent());
    positions.push_back(nodes.positions);
    rotations.push_back(nodes.rotations);
    graphs.push_back(nodes.graph.indices);
  }
  for (std::size_t k = 1; k < positions.size(); ++k) {
    CAPTURE(k);
    CHECK(graphs[k] == graphs[0]);
    CHECK(positions[k] == positions[0]);  // exact equality: bitwise for finite doubles
    CHECK(rotations[k] == rotations[0]);
  }
  // The run moved the nodes (otherwise equality would be trivial).
  trainer::Nodes start = trainer::make_nodes(q.lifted, c.nodes, c.variant.semantic_graph, {1, 0});
  CHECK(start.positions != positions[0]);
}

TEST_CASE("C-ARAP options: the directed reading keeps the energy and rotation gradient, changes the positions'") {
  const QuickStage0& q = quick();
  const smg::ParallelOptions par{2, 0};
  trainer::Nodes nodes = initial_nodes(q, true, par);
  const trainer::VariantSpec no_lrm = trainer::variant_spec(trainer::Variant::no_lrm);
  trainer::NodeLossOptions o = q.config.node_loss;
  trainer::NodeObjective sym(no_lrm, o, par);
  o.carap_reading = trainer::CarapReading::directed;
  trainer::NodeObjective dir(no_lrm, o, par);
  const std::size_t n = nodes.positions.size();
  std::vector<double> gx_s(n, 0.0), gr_s(n, 0.0), gx_d(n, 0.0), gr_d(n, 0.0);
  const trainer::NodeLossTerms es = sym.evaluate(nodes, 1.0, gx_s.data(), gr_s.data());
  const trainer::NodeLossTerms ed = dir.evaluate(nodes, 1.0, gx_d.data(), gr_d.data());
  CHECK(ed.rigidity() == doctest::Approx(es.rigidity()).epsilon(1e-12));
  CHECK(ed.data == es.data);
  double dr = 0, nr = 0, dx = 0, nx = 0;
  for (std::size_t k = 0; k < n; ++k) {
    dr += (gr_d[k] - gr_s[k]) * (gr_d[k] - gr_s[k]);
    nr += gr_s[k] * gr_s[k];
    dx += (gx_d[k] - gx_s[k]) * (gx_d[k] - gx_s[k]);
    nx += gx_s[k] * gx_s[k];
  }
  CHECK(std::sqrt(dr / nr) < 1e-10);
  CHECK(std::sqrt(dx / nx) > 1e-3);
}

TEST_CASE("C-ARAP options: confidences from the estimate follow it, from the lifted trajectories or the truth they do not") {
  const QuickStage0& q = quick();
  const trainer::TrainerConfig& c = q.config;
  const smg::ParallelOptions par{2, 0};
  trainer::Nodes nodes = initial_nodes(q, true, par);
  const trainer::VariantSpec full = trainer::variant_spec(trainer::Variant::full);
  const auto confidences_before_after = [&](trainer::ConfidenceSource source) {
    trainer::Nodes n = nodes;
    trainer::NodeLossOptions o = c.node_loss;
    o.confidence_source = source;
    trainer::NodeObjective obj(full, o, par);
    obj.update_confidences(n);
    const std::vector<double> before = obj.confidences();
    for (std::size_t k = 0; k < n.positions.size(); ++k) n.positions[k] += 0.02 * std::sin(0.37 * static_cast<double>(k));
    obj.update_confidences(n);
    return std::pair{before, obj.confidences()};
  };
  const auto [est0, est1] = confidences_before_after(trainer::ConfidenceSource::estimate);
  const auto [lift0, lift1] = confidences_before_after(trainer::ConfidenceSource::lifted);
  const auto [tru0, tru1] = confidences_before_after(trainer::ConfidenceSource::truth);
  CHECK(est0 == lift0);  // the lifted trajectories are the estimate at the first update
  CHECK(est0 != est1);
  CHECK(lift0 == lift1);
  CHECK(tru0 == tru1);
  CHECK(tru0 == trainer::node_confidences(nodes, nodes.truth, c.node_loss.regularizers.confidence, par));
  // Without the visibility factor: the same value where observed, the motion factors elsewhere.
  const std::vector<double> all =
      trainer::node_confidences(nodes, nodes.positions, c.node_loss.regularizers.confidence, par, false);
  long long hidden_positive = 0;
  for (std::size_t s = 0; s < all.size(); ++s) {
    if (nodes.visible[s]) {
      CHECK(all[s] == est0[s]);
    } else {
      CHECK(est0[s] == 0.0);
      hidden_positive += all[s] > 0.0;
    }
  }
  CHECK(hidden_positive > 0);
  // Without ground truth (a scene from disk) the oracle is refused.
  trainer::Nodes blind = nodes;
  blind.truth.clear();
  trainer::NodeLossOptions o = c.node_loss;
  o.confidence_source = trainer::ConfidenceSource::truth;
  trainer::NodeObjective obj(full, o, par);
  CHECK_THROWS_WITH_AS(obj.update_confidences(blind), doctest::Contains("ground truth"), std::invalid_argument);
}

TEST_CASE("confidence diagnostics: rank correlations, bins and the weight ratios of both readings") {
  const QuickStage0& q = quick();
  const trainer::TrainerConfig& c = q.config;
  const smg::ParallelOptions par{2, 0};
  trainer::Nodes nodes = trainer::make_nodes(q.lifted, c.nodes, true, par);
  const trainer::ConfidenceDiagnostics d =
      trainer::confidence_diagnostics(nodes, nodes.positions, c.node_loss.regularizers.confidence, 0.6, par);
  long long observed = 0;
  for (std::uint8_t v : nodes.visible) observed += v;
  long long binned = 0;
  for (long long k : d.count_by_observation_error) binned += k;
  CHECK(binned == observed);
  CHECK(d.spearman_error >= -1.0);
  CHECK(d.spearman_error <= 1.0);
  CHECK(d.low_fraction > 0.0);
  // Every weight ratio lies in [alpha, 1]; the symmetric reading weakens low-confidence samples
  // more than high-confidence ones (their incoming terms carry their own c).
  for (double r : {d.symmetric_low, d.symmetric_high, d.directed_low, d.directed_high}) {
    CHECK(r >= 0.6 - 1e-12);
    CHECK(r <= 1.0 + 1e-12);
  }
  CHECK(d.symmetric_low < d.symmetric_high);
  // With alpha = 1 every ratio is 1; the estimate at the truth has zero error everywhere.
  const trainer::ConfidenceDiagnostics one =
      trainer::confidence_diagnostics(nodes, nodes.positions, c.node_loss.regularizers.confidence, 1.0, par);
  CHECK(one.symmetric_low == doctest::Approx(1.0));
  CHECK(one.directed_high == doctest::Approx(1.0));
  // Observations equal to the truth all fall in the first bin.
  trainer::Nodes exact = nodes;
  exact.observed = exact.truth;
  const trainer::ConfidenceDiagnostics e =
      trainer::confidence_diagnostics(exact, exact.truth, c.node_loss.regularizers.confidence, 0.6, par);
  CHECK(e.count_by_observation_error[0] == observed);
  // At the truth, the estimate's and the truth's confidences coincide.
  CHECK(e.mean_observed == e.mean_observed_truth);
  CHECK(e.low_observed == e.low_observed_truth);
  CHECK(e.mean_observed > 0.0);
  CHECK(e.mean_observed < 1.0);
  // Failed reports and bending edges: absent inputs give zeros; with every observed sample
  // marked failed the failed mean is the observed mean; with one class, every edge between two
  // bodies counts as bending and the two edge means, weighted by their counts, give the mean of
  // c_j over all edges.
  CHECK(d.count_failed_observed == 0);
  CHECK(d.count_edge_bending == 0);
  trainer::Nodes marked = nodes;
  marked.failed_report.assign(marked.visible.size(), 1);
  marked.semantic_class.assign(static_cast<std::size_t>(marked.count), 0);
  const trainer::ConfidenceDiagnostics m =
      trainer::confidence_diagnostics(marked, marked.positions, c.node_loss.regularizers.confidence, 0.6, par);
  CHECK(m.count_failed_observed == observed);
  CHECK(m.failed_observed == doctest::Approx(d.mean_observed).epsilon(1e-12));
  CHECK(m.clean_observed == 0.0);
  long long edges = 0, between = 0;
  const int K = marked.graph.k;
  for (int i = 0; i < marked.count; ++i)
    for (int k = 0; k < K; ++k) {
      const int j = marked.graph.indices[static_cast<std::size_t>(i) * K + k];
      if (j < 0) break;
      ++edges;
      between += marked.body[static_cast<std::size_t>(i)] != marked.body[static_cast<std::size_t>(j)];
    }
  REQUIRE(between > 0);
  CHECK(m.count_edge_bending == between);
  CHECK(m.edge_bending > 0.0);
  CHECK(m.edge_rigid > 0.0);
  CHECK(m.edge_bending <= 1.0);
}

// --stage2-unobserved hold (Stage2Options::hold_unobserved): no photometric gradient reaches a
// node's pose at the frames where its track is unobserved. With the nodes' objective off
// (node_weight 0) nothing else moves them, and Adam with a zero gradient steps by exactly 0, so
// those samples keep their stage-1 values; with move, some of them change.
TEST_CASE("stage 2 --stage2-unobserved hold: no photometric step at unobserved samples; move takes some") {
  const QuickStage0& q = quick();
  const trainer::TrainerConfig& c = q.config;
  const smg::ParallelOptions par{2, 0};
  const trainer::Nodes start = initial_nodes(q, c.variant.semantic_graph, par);
  long long unobserved = 0;
  for (const std::uint8_t v : start.visible) unobserved += v == 0 ? 1 : 0;
  REQUIRE(unobserved > 0);
  // Per sample: did stage 2 move the position or the rotation at that (t, i)?
  const auto moved = [&](bool hold) {
    trainer::Nodes nodes = start;
    trainer::NodeObjective objective(c.variant, c.node_loss, par);
    trainer::GaussianModel<float> model = trainer::init_model<float>(q.data, nodes, c.init, par);
    trainer::Stage2Options s2 = c.stage2;
    s2.iterations = 12;  // 12 of the 16 frames rendered: enough unobserved samples, cheap under the sanitizers
    s2.node_weight = 0.0;
    s2.hold_unobserved = hold;
    trainer::train_gaussians(q.data, nodes, objective, model, s2, stage1_silent(), par);
    std::vector<char> m(start.visible.size(), 0);
    // Positions bitwise; rotations to 1e-12, since Adam re-normalises every quaternion it steps
    // (a step of exactly 0 may still move the last bit).
    for (std::size_t s = 0; s < m.size(); ++s)
      for (std::size_t k = 0; k < 4; ++k)
        if ((k < 3 && nodes.positions[3 * s + k] != start.positions[3 * s + k]) ||
            std::abs(nodes.rotations[4 * s + k] - start.rotations[4 * s + k]) > 1e-12)
          m[s] = 1;
    return m;
  };
  const std::vector<char> held = moved(true), free = moved(false);
  long long held_unobserved = 0, free_unobserved = 0, held_observed = 0;
  for (std::size_t s = 0; s < held.size(); ++s) {
    if (start.visible[s] == 0) {
      held_unobserved += held[s];
      free_unobserved += free[s];
    } else {
      held_observed += held[s];
    }
  }
  CAPTURE(unobserved);
  CHECK(held_unobserved == 0);
  CHECK(free_unobserved > 0);
  CHECK(held_observed > 0);  // the photometric gradient still reaches the observed samples
}
