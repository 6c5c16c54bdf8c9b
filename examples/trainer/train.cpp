// smg_trainer — reconstructs the example dynamic scene end to end with SMG and evaluates it on
// held-out views (docs/trainer.md).
//
//   smg_trainer [--variant full] [--seed 0] [--out trainer_out] [--quick] [--threads 0] ...
//
// Progress lines go to stderr; the last line on stdout is one JSON object with the metrics,
// also written to OUT/metrics.json, next to the pictures (pictures.hpp) and OUT/view.html, one
// self-contained page of the run (view_html.hpp; --no-view skips it), and with --ply (default
// with --quick) OUT/ply/frame_<t>.ply, the Gaussians of every frame (ply.hpp). Bad flags or an
// output folder that cannot be written: one line on stderr and exit code 2, before any work.
// A failure during training: one line on stderr and exit code 1.
//
// --data SCENE trains on a scene on disk (docs/data.md): the Dycheck iPhone layout plus priors,
// or Shape-of-Motion's or MoSca's preprocessed layout, detected from the folder's contents (layouts.hpp);
// OUT/renders/<frame>.png for every validation frame, OUT/metrics.json with Dycheck's mPSNR and
// mSSIM, and with --track-queries Q.json OUT/tracks3d.npy [M][T][3]. A missing or inconsistent
// file, or a scene too poor to train (too few lifted object tracks): exit 2 with one line naming
// the file or the cause, control characters escaped, before any training; OUT is created only
// once the scene has passed stage 0. Without feature files the graph is geometric (one stderr
// note). --export-dycheck DIR writes the procedural scene in that layout (plus queries.json and
// queries_tracks3d.npy, the true tracks); with --export-layout som / mosca, in Shape-of-Motion's / MoSca's.
//
// --export-case DIR stops after stage 0 (lifting, node selection, graph, initial rotations) and
// writes stage 1's problem as .npy files and case.json into DIR instead of training
// (docs/trainer.md, "Exporting the stage-1 problem"; examples/torch/fit_nodes.py reads it).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "json_line.hpp"
#include "npy.hpp"
#include "trainer/data_export.hpp"
#include "trainer/data_queries.hpp"
#include "trainer/data_scene.hpp"
#include "trainer/layouts.hpp"
#include "trainer/metrics_json.hpp"
#include "trainer/dycheck.hpp"
#include "trainer/flags.hpp"
#include "trainer/image_io.hpp"
#include "trainer/pictures.hpp"
#include "trainer/ply.hpp"
#include "trainer/pipeline.hpp"
#include "trainer/settings.hpp"
#include "trainer/view_html.hpp"

namespace {

namespace fs = std::filesystem;

// The variant's stage-1 problem, as run_trainer hands it to fit_nodes (docs/trainer.md).
std::string export_case(const fs::path& dir, const trainer::TrainerConfig& cfg, const trainer::TrainerResult& r) {
  const trainer::Nodes& n = r.nodes;
  const std::int64_t T = n.frames, N = n.count, K = n.graph.k;
  const auto file = [&](const char* name) { return (dir / name).string(); };
  npy::write(file("lifted.npy"), n.positions.data(), {T, N, 3});
  npy::write(file("visibility.npy"), n.visible.data(), {T, N});
  npy::write(file("gt_positions.npy"), n.truth.data(), {T, N, 3});
  npy::write(file("quats.npy"), n.rotations.data(), {T, N, 4});
  const std::vector<std::int64_t> indices(n.graph.indices.begin(), n.graph.indices.end());
  npy::write(file("graph_indices.npy"), indices.data(), {N, K});
  npy::write(file("graph_weights.npy"), n.graph.weights.data(), {N, K});

  const trainer::NodeLossOptions& l = cfg.node_loss;
  const smg::RegularizerOptions& ro = l.regularizers;
  const trainer::Stage1Options& s = cfg.stage1;
  const trainer::VariantSpec& v = cfg.variant;
  std::string gaps = "[", gap_weights = "[";
  for (const smg::Gap& g : ro.carap.gaps) {
    gaps += (gaps.size() > 1 ? "," : "") + std::to_string(g.delta);
    std::array<char, 32> w{};
    std::snprintf(w.data(), w.size(), "%.10g", g.weight);
    gap_weights += (gap_weights.size() > 1 ? "," : "") + std::string(w.data());
  }
  cli::JsonLine j;
  j.add("program", "smg_trainer")
      .add("kind", "stage1_case")
      .add("seed", static_cast<long long>(cfg.dataset.scene.seed))
      .add("T", static_cast<long long>(T))
      .add("N", static_cast<long long>(N))
      .add("K", static_cast<long long>(K))
      .add("variant", trainer::to_string(v.variant))
      .add("semantic_graph", v.semantic_graph)
      .add("rigidity", v.rigidity == trainer::Rigidity::carap ? "carap"
                       : v.rigidity == trainer::Rigidity::arap ? "arap" : "none")
      .add("lrm", v.lrm)
      .add("quats_order", "wxyz")
      .add("w_data", l.data_weight)
      .add("data_huber", l.data_huber)
      .add("w_rigidity", ro.carap.weight)
      .add("w_lrm", ro.lrm.weight)
      .add("lrm_huber", ro.lrm.huber_delta)
      .add("alpha", ro.carap.alpha)
      .add_raw("gaps", gaps + "]")
      .add_raw("gap_weights", gap_weights + "]")
      .add("kappa_m", ro.confidence.kappa_m)
      .add("kappa_r", ro.confidence.kappa_r)
      .add("lambda_m", ro.confidence.lambda_m)
      .add("lambda_r", ro.confidence.lambda_r)
      .add("confidence_eps", ro.confidence.eps)
      .add("iterations", s.iterations)
      .add("lr_position", s.lr_position)
      .add("lr_position_final", s.lr_position_final)
      .add("lr_rotation", s.lr_rotation)
      .add("lr_rotation_final", s.lr_rotation_final)
      .add("confidence_every", s.confidence_every)
      .add("extent", r.data.extent)
      .add("unit", n.unit)
      .add("epe_lifted", r.tracks_lifted.all.epe)
      .add("edges", static_cast<long long>(n.graph.stats.edges));
  // Every term its weight switches (not the variant), as w_<term> (w_accel, ...): fit_nodes.py
  // refuses a case with a term it does not fit, so a new term is recorded without an edit here.
  smg::for_each_term(ro, [&](const char* name, bool, const auto& o) {
    if constexpr (trainer::has_weight<std::decay_t<decltype(o)>>::value)
      if (!trainer::variant_term(name)) j.add(std::string("w_") + name, o.weight);
  });
  j.add("dir", dir.string());
  const std::string line = j.str();
  std::ofstream f(dir / "case.json");
  f << line << "\n";
  if (!f) throw std::runtime_error("cannot write " + file("case.json"));
  return line;
}


// What the command line asks for, parsed and validated (with --data, the scene read and
// validated too) before any work.
struct Request {
  trainer::TrainerConfig cfg;
  enum class Job { train, export_scene, export_case } job = Job::train;
  fs::path out;                 // train: OUT; export_scene / export_case: the folder to write
  std::string export_layout;    // export_scene: dycheck, som or mosca
  bool pictures = true, quiet = false, view = true, ply = false;
  // --data: the scene (moved into the run once it starts) and its layout's description;
  // --track-queries / --track-truth.
  bool from_disk = false;
  std::optional<trainer::Dataset> data;
  const char* data_layout = nullptr;
  double seconds_read = 0;
  std::optional<trainer::TrackQueries> queries;
  std::optional<std::vector<float>> truth;
};

// --export-dycheck: the generated scene in the Dycheck layout, with 3D query tracks.
// layout som / mosca: the same scene in Shape-of-Motion's or MoSca's layout (layouts.hpp).
int export_dycheck(const trainer::TrainerConfig& cfg, const fs::path& dir, const std::string& layout, bool quiet) {
  const trainer::Progress progress(stderr, quiet);
  const auto t0 = std::chrono::steady_clock::now();
  const trainer::Dataset d = trainer::make_dataset(cfg.dataset, smg::ParallelOptions{cfg.threads, 0});
  if (layout == "som")
    trainer::write_som(dir.string(), trainer::to_dycheck(d));
  else if (layout == "mosca")
    trainer::write_mosca(dir.string(), trainer::to_dycheck(d));
  else
    trainer::write_dycheck(dir.string(), trainer::to_dycheck(d));
  trainer::TrackQueries q;
  std::vector<float> truth;
  trainer::export_queries(d, trainer::kQueryCount, &q, &truth);
  trainer::write_track_queries((dir / "queries.json").string(), q);
  npy::write((dir / "queries_tracks3d.npy").string(), truth.data(), {q.count(), d.frames(), 3});
  progress.line("done", trainer::format("scene seed %llu (T=%d %dx%d, %d tracks, %d queries) in %s/ (%.1fs)",
                                        static_cast<unsigned long long>(d.seed), d.frames(),
                                        d.width, d.height, d.priors.tracks.count, q.count(),
                                        dir.string().c_str(), trainer::seconds_since(t0)));
  return 0;
}

// Parses the command line into `q` and, with --data, reads and validates the scene: every file
// problem throws (DataError naming the file), a bad flag throws cli::UsageError. Returns false
// after --help.
bool parse(int argc, char** argv, Request& q) {
  trainer::TrainerConfig& cfg = q.cfg;
  cli::Args args(trainer::setting_flags());
  if (!trainer::flags::parse(args, argc, argv, "smg_trainer",
                             "Reconstructs the example dynamic scene with SMG and evaluates it on two held-out "
                             "views (docs/trainer.md)."))
    return false;
  cfg = trainer::default_config(args.get_switch("quick"));
  trainer::apply_settings(args, &cfg);
  cfg.image_eval = !args.get_switch("no-image-eval");
  q.pictures = !args.get_switch("no-pictures") && cfg.image_eval;
  q.view = !args.get_switch("no-view") && cfg.image_eval;
  if (args.get_switch("ply") && args.get_switch("no-ply")) throw cli::UsageError("--ply and --no-ply contradict each other");
  q.ply = args.get_switch("ply") || (args.get_switch("quick") && !args.get_switch("no-ply"));
  q.quiet = args.get_switch("quiet");
  trainer::flags::validate(cfg.dataset.scene, cfg.dataset.priors);
  if (args.given("data")) {
    if (cfg.node_loss.confidence_source == trainer::ConfidenceSource::truth)
      throw cli::UsageError("--confidence-from truth needs the generated scene's ground truth, not --data");
    for (const trainer::Setting& f : trainer::settings())
      if (f.generated_only && args.given(f.name))
        throw cli::UsageError(std::string("--") + f.name + " cannot be used with --data");
  } else {
    for (const char* f : {"track-queries", "track-truth"})
      if (args.given(f)) throw cli::UsageError(std::string("--") + f + " needs --data");
  }
  if (args.given("export-layout") && !args.given("export-dycheck"))
    throw cli::UsageError("--export-layout needs --export-dycheck");
  if (args.given("track-truth") && !args.given("track-queries"))
    throw cli::UsageError("--track-truth needs --track-queries");
  if (args.given("export-dycheck")) {
    q.job = Request::Job::export_scene;
    q.out = args.get("export-dycheck");
    q.export_layout = args.get_choice("export-layout", trainer::export_layout_names());
    if (q.out.empty()) throw cli::UsageError("--export-dycheck needs a folder");
    cli::ensure_writable_dir(q.out);
  } else if (args.given("export-case")) {
    q.job = Request::Job::export_case;
    q.out = args.get("export-case");
    if (q.out.empty()) throw cli::UsageError("--export-case needs a folder");
    cli::ensure_writable_dir(q.out);
  } else if (args.given("data")) {
    // Created only once the scene is validated (train); a file in its place is refused now.
    q.out = args.get("out");
    std::error_code ec;
    if (q.out.empty()) throw cli::UsageError("--out needs a folder");
    if (fs::exists(q.out, ec) && !fs::is_directory(q.out, ec))
      throw cli::UsageError("output folder '" + q.out.string() + "' is not a folder");
  } else {
    q.out = args.get("out");
    cli::ensure_writable_dir(q.out);
  }
  if (!args.given("data")) return true;
  q.from_disk = true;
  // Every file is validated here: a bad scene exits 2 with one line naming the file.
  const auto t0 = std::chrono::steady_clock::now();
  if (cfg.threads > 0) smg::set_num_threads(cfg.threads);
  trainer::DataLayout layout = trainer::DataLayout::dycheck;
  q.data = trainer::dataset_from_dycheck(trainer::read_data_scene(args.get("data"), &layout));
  q.data_layout = trainer::data_layout_description(layout);
  if (args.given("track-queries")) q.queries = trainer::read_track_queries(args.get("track-queries"), *q.data);
  if (args.given("track-truth")) {
    const std::string path = args.get("track-truth");
    try {
      const npy::Array a = npy::read(path);
      const std::vector<std::int64_t> want{q.queries->count(), q.data->frames(), 3};
      if (a.shape != want) throw npy::Error("shape " + npy::shape_string(a.shape) + ", expected " + npy::shape_string(want));
      q.truth = a.as<float>(path);
    } catch (const npy::Error& e) {
      throw trainer::DataError(path + ": " + e.what());
    }
    for (float v : *q.truth)
      if (!std::isfinite(v)) throw trainer::DataError(path + ": not finite");
  }
  q.seconds_read = trainer::seconds_since(t0);
  return true;
}

// Trains on the procedural scene, or on the scene from disk. A scene from disk can still be
// refused by stage 0 (DataError): its progress lines are held back until it is accepted, and
// OUT is created only then, so a refused scene prints its one error line and leaves nothing.
trainer::TrainerResult train(Request& q, const trainer::Progress& progress) {
  const trainer::TrainerConfig& cfg = q.cfg;
  if (!q.data) {
    progress.line("start", "variant " + trainer::to_string(cfg.variant.variant) + ", seed " +
                               std::to_string(cfg.dataset.scene.seed) + ", output " + q.out.string());
    return trainer::run_trainer(cfg, progress);
  }
  progress.hold();
  progress.line("data", std::string("layout: ") + q.data_layout);
  progress.line("start", "variant " + trainer::to_string(cfg.variant.variant) + ", scene " + q.data->source +
                             ", output " + q.out.string());
  trainer::TrainerResult stage0 = trainer::run_stage0(cfg, std::move(*q.data), progress);
  q.data.reset();
  progress.release();
  // Once the scene is accepted: the one note of a scene without feature maps (even with --quiet).
  if (stage0.data.priors.feature_dim == 0)
    std::cerr << "smg_trainer: note: no feature files (priors/features/<frame>.npy): the graph is geometric"
              << (cfg.variant.semantic_graph ? ", without the semantic gate of variant " + trainer::to_string(cfg.variant.variant)
                                             : std::string())
              << "\n";
  cli::ensure_writable_dir(q.out);
  // The query tracks are scored inside the pipeline, after stage 1 and after stage 2, by the
  // code that scores a procedural run (score_queries).
  if (q.queries) {
    trainer::QuerySet set;
    set.queries = *q.queries;
    set.truth = q.truth.value_or(std::vector<float>());  // empty: the tracks are written, not scored
    stage0.queries = std::move(set);
  }
  return trainer::run_trainer(std::move(stage0), progress);
}

// Writes OUT: the validation frames' renders (OUT/renders/<frame>.png), the query tracks
// (OUT/tracks3d.npy), the pictures of the test views (procedural scene), metrics.json and
// view.html. Returns metrics.json's line.
std::string write_run(const Request& q, const trainer::TrainerResult& r, const trainer::Progress& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  const trainer::Evaluation& e = r.evaluation;
  std::vector<std::string> written;
  std::string what = "pictures";  // what the run's images are, for the last lines
  if (!r.data.truth) {
    fs::create_directories(q.out / "renders");
    for (std::size_t v = 0; v < e.frame_renders.size(); ++v)
      trainer::write_png((q.out / "renders" / (r.data.eval[v].name + ".png")).string(), e.frame_renders[v]);
    what = std::to_string(e.frame_renders.size()) + " renders";
  } else if (q.pictures) {
    written = trainer::write_pictures(q.out.string(), r);
  }
  // The query tracks after stage 2, as the pipeline carried and scored them.
  const std::vector<float>& tracks = r.query_stage2.tracks;
  const trainer::QueryTrackError& te = r.query_stage2.all;
  if (q.queries)
    npy::write((q.out / "tracks3d.npy").string(), tracks.data(), {q.queries->count(), r.data.frames(), 3});
  trainer::RunRecord rec;
  rec.config = &q.cfg;
  rec.out = q.out.string();
  rec.seconds_read = q.seconds_read;
  rec.seconds_write = trainer::seconds_since(t0);
  rec.queries = q.queries ? q.queries->count() : 0;
  rec.query_error = r.query_stage2.scored ? &te : nullptr;  // scored: the queries had true tracks
  const std::string line = trainer::metrics_json(r, rec);
  trainer::write_metrics_json(q.out.string(), line);
  if (q.view) {
    trainer::ViewInputs vi;
    vi.metrics_json = line;
    if (q.queries) {
      vi.tracks = &tracks;
      vi.truth = &r.queries->truth;  // empty without --track-truth
      vi.queries = q.queries->count();
    }
    written.push_back(trainer::write_view_html(q.out.string(), r, vi));
  }
  if (q.ply) {
    const std::vector<std::string> ply = trainer::write_ply_frames(q.out.string(), r.model, r.nodes);
    if (!ply.empty())
      written.push_back((q.out / "ply").string() + "/frame_<t>.ply, t = 0.." + std::to_string(ply.size() - 1) + " (" +
                        std::to_string(r.model.count()) + " Gaussians each)");
  }
  progress.line("done", what + " and metrics.json in " + q.out.string() + "/");
  for (const std::string& p : written) progress.line("done", "  " + p);
  return line;
}

}  // namespace

// parse -> run -> write. Exit codes: 0 done; 2 a bad flag, an output folder that cannot be
// written or a scene refused (one line on stderr, before anything is written); 1 a failure
// during the run.
int main(int argc, char** argv) {
  Request q;
  try {
    if (!parse(argc, argv, q)) return 0;
  } catch (const std::exception& e) {
    std::cerr << "smg_trainer: error: " << cli::escape_line(e.what()) << "\n";
    return 2;
  }

  try {
    const trainer::TrainerConfig& cfg = q.cfg;
    if (cfg.threads > 0) smg::set_num_threads(cfg.threads);
    if (q.job == Request::Job::export_scene) return export_dycheck(cfg, q.out, q.export_layout, q.quiet);
    const trainer::Progress progress(stderr, q.quiet);
    if (q.job == Request::Job::export_case) {
      progress.line("start", "variant " + trainer::to_string(cfg.variant.variant) + ", seed " +
                                 std::to_string(cfg.dataset.scene.seed) + ", exporting the stage-1 case to " +
                                 q.out.string());
      const trainer::TrainerResult r = trainer::run_stage0(cfg, progress);
      const std::string line = export_case(q.out, cfg, r);
      progress.line("done", "stage-1 case (T=" + std::to_string(r.nodes.frames) + ", N=" +
                                std::to_string(r.nodes.count) + ") in " + q.out.string() + "/");
      std::cout << line << std::endl;
      return 0;
    }
    const trainer::TrainerResult r = train(q, progress);
    std::cout << write_run(q, r, progress) << std::endl;
    return 0;
  } catch (const trainer::DataError& e) {
    // A scene refused by stage 0 (--data): a data problem like those found while reading. (The
    // exporter's write errors stay failures of the run.)
    std::cerr << "smg_trainer: error: " << cli::escape_line(e.what()) << "\n";
    return q.from_disk ? 2 : 1;
  } catch (const cli::UsageError& e) {
    std::cerr << "smg_trainer: error: " << cli::escape_line(e.what()) << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "smg_trainer: error: " << cli::escape_line(e.what()) << "\n";
    return 1;
  }
}
