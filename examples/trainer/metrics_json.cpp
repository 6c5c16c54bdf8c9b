// examples/trainer/metrics_json.cpp — smg_trainer's metrics.json (metrics_json.hpp).
#include "trainer/metrics_json.hpp"

#include <filesystem>
#include <fstream>
#include <stdexcept>

#include <sys/resource.h>

#include "json_line.hpp"
#include "smg/core/parallel.hpp"
#include "trainer/util.hpp"

namespace trainer {

namespace {

std::string view_json(const ViewMetrics& v) {
  cli::JsonLine j;
  j.add("psnr", v.psnr)
      .add("ssim", v.ssim)
      .add("psnr_masked", v.psnr_masked)
      .add("ssim_masked", v.ssim_masked)
      .add("psnr_box", v.psnr_box)
      .add("psnr_objects", v.psnr_objects);
  return j.str();
}

// The C-ARAP settings (docs/trainer.md, "C-ARAP options").
void add_carap_settings(cli::JsonLine& j, const NodeLossOptions& nl) {
  j.add("alpha", nl.regularizers.carap.alpha)
      .add("carap_reading", carap_reading_names()[static_cast<std::size_t>(nl.carap_reading)])
      .add("confidence_from", confidence_source_names()[static_cast<std::size_t>(nl.confidence_source)])
      .add("confidence_visibility", nl.confidence_visibility);
}

// The stage-1 weights (--w-data, --w-rigidity, --w-lrm, --w-accel; case.json's w_*), each only
// when set to other than the trainer's default, as stage2_unobserved below: a default run's keys
// stay as they were, so the studies' canaries (scripts/ladder_report.py, check_cache), which
// compare every number of a default run's metrics.json with a record, still match.
void add_weights(cli::JsonLine& j, const NodeLossOptions& nl) {
  const NodeLossOptions defaults;
  const auto add = [&](const char* key, double value, double default_value) {
    if (value != default_value) j.add(key, value);
  };
  add("w_data", nl.data_weight, defaults.data_weight);
  add("w_rigidity", nl.regularizers.carap.weight, defaults.regularizers.carap.weight);
  add("w_lrm", nl.regularizers.lrm.weight, defaults.regularizers.lrm.weight);
  add("w_accel", nl.regularizers.accel.weight, defaults.regularizers.accel.weight);
}

void add_confidence(cli::JsonLine& j, const std::string& suffix, const ConfidenceDiagnostics& d) {
  j.add("conf_spearman_error" + suffix, d.spearman_error)
      .add("conf_spearman_observation" + suffix, d.spearman_observation)
      .add("conf_obs_err_below_3cm" + suffix, d.mean_by_observation_error[0])
      .add("conf_obs_err_3_10cm" + suffix, d.mean_by_observation_error[1])
      .add("conf_obs_err_10_30cm" + suffix, d.mean_by_observation_error[2])
      .add("conf_obs_err_above_30cm" + suffix, d.mean_by_observation_error[3])
      .add("conf_low_fraction" + suffix, d.low_fraction)
      .add("conf_mean_observed" + suffix, d.mean_observed)
      .add("conf_low_observed" + suffix, d.low_observed)
      .add("conf_mean_observed_truth" + suffix, d.mean_observed_truth)
      .add("conf_low_observed_truth" + suffix, d.low_observed_truth)
      .add("conf_weight_symmetric_low" + suffix, d.symmetric_low)
      .add("conf_weight_symmetric_high" + suffix, d.symmetric_high)
      .add("conf_weight_directed_low" + suffix, d.directed_low)
      .add("conf_weight_directed_high" + suffix, d.directed_high)
      .add("conf_failed_observed" + suffix, d.failed_observed)
      .add("conf_clean_observed" + suffix, d.clean_observed)
      .add("conf_failed_observed_count" + suffix, d.count_failed_observed)
      .add("conf_edge_bending" + suffix, d.edge_bending)
      .add("conf_edge_rigid" + suffix, d.edge_rigid)
      .add("conf_edge_bending_count" + suffix, d.count_edge_bending);
}

void add_tracks(cli::JsonLine& j, const std::string& suffix, const TrackMetrics& m) {
  j.add("epe" + suffix, m.all.epe)
      .add("delta_5" + suffix, m.all.within_5)
      .add("delta_10" + suffix, m.all.within_10)
      .add("epe_box" + suffix, m.box.epe)
      .add("epe_arm" + suffix, m.arm.epe)
      .add("epe_ball" + suffix, m.ball.epe)
      .add("epe_hidden" + suffix, m.hidden.epe)
      .add("epe_box_hidden" + suffix, m.box_hidden.epe);
}

std::string query_error_json(const QueryTrackError& e) {
  cli::JsonLine j;
  j.add("epe", e.epe).add("delta_5cm", e.within_5cm).add("delta_10cm", e.within_10cm).add("samples", e.samples);
  return j.str();
}

// epe_query.stage1 / .stage2 (docs/trainer.md, "Query tracks"): all samples, and where the
// query set knows them, by the semantic class under each query and split into truly visible and
// hidden samples.
std::string query_score_json(const QueryScore& s, const std::vector<std::string>& class_names) {
  cli::JsonLine j;
  j.add_raw("all", query_error_json(s.all));
  if (s.visible.samples + s.hidden.samples > 0)
    j.add_raw("visible", query_error_json(s.visible)).add_raw("hidden", query_error_json(s.hidden));
  if (!s.by_class.empty()) {
    cli::JsonLine c;
    for (const auto& [cls, e] : s.by_class)
      c.add_raw(cls >= 0 && sz(cls) < class_names.size() ? class_names[sz(cls)] : "class_" + std::to_string(cls),
                query_error_json(e));
    j.add_raw("by_class", c.str());
  }
  return j.str();
}

std::string tracking_error_json(const TrackingError& e) {
  cli::JsonLine j;
  j.add("epe", e.epe).add("samples", e.samples);
  return j.str();
}

std::string node_split_json(const NodeErrorSplit& s) {
  cli::JsonLine j;
  j.add_raw("failed", tracking_error_json(s.failed))
      .add_raw("clean", tracking_error_json(s.clean))
      .add_raw("conf_low", tracking_error_json(s.conf_low))
      .add_raw("conf_mid", tracking_error_json(s.conf_mid))
      .add_raw("conf_high", tracking_error_json(s.conf_high))
      .add_raw("driving", tracking_error_json(s.driving))
      .add_raw("idle", tracking_error_json(s.idle))
      .add("weighted_epe", s.weighted_epe);
  return j.str();
}

double peak_memory_mib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_maxrss) / 1024.0;  // Linux: KiB
}

// The keys only one kind of scene has, each group written at its place in the line: the
// procedural scene's (what its truth measures) or a scene from disk's (its validation frames,
// reading and writing). metrics_json picks the table once instead of testing for truth at every
// group, and the keys keep their order.
struct SceneKeys {
  void (*scene)(cli::JsonLine&, const TrainerResult&, const RunRecord&);        // after variant
  void (*images)(cli::JsonLine&, const TrainerResult&, const RunRecord&);       // after threads
  void (*evaluation)(cli::JsonLine&, const TrainerResult&, const RunRecord&);   // after the C-ARAP settings
  void (*node_split)(cli::JsonLine&, const TrainerResult&);                     // after epe_query
  void (*lengths)(cli::JsonLine&, const TrainerResult&);                        // after extent
  void (*read)(cli::JsonLine&, const TrainerResult&, const RunRecord&);         // before seconds_stage0
  void (*totals)(cli::JsonLine&, const TrainerResult&, const RunRecord&);       // after seconds_eval
};

// A group of keys that this kind of scene does not have.
void no_keys(cli::JsonLine&, const TrainerResult&) {}

const SceneKeys kProceduralKeys = {
    [](cli::JsonLine& j, const TrainerResult&, const RunRecord& run) {
      const TrainerConfig& cfg = *run.config;
      j.add("scene", to_string(cfg.dataset.scene.layout)).add("seed", static_cast<long long>(cfg.dataset.scene.seed));
      if (cfg.dataset.tracker_failures != TrackerFailures::scene)  // only when set: the default keys stay
        j.add("tracker_failures", tracker_failure_names()[static_cast<std::size_t>(cfg.dataset.tracker_failures)]);
    },
    [](cli::JsonLine& j, const TrainerResult& r, const RunRecord& run) {
      if (run.config->image_eval) {
        const Evaluation& e = r.evaluation;
        j.add("test_psnr", e.mean.psnr)
            .add("test_ssim", e.mean.ssim)
            .add("test_psnr_masked", e.mean.psnr_masked)
            .add("test_ssim_masked", e.mean.ssim_masked)
            .add("test_psnr_box", e.mean.psnr_box)
            .add("test_psnr_objects", e.mean.psnr_objects)
            .add("train_psnr", e.train_psnr);
        std::string views = "{";
        for (const auto& v : e.views)
          views += (views.size() > 1 ? "," : "") + cli::JsonLine::quote(v.name) + ":" + view_json(v);
        j.add_raw("views", views + "}");
      }
      add_tracks(j, "", r.evaluation.tracks);
      add_tracks(j, "_stage1", r.tracks_stage1);
      add_tracks(j, "_lifted", r.tracks_lifted);
    },
    [](cli::JsonLine& j, const TrainerResult& r, const RunRecord&) {
      add_confidence(j, "", r.confidence_stage1);
      add_confidence(j, "_lifted", r.confidence_lifted);
    },
    [](cli::JsonLine& j, const TrainerResult& r) {
      j.add_raw("node_epe_split_stage1", node_split_json(r.node_split_stage1));
    },
    no_keys,
    [](cli::JsonLine& j, const TrainerResult& r, const RunRecord&) { j.add("seconds_dataset", r.seconds_dataset); },
    [](cli::JsonLine& j, const TrainerResult& r, const RunRecord&) { j.add("seconds_total", r.seconds_total); },
};

const SceneKeys kDiskKeys = {
    [](cli::JsonLine& j, const TrainerResult& r, const RunRecord&) { j.add("scene", r.data.source); },
    [](cli::JsonLine&, const TrainerResult&, const RunRecord&) {},
    [](cli::JsonLine& j, const TrainerResult& r, const RunRecord& run) {
      const Evaluation& e = r.evaluation;
      j.add("semantic_graph", r.config.variant.semantic_graph);
      if (run.config->image_eval)
        j.add("val_frames", static_cast<long long>(e.frames.size()))
            .add("mpsnr", e.frames_mean.mpsnr)
            .add("mssim", e.frames_mean.mssim)
            .add("mssim_covisible", e.frames_mean.mssim_covisible)
            .add("psnr", e.frames_mean.psnr)
            .add("ssim", e.frames_mean.ssim);
      std::string frames = "[";
      for (const FrameScore& f : e.frames) {
        cli::JsonLine fj;
        fj.add("frame", f.name).add("mpsnr", f.mpsnr).add("mssim", f.mssim).add("mssim_covisible", f.mssim_covisible)
            .add("psnr", f.psnr).add("ssim", f.ssim);
        frames += (frames.size() > 1 ? "," : "") + fj.str();
      }
      j.add_raw("per_frame", frames + "]");
      if (run.queries > 0) j.add("queries", run.queries);
      if (run.query_error)
        j.add("epe", run.query_error->epe)
            .add("delta_5cm", run.query_error->within_5cm)
            .add("delta_10cm", run.query_error->within_10cm);
    },
    no_keys,
    [](cli::JsonLine& j, const TrainerResult& r) {
      j.add("length_factor", r.length_factor).add("unit", r.nodes.unit).add("lifted_tracks", r.lifted.count);
    },
    [](cli::JsonLine& j, const TrainerResult&, const RunRecord& run) { j.add("seconds_read", run.seconds_read); },
    [](cli::JsonLine& j, const TrainerResult& r, const RunRecord& run) {
      j.add("seconds_write", run.seconds_write)
          .add("seconds_total", run.seconds_read + r.seconds_total + run.seconds_write)
          .add("peak_memory_mib", peak_memory_mib());
    },
};

}  // namespace

std::string metrics_json(const TrainerResult& r, const RunRecord& run) {
  const TrainerConfig& cfg = *run.config;
  const SceneKeys& kind = r.data.truth ? kProceduralKeys : kDiskKeys;
  cli::JsonLine j;
  j.add("program", "smg_trainer").add("variant", to_string(cfg.variant.variant));
  kind.scene(j, r, run);
  j.add("T", r.data.frames())
      .add("width", r.data.width)
      .add("height", r.data.height)
      .add("threads", cfg.threads > 0 ? cfg.threads : smg::num_threads());
  if (!cfg.image_eval) j.add("image_eval", false);  // --no-image-eval: no image metrics below
  kind.images(j, r, run);
  add_carap_settings(j, cfg.node_loss);
  add_weights(j, cfg.node_loss);
  kind.evaluation(j, r, run);
  if (r.query_stage1.scored) {
    const std::vector<std::string>& names = truth_or_empty(r.data).scene.class_names;  // none from disk
    cli::JsonLine q;
    q.add("queries", r.queries->queries.count())
        .add_raw("stage1", query_score_json(r.query_stage1, names))
        .add_raw("stage2", query_score_json(r.query_stage2, names));
    j.add_raw("epe_query", q.str());
    kind.node_split(j, r);
  }
  {
    cli::JsonLine sj;
    sj.add("low_confidence", r.signals.low_confidence)
        .add("visibility_flips", r.signals.visibility_flips)
        .add("observed", r.signals.observed);
    j.add_raw("signals", sj.str());
  }
  j.add("extent", r.data.extent);
  kind.lengths(j, r);
  j.add("nodes", r.nodes.count)
      .add("edges", static_cast<long long>(r.nodes.graph.stats.edges))
      .add("gate_removed_edges", static_cast<long long>(r.nodes.graph.stats.gate_removed_edges))
      .add("gaussians", r.model.count())
      .add("gaussians_static", r.model.fixed)
      .add("gaussians_dynamic", r.model.dynamic())
      .add("pruned", r.stage2.pruned)
      .add("stage1_iterations", r.stage1.iterations)
      .add("stage2_iterations", r.stage2.iterations);
  if (run.config->stage2.hold_unobserved)  // only when set: the default keys stay
    j.add("stage2_unobserved", "hold");
  kind.read(j, r, run);
  j.add("seconds_stage0", r.seconds_stage0)
      .add("seconds_stage1", r.stage1.seconds)
      .add("seconds_stage2", r.stage2.seconds)
      .add("seconds_eval", r.evaluation.seconds);
  kind.totals(j, r, run);
  j.add("out", run.out);
  return j.str();
}

void write_metrics_json(const std::string& out_dir, const std::string& line) {
  const std::string path = (std::filesystem::path(out_dir) / "metrics.json").string();
  std::ofstream f(path);
  f << line << "\n";
  if (!f) throw std::runtime_error("cannot write " + path);
}

}  // namespace trainer
