// examples/trainer/pipeline.cpp — the trainer's stages in order (pipeline.hpp).
#include "trainer/pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "trainer/frames.hpp"

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

void resolve_frames(TrainerConfig& c) {
  const int T = c.dataset.scene.frames;
  if (c.init.static_frames.empty()) c.init.static_frames = spread_frames(T, 4);
  if (c.init.dynamic_frames.empty()) c.init.dynamic_frames = spread_frames(T, 8);
}

TrainerResult run_stage0(const TrainerConfig& config_in, const Progress& progress) {
  TrainerConfig config = config_in;
  resolve_frames(config);
  const smg::ParallelOptions par{config.threads, 0};
  TrainerResult r;

  auto t0 = std::chrono::steady_clock::now();
  r.data = make_dataset(config.dataset, par);
  r.seconds_dataset = seconds_since(t0);
  const Scene& scene = r.data.scene;
  progress.line("data", format("scene seed %llu: T=%d %dx%d, %d tracks, extent %.3f m (%.1fs)",
                               static_cast<unsigned long long>(scene.config.seed), scene.frames(), scene.width(),
                               scene.height(), r.data.priors.tracks.count, scene.extent, r.seconds_dataset));

  // Stage 0: lifting, nodes, graph, rotations.
  t0 = std::chrono::steady_clock::now();
  r.lifted = lift_tracks(scene, r.data.priors, config.lift);
  r.nodes = make_nodes(r.lifted, config.nodes, config.variant.semantic_graph, par);
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
  r.tracks_lifted = track_metrics(scene, r.nodes);
  return r;
}

TrainerResult run_trainer(const TrainerConfig& config_in, const Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  TrainerConfig config = config_in;
  resolve_frames(config);
  const smg::ParallelOptions par{config.threads, 0};
  TrainerResult r = run_stage0(config, progress);
  const Scene& scene = r.data.scene;

  // Stage 1.
  NodeObjective objective(config.variant, config.node_loss, par);
  r.stage1 = fit_nodes(r.nodes, objective, config.stage1, progress);
  r.tracks_stage1 = track_metrics(scene, r.nodes);
  progress.line("stage1", format("done in %.1fs: node EPE %.4f m (lifted %.4f), box %.4f, hidden %.4f",
                                 r.stage1.seconds, r.tracks_stage1.all.epe, r.tracks_lifted.all.epe,
                                 r.tracks_stage1.box.epe, r.tracks_stage1.hidden.epe));

  // Stage 2.
  auto t0 = std::chrono::steady_clock::now();
  r.model = init_model<float>(r.data, r.nodes, config.init, par);
  progress.line("stage2", format("init: %d Gaussians (%d static, %d dynamic, %d drivers each) in %.2fs", r.model.count(),
                                 r.model.fixed, r.model.dynamic(), r.model.skin.width, seconds_since(t0)));
  Stage2Options s2 = config.stage2;
  s2.seed = scene.config.seed;
  r.stage2 = train_gaussians(r.data, r.nodes, objective, r.model, s2, progress, par);
  progress.line("stage2", format("done in %.1fs (%.1f ms per iteration)", r.stage2.seconds,
                                 1e3 * r.stage2.seconds / std::max(1, r.stage2.iterations)));

  // Evaluation.
  r.evaluation = evaluate(r.data, r.nodes, r.model, par, &r.renders);
  const Evaluation& e = r.evaluation;
  progress.line("eval", format("test PSNR %.2f dB (masked %.2f), SSIM %.4f, box PSNR %.2f; node EPE %.4f m, "
                               "d5 %.3f, d10 %.3f, box EPE %.4f (%.1fs)",
                               e.mean.psnr, e.mean.psnr_masked, e.mean.ssim, e.mean.psnr_box, e.tracks.all.epe,
                               e.tracks.all.within_5, e.tracks.all.within_10, e.tracks.box.epe, e.seconds));
  r.seconds_total = seconds_since(start);
  return r;
}

}  // namespace trainer
