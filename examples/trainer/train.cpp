// smg_trainer — reconstructs the example dynamic scene end to end with SMG and evaluates it on
// held-out views (docs/trainer.md).
//
//   smg_trainer [--variant full] [--seed 0] [--out trainer_out] [--quick] [--threads 0] ...
//
// Progress lines go to stderr; the last line on stdout is one JSON object with the metrics,
// also written to OUT/metrics.json, next to the pictures (pictures.hpp) and OUT/view.html, one
// self-contained page of the run (view_html.hpp; --no-view skips it). Bad flags or an
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
#include <stdexcept>
#include <string>
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
  const trainer::Stage1Options& s = cfg.stage1;
  const trainer::VariantSpec& v = cfg.variant;
  std::string gaps = "[", gap_weights = "[";
  for (const smg::Gap& g : l.gaps) {
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
      .add("w_rigidity", l.rigidity_weight)
      .add("w_lrm", l.lrm_weight)
      .add("lrm_huber", l.lrm_huber)
      .add("alpha", l.alpha)
      .add_raw("gaps", gaps + "]")
      .add_raw("gap_weights", gap_weights + "]")
      .add("kappa_m", l.confidence.kappa_m)
      .add("kappa_r", l.confidence.kappa_r)
      .add("lambda_m", l.confidence.lambda_m)
      .add("lambda_r", l.confidence.lambda_r)
      .add("confidence_eps", l.confidence.eps)
      .add("iterations", s.iterations)
      .add("lr_position", s.lr_position)
      .add("lr_position_final", s.lr_position_final)
      .add("lr_rotation", s.lr_rotation)
      .add("lr_rotation_final", s.lr_rotation_final)
      .add("confidence_every", s.confidence_every)
      .add("extent", r.data.extent)
      .add("unit", n.unit)
      .add("epe_lifted", r.tracks_lifted.all.epe)
      .add("edges", static_cast<long long>(n.graph.stats.edges))
      .add("dir", dir.string());
  const std::string line = j.str();
  std::ofstream f(dir / "case.json");
  f << line << "\n";
  if (!f) throw std::runtime_error("cannot write " + file("case.json"));
  return line;
}


// --data: trains on a scene from disk and writes renders, tracks3d.npy and metrics.json. OUT is
// created after stage 0, which can still refuse the scene (DataError).
int run_data(const trainer::TrainerConfig& cfg, trainer::Dataset data, const char* layout, double seconds_read,
             const trainer::TrackQueries* queries, const std::vector<float>* truth, const fs::path& out,
             bool quiet, bool view) {
  // Stage 0's progress lines are held back (a temporary file) until the scene is accepted, so that
  // a refused scene prints its one error line and nothing else.
  const std::unique_ptr<std::FILE, int (*)(std::FILE*)> held(quiet ? nullptr : std::tmpfile(), &std::fclose);
  const trainer::Progress early(held.get(), quiet);
  early.line("data", std::string("layout: ") + layout);
  early.line("start", "variant " + trainer::to_string(cfg.variant.variant) + ", scene " +
                          data.source + ", output " + out.string());
  trainer::TrainerResult stage0 = trainer::run_stage0(cfg, std::move(data), early);
  if (held) {
    std::rewind(held.get());
    std::array<char, 4096> buf{};
    for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), held.get())) > 0;) std::fwrite(buf.data(), 1, n, stderr);
    std::fflush(stderr);
  }
  const trainer::Progress progress(stderr, quiet, early.start());
  // Once the scene is accepted: the one note of a scene without feature maps (even with --quiet).
  if (stage0.data.priors.feature_dim == 0)
    std::cerr << "smg_trainer: note: no feature files (priors/features/<frame>.npy): the graph is geometric"
              << (cfg.variant.semantic_graph ? ", without the semantic gate of variant " + trainer::to_string(cfg.variant.variant)
                                             : std::string())
              << "\n";
  cli::ensure_writable_dir(out);
  const trainer::TrainerResult r = trainer::run_trainer(std::move(stage0), progress);
  const auto t0 = std::chrono::steady_clock::now();
  fs::create_directories(out / "renders");
  for (std::size_t v = 0; v < r.evaluation.frame_renders.size(); ++v)
    trainer::write_png((out / "renders" / (r.data.eval[v].name + ".png")).string(), r.evaluation.frame_renders[v]);
  std::vector<float> tracks;
  trainer::QueryTrackError te;
  if (queries) {
    tracks = trainer::carry_queries(*queries, r.data, r.nodes, r.model);
    npy::write((out / "tracks3d.npy").string(), tracks.data(),
               {queries->count(), r.data.frames(), 3});
    if (truth) {
      te = trainer::query_track_error(tracks, *truth);
      progress.line("eval", trainer::format("%d query tracks: EPE %.4f m, within 5 cm %.3f, within 10 cm %.3f",
                                            queries->count(), te.epe, te.within_5cm, te.within_10cm));
    }
  }
  trainer::RunRecord rec;
  rec.config = &cfg;
  rec.out = out.string();
  rec.seconds_read = seconds_read;
  rec.seconds_write = trainer::seconds_since(t0);
  rec.queries = queries ? queries->count() : 0;
  rec.query_error = queries && truth ? &te : nullptr;
  const std::string line = trainer::metrics_json(r, rec);
  trainer::write_metrics_json(out.string(), line);
  if (view) {
    trainer::ViewInputs vi;
    vi.metrics_json = line;
    if (queries) {
      vi.tracks = &tracks;
      vi.truth = truth;
      vi.queries = queries->count();
    }
    progress.line("done", "page of the run: " + trainer::write_view_html(out.string(), r, vi));
  }
  progress.line("done", std::to_string(r.evaluation.frame_renders.size()) + " renders and metrics.json in " + out.string() + "/");
  std::cout << line << std::endl;
  return 0;
}

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
  trainer::export_queries(d, 256, &q, &truth);
  trainer::write_track_queries((dir / "queries.json").string(), q);
  npy::write((dir / "queries_tracks3d.npy").string(), truth.data(), {q.count(), d.frames(), 3});
  progress.line("done", trainer::format("scene seed %llu (T=%d %dx%d, %d tracks, %d queries) in %s/ (%.1fs)",
                                        static_cast<unsigned long long>(d.seed), d.frames(),
                                        d.width, d.height, d.priors.tracks.count, q.count(),
                                        dir.string().c_str(), trainer::seconds_since(t0)));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  trainer::TrainerConfig cfg;
  fs::path out, export_dir, dycheck_dir;
  bool pictures = true, quiet = false, view = true;
  std::string export_layout;
  const char* data_layout = nullptr;  // --data: the detected layout's description
  // --data: the scene, read and validated before anything is trained.
  trainer::Dataset data;
  bool have_data = false;
  double seconds_read = 0;
  trainer::TrackQueries queries;
  std::vector<float> truth;
  bool have_queries = false, have_truth = false;
  try {
    cli::Args args(trainer::setting_flags());
    if (!trainer::flags::parse(args, argc, argv, "smg_trainer",
                               "Reconstructs the example dynamic scene with SMG and evaluates it on two held-out "
                               "views (docs/trainer.md)."))
      return 0;
    const bool quick = args.get_switch("quick");
    cfg = trainer::default_config(quick);
    trainer::apply_settings(args, &cfg);
    pictures = !args.get_switch("no-pictures");
    view = !args.get_switch("no-view");
    quiet = args.get_switch("quiet");
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
      dycheck_dir = args.get("export-dycheck");
      export_layout = args.get_choice("export-layout", trainer::export_layout_names());
      if (dycheck_dir.empty()) throw cli::UsageError("--export-dycheck needs a folder");
      cli::ensure_writable_dir(dycheck_dir);
    } else if (args.given("export-case")) {
      export_dir = args.get("export-case");
      if (export_dir.empty()) throw cli::UsageError("--export-case needs a folder");
      cli::ensure_writable_dir(export_dir);
    } else if (args.given("data")) {
      // Created only once the scene is validated (run_data); a file in its place is refused now.
      out = args.get("out");
      std::error_code ec;
      if (out.empty()) throw cli::UsageError("--out needs a folder");
      if (fs::exists(out, ec) && !fs::is_directory(out, ec))
        throw cli::UsageError("output folder '" + out.string() + "' is not a folder");
    } else {
      out = args.get("out");
      cli::ensure_writable_dir(out);
    }
    if (args.given("data")) {
      // Every file is validated here: a bad scene exits 2 with one line naming the file.
      const auto t0 = std::chrono::steady_clock::now();
      if (cfg.threads > 0) smg::set_num_threads(cfg.threads);
      trainer::DataLayout layout = trainer::DataLayout::dycheck;
      data = trainer::dataset_from_dycheck(trainer::read_data_scene(args.get("data"), &layout));
      data_layout = trainer::data_layout_description(layout);
      have_data = true;
      if (args.given("track-queries")) {
        queries = trainer::read_track_queries(args.get("track-queries"), data);
        have_queries = true;
      }
      if (args.given("track-truth")) {
        const std::string path = args.get("track-truth");
        try {
          const npy::Array a = npy::read(path);
          const std::vector<std::int64_t> want{queries.count(), data.frames(), 3};
          if (a.shape != want)
            throw npy::Error("shape " + npy::shape_string(a.shape) + ", expected " + npy::shape_string(want));
          truth = a.as<float>(path);
        } catch (const npy::Error& e) {
          throw trainer::DataError(path + ": " + e.what());
        }
        for (float v : truth)
          if (!std::isfinite(v)) throw trainer::DataError(path + ": not finite");
        have_truth = true;
      }
      seconds_read = trainer::seconds_since(t0);
    }
  } catch (const std::exception& e) {
    std::cerr << "smg_trainer: error: " << cli::escape_line(e.what()) << "\n";
    return 2;
  }

  try {
    if (cfg.threads > 0) smg::set_num_threads(cfg.threads);
    if (have_data)
      return run_data(cfg, std::move(data), data_layout, seconds_read, have_queries ? &queries : nullptr,
                      have_truth ? &truth : nullptr, out, quiet, view);
    if (!dycheck_dir.empty()) return export_dycheck(cfg, dycheck_dir, export_layout, quiet);
    const trainer::Progress progress(stderr, quiet);
    if (!export_dir.empty()) {
      progress.line("start", "variant " + trainer::to_string(cfg.variant.variant) + ", seed " +
                                 std::to_string(cfg.dataset.scene.seed) + ", exporting the stage-1 case to " +
                                 export_dir.string());
      const trainer::TrainerResult r = trainer::run_stage0(cfg, progress);
      const std::string line = export_case(export_dir, cfg, r);
      progress.line("done", "stage-1 case (T=" + std::to_string(r.nodes.frames) + ", N=" +
                                std::to_string(r.nodes.count) + ") in " + export_dir.string() + "/");
      std::cout << line << std::endl;
      return 0;
    }
    progress.line("start", "variant " + trainer::to_string(cfg.variant.variant) + ", seed " +
                               std::to_string(cfg.dataset.scene.seed) + ", output " + out.string());
    const trainer::TrainerResult r = trainer::run_trainer(cfg, progress);
    std::vector<std::string> written;
    if (pictures) written = trainer::write_pictures(out.string(), r);
    trainer::RunRecord rec;
    rec.config = &cfg;
    rec.out = out.string();
    const std::string line = trainer::metrics_json(r, rec);
    trainer::write_metrics_json(out.string(), line);
    if (view) {
      trainer::ViewInputs vi;
      vi.metrics_json = line;
      written.push_back(trainer::write_view_html(out.string(), r, vi));
    }
    if (!quiet) {
      progress.line("done", "pictures and metrics.json in " + out.string() + "/");
      for (const auto& p : written) progress.line("done", "  " + p);
    }
    std::cout << line << std::endl;
    return 0;
  } catch (const trainer::DataError& e) {
    // A scene refused by stage 0 (--data): a data problem like those found while reading. (The
    // exporter's write errors stay failures of the run.)
    std::cerr << "smg_trainer: error: " << cli::escape_line(e.what()) << "\n";
    return have_data ? 2 : 1;
  } catch (const cli::UsageError& e) {
    std::cerr << "smg_trainer: error: " << cli::escape_line(e.what()) << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "smg_trainer: error: " << cli::escape_line(e.what()) << "\n";
    return 1;
  }
}
