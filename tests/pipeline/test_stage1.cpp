// Stage 0 + stage 1 on the real quick scene (default_config(true)): stage 1 with the full
// variant lowers the node tracking error below the lifted one; the base variant (data term only)
// leaves observed samples at their lifted value; results are bit-identical for any thread count.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
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
    s.lifted = trainer::lift_tracks(s.data.scene, s.data.priors, s.config.lift);
    return s;
  }();
  return q;
}

const trainer::Progress& silent() {
  static const trainer::Progress p(nullptr, true);
  return p;
}

}  // namespace

TEST_CASE("stage 1 (full variant, quick scene): node EPE below the lifted EPE") {
  const QuickStage0& q = quick();
  const trainer::TrainerConfig& c = q.config;
  REQUIRE(c.variant.variant == trainer::Variant::full);
  const smg::ParallelOptions par{2, 0};
  trainer::Nodes nodes = trainer::make_nodes(q.lifted, c.nodes, c.variant.semantic_graph, par);
  trainer::init_rotations(nodes);
  REQUIRE(nodes.count > 10);
  const trainer::TrackMetrics lifted = trainer::track_metrics(q.data.scene, nodes);
  trainer::NodeObjective objective(c.variant, c.node_loss, par);
  const trainer::Stage1Result r = trainer::fit_nodes(nodes, objective, c.stage1, silent());
  const trainer::TrackMetrics fitted = trainer::track_metrics(q.data.scene, nodes);
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
  CHECK(r.final.rigidity > 0);
  CHECK(r.final.lrm > 0);
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
  trainer::Nodes nodes = trainer::make_nodes(q.lifted, c.nodes, c.variant.semantic_graph, par);
  trainer::init_rotations(nodes);
  const trainer::TrackMetrics lifted = trainer::track_metrics(q.data.scene, nodes);
  const std::vector<double> start = nodes.positions;
  trainer::Stage1Options s1 = c.stage1;
  s1.iterations = 100;
  trainer::NodeObjective objective(c.variant, c.node_loss, par);
  const trainer::Stage1Result r = trainer::fit_nodes(nodes, objective, s1, silent());
  CHECK(r.final.rigidity == 0.0);
  CHECK(r.final.lrm == 0.0);
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
  const trainer::TrackMetrics fitted = trainer::track_metrics(q.data.scene, nodes);
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
    trainer::Nodes nodes = trainer::make_nodes(q.lifted, c.nodes, c.variant.semantic_graph, par);
    trainer::init_rotations(nodes);
    trainer::NodeObjective objective(c.variant, c.node_loss, par);
    trainer::fit_nodes(nodes, objective, s1, silent());
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
