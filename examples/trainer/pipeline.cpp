// examples/trainer/pipeline.cpp — the trainer's stages in order (pipeline.hpp).
#include "trainer/pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "trainer/data_export.hpp"
#include "trainer/frames.hpp"
#include "trainer/util.hpp"

namespace trainer {

TrainerConfig default_config(bool quick) {
  TrainerConfig c;
  if (quick) {
    c.dataset.scene.frames = 16;
    c.dataset.scene.width = 96;
    c.dataset.scene.height = 72;
    c.dataset.priors.tracks = 500;
    c.stage1.iterations = 500;
    c.stage1.log_every = 50;
    c.stage2.iterations = 300;
    c.stage2.prune_from = 100;
    c.stage2.prune_every = 100;
    c.stage2.prune_tail = 50;
    c.stage2.log_every = 50;
  }
  return c;
}

void resolve_frames(TrainerConfig& c) { resolve_frames(c, c.dataset.scene.frames, {}); }

void resolve_frames(TrainerConfig& c, int T, const std::vector<std::uint8_t>& has_mask) {
  std::vector<int> masked;
  for (int t = 0; t < T; ++t)
    if (has_mask.empty() || has_mask[static_cast<std::size_t>(t)]) masked.push_back(t);
  const auto pick = [&](int n) {
    std::vector<int> out;
    for (int i : spread_frames(static_cast<int>(masked.size()), n)) out.push_back(masked[static_cast<std::size_t>(i)]);
    return out;
  };
  if (c.init.static_frames.empty()) c.init.static_frames = pick(4);
  if (c.init.dynamic_frames.empty()) c.init.dynamic_frames = pick(8);
}

void scale_lengths(TrainerConfig& c, double f) {
  c.nodes.unit *= f;
  c.node_loss.data_huber *= f;
  c.node_loss.regularizers.lrm.huber_delta *= f;
  c.node_loss.regularizers.confidence.eps *= f;
  c.stage1.lr_position *= f;
  c.stage1.lr_position_final *= f;
  c.stage2.lr_means *= f;
  c.stage2.lr_means_final *= f;
  c.stage2.lr_node_position *= f;
  c.stage2.lr_node_position_final *= f;
  c.stage2.prune_scale *= f;
}

TrainerResult run_stage0(const TrainerConfig& config, const Progress& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  Dataset data = make_dataset(config.dataset, smg::ParallelOptions{config.threads, 0});
  const double seconds = seconds_since(t0);
  progress.line("data", format("scene seed %llu: T=%d %dx%d, %d tracks, extent %.3f m (%.1fs)",
                               static_cast<unsigned long long>(data.seed), data.frames(), data.width, data.height,
                               data.priors.tracks.count, data.extent, seconds));
  TrainerResult r = run_stage0(config, std::move(data), progress);
  r.seconds_dataset = seconds;
  return r;
}

SceneSignals scene_signals(const Nodes& n, const std::vector<double>& c) {
  const int T = n.frames, N = n.count;
  if (c.size() != sz(T) * N || n.visible.size() != sz(T) * N)
    throw std::invalid_argument("scene_signals: confidence and visibility must be [T][N]");
  long long observed = 0, low = 0, flips = 0;
  for (int t = 0; t < T; ++t)
    for (int i = 0; i < N; ++i) {
      const std::size_t k = sz(t) * N + i;
      if (n.visible[k]) {
        ++observed;
        low += c[k] < 0.3;
      }
      if (t > 0) flips += (n.visible[k] != 0) != (n.visible[k - sz(N)] != 0);
    }
  SceneSignals s;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  s.observed = T * N > 0 ? static_cast<double>(observed) / (static_cast<double>(T) * N) : nan;
  s.low_confidence = observed > 0 ? static_cast<double>(low) / static_cast<double>(observed) : nan;
  s.visibility_flips = T > 1 && N > 0 ? static_cast<double>(flips) / (static_cast<double>(T - 1) * N) : nan;
  return s;
}

namespace {

// What only the procedural scene's truth can say, for the confidence diagnostics
// (confidence_diagnostics): each node's semantic class and which of its samples are failed
// tracker reports.
void label_nodes_from_truth(const Dataset& d, const LiftedTracks& lifted, Nodes& nodes) {
  const Scene& scene = d.truth->scene;
  const Tracks& tr = d.priors.tracks;
  const int T = nodes.frames, N = nodes.count;
  nodes.semantic_class.resize(sz(N));
  nodes.failed_report.assign(sz(T) * N, 0);
  for (int i = 0; i < N; ++i) {
    nodes.semantic_class[sz(i)] = scene.bodies[sz(nodes.body[sz(i)])].semantic_class;
    const int track = lifted.track[sz(nodes.track[sz(i)])];
    for (int t = 0; t < T; ++t) {
      const SampleKind k = tr.kind[sz(t) * tr.count + track];
      nodes.failed_report[sz(t) * N + i] = k == SampleKind::outlier || k == SampleKind::occluded_reported ||
                                           k == SampleKind::stuck || k == SampleKind::switched;
    }
  }
}

}  // namespace

TrainerResult run_stage0(const TrainerConfig& config_in, Dataset data, const Progress& progress) {
  TrainerResult r;
  r.config = config_in;
  TrainerConfig& config = r.config;
  r.data = std::move(data);
  Dataset& d = r.data;
  const bool truth = d.truth.has_value();
  const smg::ParallelOptions par{config.threads, 0};
  auto t0 = std::chrono::steady_clock::now();
  // Stage 0: lifting, nodes, graph, rotations. Lifting depends on no length of the configuration.
  resolve_frames(config, d.frames(), d.priors.has_mask);
  r.lifted = lift_tracks(d.cameras, d.priors, config.lift);
  // Without feature maps there are no descriptors: the graph is geometric (train.cpp says so).
  if (d.priors.feature_dim == 0) config.variant.semantic_graph = false;
  const auto select_nodes = [&] { return make_nodes(r.lifted, config.nodes, config.variant.semantic_graph, par); };
  if (truth) {
    r.nodes = select_nodes();
    // What only the truth can say of stage 0 (the node labels take no part in training; the
    // error of the lifted trajectories reads no rotation).
    label_nodes_from_truth(d, r.lifted, r.nodes);
    r.tracks_lifted = track_metrics(d.truth->scene, r.nodes);
    r.queries = export_query_set(d, kQueryCount);
  } else {
    // A scene from disk: its scale decides every length (docs/data.md section 5). Too little
    // usable data is a problem of the scene's files (exit 2 in smg_trainer), named by the files
    // that decide it.
    const double extent = lifted_extent(r.lifted);
    if (!(extent > 0))
      throw DataError("priors/tracks.npz, priors/masks, depth/2x: too few lifted object tracks to measure the "
                      "scene's extent (fewer than 16 visible samples with depth > 0 of tracks whose query pixel "
                      "is in a dynamic mask)");
    d.extent = extent;
    r.length_factor = extent / kReferenceExtent;
    scale_lengths(config, r.length_factor);
    progress.line("data", format("%s: T=%d %dx%d, %d tracks, %d validation frames, extent %.3f m (lengths x %.3f)",
                                 d.source.c_str(), d.frames(), d.width, d.height, d.priors.tracks.count,
                                 static_cast<int>(d.eval.size()), extent, r.length_factor));
    try {
      r.nodes = select_nodes();
    } catch (const std::runtime_error& e) {
      // No node (no track visible in enough frames): on disk that is the scene's problem, not the
      // program's.
      throw DataError("priors/tracks.npz: " + std::string(e.what()));
    }
  }
  init_rotations(r.nodes);
  r.seconds_stage0 = seconds_since(t0);
  {
    const smg::GraphStats& gs = r.nodes.graph.stats;
    progress.line("stage0", format("%d lifted object tracks -> %d nodes (unit %.3f m); %s graph: %lld edges, "
                                   "mean degree %.1f, %lld removed by the gate, %lld isolated (%.2fs)",
                                   r.lifted.count, r.nodes.count, r.nodes.unit,
                                   config.variant.semantic_graph ? "semantic" : "geometric",
                                   static_cast<long long>(gs.edges), gs.mean_degree,
                                   static_cast<long long>(gs.gate_removed_edges),
                                   static_cast<long long>(gs.isolated_nodes), r.seconds_stage0));
  }
  return r;
}

namespace {

void log_queries(const Progress& progress, const char* stage, int count, const QueryScore& s) {
  if (!s.scored) return;
  std::string line = format("%d query tracks: EPE %.4f m, within 5 cm %.3f, within 10 cm %.3f", count, s.all.epe,
                            s.all.within_5cm, s.all.within_10cm);
  if (s.visible.samples + s.hidden.samples > 0)
    line += format(" (visible %.4f, hidden %.4f)", s.visible.epe, s.hidden.epe);
  progress.line(stage, line);
}

// Stages 1 and 2 and the evaluation, after run_stage0.
TrainerResult run_stages(TrainerResult r, std::chrono::steady_clock::time_point start, const Progress& progress) {
  const smg::ParallelOptions par{r.config.threads, 0};
  const bool truth = r.data.truth.has_value();
  // What the run sees of its scene before stage 1, without truth (metrics.json: signals).
  const std::vector<double> c_lifted =
      node_confidences(r.nodes, r.nodes.positions, r.config.node_loss.regularizers.confidence, par);
  r.signals = scene_signals(r.nodes, c_lifted);
  const TrainerConfig& config = r.config;

  // Stage 1. What the truth can say of it is scored below, once the query tracks are known.
  NodeObjective objective(config.variant, config.node_loss, par);
  const std::vector<double> lifted = r.nodes.positions;  // stage 1's start, for the diagnostics
  r.stage1 = fit_nodes(r.nodes, objective, config.stage1, progress);
  progress.line("stage1", format("done in %.1fs", r.stage1.seconds));

  // Stage 2.
  auto t0 = std::chrono::steady_clock::now();
  r.model = init_model<float>(r.data, r.nodes, config.init, par);
  progress.line("stage2", format("init: %d Gaussians (%d static, %d dynamic, %d drivers each) in %.2fs", r.model.count(),
                                 r.model.fixed, r.model.dynamic(), r.model.skin.width, seconds_since(t0)));
  if (r.queries) {
    r.query_stage1 = score_queries(*r.queries, r.data, r.nodes, r.model, par);
    log_queries(progress, "stage1", r.queries->queries.count(), r.query_stage1);
  }
  // Stage 1 against the truth, in one place: what the confidences measure of the lifted
  // trajectories and of stage 1's, the node EPE, and its split by what explains it.
  if (truth) {
    const Scene& scene = r.data.truth->scene;
    const smg::RegularizerOptions& ro = config.node_loss.regularizers;
    r.confidence_lifted = confidence_diagnostics(r.nodes, lifted, ro.confidence, ro.carap.alpha, par);
    r.confidence_stage1 = confidence_diagnostics(r.nodes, r.nodes.positions, ro.confidence, ro.carap.alpha, par);
    r.tracks_stage1 = track_metrics(scene, r.nodes);
    progress.line("stage1", format("node EPE %.4f m (lifted %.4f), box %.4f, hidden %.4f", r.tracks_stage1.all.epe,
                                   r.tracks_lifted.all.epe, r.tracks_stage1.box.epe, r.tracks_stage1.hidden.epe));
    if (r.query_stage1.scored)
      r.node_split_stage1 = node_error_split(scene, r.nodes, c_lifted, r.query_stage1.node_weight);
  }
  Stage2Options s2 = config.stage2;
  s2.seed = r.data.seed;
  r.stage2 = train_gaussians(r.data, r.nodes, objective, r.model, s2, progress, par);
  progress.line("stage2", format("done in %.1fs (%.1f ms per iteration)", r.stage2.seconds,
                                 1e3 * r.stage2.seconds / std::max(1, r.stage2.iterations)));

  // Evaluation.
  if (config.image_eval) r.evaluation = evaluate(r.data, r.nodes, r.model, par, /*keep_renders=*/true);
  const Evaluation& e = r.evaluation;
  if (!e.frames.empty()) {
    const FrameScore& m = e.frames_mean;
    progress.line("eval", format("%d validation frames: mPSNR %.2f dB, mSSIM %.4f (covisible %.4f), PSNR %.2f dB (%.1fs)",
                                 static_cast<int>(e.frames.size()), m.mpsnr, m.mssim, m.mssim_covisible, m.psnr,
                                 e.seconds));
  }
  if (r.queries) {
    r.query_stage2 = score_queries(*r.queries, r.data, r.nodes, r.model, par);
    log_queries(progress, "eval", r.queries->queries.count(), r.query_stage2);
  }
  // The run against the truth: the node error after stage 2 (evaluate() scores it with the
  // images; without them it is scored here) and the test views.
  if (truth) {
    if (!config.image_eval) {
      r.evaluation.tracks = track_metrics(r.data.truth->scene, r.nodes);
    } else {
      progress.line("eval", format("test PSNR %.2f dB (masked %.2f), SSIM %.4f, box PSNR %.2f; node EPE %.4f m, "
                                   "d5 %.3f, d10 %.3f, box EPE %.4f (%.1fs)",
                                   e.mean.psnr, e.mean.psnr_masked, e.mean.ssim, e.mean.psnr_box, e.tracks.all.epe,
                                   e.tracks.all.within_5, e.tracks.all.within_10, e.tracks.box.epe, e.seconds));
    }
  }
  r.seconds_total = seconds_since(start);
  return r;
}

}  // namespace

TrainerResult run_trainer(const TrainerConfig& config, const Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  TrainerResult r = run_stage0(config, progress);
  return run_stages(std::move(r), start, progress);
}

TrainerResult run_trainer(const TrainerConfig& config, Dataset data, const Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  TrainerResult r = run_stage0(config, std::move(data), progress);
  return run_stages(std::move(r), start, progress);
}

TrainerResult run_trainer(TrainerResult stage0, const Progress& progress) {
  // seconds_total counts from the start of stage 0, as in the one-call forms.
  const auto start = std::chrono::steady_clock::now() -
                     std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                         std::chrono::duration<double>(stage0.seconds_stage0));
  return run_stages(std::move(stage0), start, progress);
}

}  // namespace trainer
