// scene_preview — generate the example scene and its priors for a seed and write pictures.
//
//   scene_preview [--out DIR] [--seed S] [--frames T] [--width W] [--height H] [--tracks N] ...
//
// Writes into DIR: train.png, test_right.png, test_left.png (contact sheets over time), depth.png
// (noisy depth prior), features.png (semantic features, PCA to RGB), tracks.png (reported tracks
// over the training frames), covisible.png (test views, parts never seen by the training camera
// darkened) and overview.png (all of them, a few frames each). Prints one JSON line with the
// sizes, track statistics and timings. Bad flags or an unwritable DIR: one line on stderr, exit
// code 2.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "json_line.hpp"
#include "trainer/dataset.hpp"
#include "trainer/flags.hpp"
#include "trainer/frames.hpp"
#include "trainer/image_io.hpp"
#include "trainer/progress.hpp"

namespace {

namespace fs = std::filesystem;
using trainer::flags::int_in;
using trainer::Image;

std::string names(const std::vector<std::string>& list) {
  std::string s;
  for (const auto& n : list) s += (s.empty() ? "" : " | ") + n;
  return s;
}

std::vector<cli::FlagSpec> flags() {
  return {{"out", "scene_preview_out", "output folder (created if missing)"},
          {"seed", "0", "scene and prior seed"},
          {"scene", "standard", "scene layout: " + names(trainer::scene_layout_names())},
          {"tracker-failures", "scene",
           "tracker failures of the priors: " + names(trainer::tracker_failure_names()) +
               " (docs/trainer.md, \"Tracker failures\")"},
          {"frames", "32", "number of frames T"},
          {"width", "160", "image width (pixels)"},
          {"height", "120", "image height (pixels)"},
          {"tracks", "1000", "number of 2D tracks"},
          {"feature-dim", "8", "semantic feature channels C"},
          {"supersample", "2", "k x k colour rays per pixel"},
          {"jitter-px", "0.5", "track jitter sigma (pixels)"},
          {"outlier-rate", "0.02", "fraction of reported samples that jump"},
          {"depth-noise", "0.02", "relative depth noise sigma"},
          {"show", "8", "frames per contact sheet"},
          {"threads", "0", "worker threads, 0 = all hardware threads"},
          {"help", "", "print this help", true}};
}

Image labelled(Image im, const std::string& text) {
  trainer::draw_text(im, 3, 3, text, Eigen::Vector3f(1, 1, 1));
  return im;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    cli::Args args(flags());
    if (!trainer::flags::parse(args, argc, argv, "scene_preview",
                               "Generates the example scene and its priors and writes pictures (docs/trainer.md)."))
      return 0;

    trainer::DatasetConfig cfg;
    trainer::SceneLayout layout = trainer::SceneLayout::standard;
    trainer::parse_scene_layout(args.get_choice("scene", trainer::scene_layout_names()), &layout);
    trainer::apply_scene_layout(layout, &cfg);
    {
      const auto& tf = trainer::tracker_failure_names();
      const std::string name = args.get_choice("tracker-failures", tf);
      cfg.tracker_failures =
          static_cast<trainer::TrackerFailures>(std::find(tf.begin(), tf.end(), name) - tf.begin());
    }
    cfg.scene.seed = static_cast<std::uint64_t>(int_in(args, "seed", 0, 2147483647));
    cfg.scene.frames = int_in(args, "frames", 2, 1000);
    cfg.scene.width = int_in(args, "width", 16, 4096);
    cfg.scene.height = int_in(args, "height", 16, 4096);
    cfg.priors.tracks = int_in(args, "tracks", 1, 1000000);
    cfg.priors.feature_dim = int_in(args, "feature-dim", trainer::classes::count + 1, 1024);
    cfg.supersample = int_in(args, "supersample", 1, 8);
    cfg.priors.jitter_px = args.get_double("jitter-px");
    cfg.priors.outlier_rate = args.get_double("outlier-rate");
    cfg.priors.depth_noise = args.get_double("depth-noise");
    const int show = int_in(args, "show", 1, 64);
    const int threads = int_in(args, "threads", 0, 1024);
    trainer::flags::validate(cfg.scene, cfg.priors);
    const fs::path out = args.get("out");
    cli::ensure_writable_dir(out);

    const auto t0 = std::chrono::steady_clock::now();
    const trainer::Dataset d = trainer::make_dataset(cfg, smg::ParallelOptions{threads, 0});
    const trainer::GroundTruth& g = *d.truth;  // make_dataset always fills it
    const trainer::LiftedTracks lifted = trainer::lift_tracks(d.cameras, d.priors);
    const double seconds_lift = trainer::seconds_since(t0) - d.seconds.total;

    // Pictures.
    const int T = g.scene.frames(), W = g.scene.width(), H = g.scene.height(), C = d.priors.feature_dim;
    const std::vector<int> frames = trainer::spread_frames(T, show);
    const int columns = std::min<int>(static_cast<int>(frames.size()), 4);
    const auto fp = trainer::fit_feature_projection(d.priors.features.data(), d.priors.features.size() / C, C);
    double zmin = 1e30, zmax = 0;
    for (const auto& r : g.train)
      for (float z : r.depth)
        if (z > 0) {
          zmin = std::min<double>(zmin, z);
          zmax = std::max<double>(zmax, z);
        }
    const int track_stride = std::max(1, d.priors.tracks.count / 300);
    enum Panel { kTrain, kTracks, kDepth, kFeatures, kTest0, kTest1, kCovis0, kCovis1, kPanels };
    const std::string panel_names[kPanels] = {"training view", "reported tracks", "depth prior", "features (PCA)",
                                              g.scene.test_views[0].name, g.scene.test_views[1].name,
                                              "covisible " + g.scene.test_views[0].name,
                                              "covisible " + g.scene.test_views[1].name};
    auto panel = [&](int kind, int t) {
      const std::size_t ts = static_cast<std::size_t>(t), plane = static_cast<std::size_t>(W) * H;
      const trainer::RenderOutput& r = g.train[ts];
      switch (kind) {
        case kTrain: return r.rgb;
        case kTracks: {
          Image im = r.rgb;
          trainer::draw_tracks(im, d.priors.tracks.uv.data(), d.priors.tracks.visible.data(), T, d.priors.tracks.count, t,
                               4, track_stride);
          return im;
        }
        case kDepth: return trainer::colorize_depth(d.priors.depth.data() + ts * plane, W, H, zmin, zmax);
        case kFeatures: return trainer::colorize_features(d.priors.features.data() + ts * plane * C, W, H, C, fp);
        case kTest0:
        case kTest1: return g.test[static_cast<std::size_t>(kind - kTest0)][ts].rgb;
        default: {  // test view with the parts the training camera never saw tinted red
          const std::size_t v = static_cast<std::size_t>(kind - kCovis0);
          Image im = g.test[v][ts].rgb;
          const std::uint8_t* m = g.test_covisible[v].data() + ts * plane;
          for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x)
              if (!m[static_cast<std::size_t>(y) * W + x]) {
                im.at(x, y, 0) = 0.5f * im.at(x, y, 0) + 0.3f;
                im.at(x, y, 1) *= 0.3f;
                im.at(x, y, 2) *= 0.3f;
              }
          return im;
        }
      }
    };
    auto sheet = [&](int kind) {
      std::vector<Image> cells;
      cells.reserve(frames.size());
      for (int t : frames) cells.push_back(labelled(panel(kind, t), "t=" + std::to_string(t)));
      return trainer::grid(cells, columns);
    };
    trainer::write_png((out / "train.png").string(), sheet(kTrain));
    trainer::write_png((out / "tracks.png").string(), sheet(kTracks));
    trainer::write_png((out / "depth.png").string(), sheet(kDepth));
    trainer::write_png((out / "features.png").string(), sheet(kFeatures));
    trainer::write_png((out / (g.scene.test_views[0].name + ".png")).string(), sheet(kTest0));
    trainer::write_png((out / (g.scene.test_views[1].name + ".png")).string(), sheet(kTest1));
    trainer::write_png((out / "covisible.png").string(), trainer::vstack({sheet(kCovis0), sheet(kCovis1)}, 4));
    // Overview: one row per modality over at most 6 frames, the row's name on its first cell.
    {
      std::vector<Image> rows;
      for (int kind : {kTrain, kTracks, kDepth, kFeatures, kTest0, kTest1}) {
        std::vector<Image> row;
        for (int t : trainer::spread_frames(T, std::min(6, show)))
          row.push_back(labelled(panel(kind, t), (row.empty() ? panel_names[kind] + "  " : std::string()) + "t=" +
                                                     std::to_string(t)));
        rows.push_back(trainer::hstack(row));
      }
      trainer::write_png((out / "overview.png").string(), trainer::vstack(rows));
    }
    const double seconds_total = trainer::seconds_since(t0);

    const trainer::TrackStats st = trainer::track_stats(d.priors.tracks);
    double covisible[2] = {0, 0};
    for (int v = 0; v < 2; ++v) {
      const auto& m = g.test_covisible[static_cast<std::size_t>(v)];
      long long n = 0, hit = 0;
      for (std::size_t i = 0; i < m.size(); ++i) {
        if (g.test[static_cast<std::size_t>(v)][i / (static_cast<std::size_t>(W) * H)].body[i % (static_cast<std::size_t>(W) * H)] < 0) continue;
        ++n;
        hit += m[i];
      }
      covisible[v] = n ? static_cast<double>(hit) / n : 0.0;
    }
    cli::JsonLine j;
    j.add("program", "scene_preview")
        .add("scene", trainer::to_string(cfg.scene.layout))
        .add("seed", static_cast<long long>(cfg.scene.seed))
        .add("T", T)
        .add("width", W)
        .add("height", H)
        .add("tracks", d.priors.tracks.count)
        .add("lifted_tracks", lifted.count)
        .add("visible_fraction", st.visible_fraction)
        .add("outlier_fraction", st.outlier_fraction)
        .add("dropped_fraction", st.dropped_fraction)
        .add("occluded_reported_fraction", st.occluded_reported_fraction)
        .add("jitter_rms_px", st.jitter_rms_px)
        .add("tracker_failures", trainer::tracker_failure_names()[static_cast<std::size_t>(cfg.tracker_failures)])
        .add("occluded_visible_rate", st.occluded_visible_rate)
        .add("stuck_track_rate", st.stuck_track_rate)
        .add("switched_track_rate", st.switched_track_rate)
        .add("extent", g.scene.extent)
        .add("min_gap", g.scene.min_gap)
        .add("covisible_fraction_test_right", covisible[0])
        .add("covisible_fraction_test_left", covisible[1])
        .add("seconds_scene", d.seconds.scene)
        .add("seconds_render_train", d.seconds.render_train)
        .add("seconds_render_test", d.seconds.render_test)
        .add("seconds_covisibility", d.seconds.covisibility)
        .add("seconds_priors", d.seconds.priors)
        .add("seconds_lift", seconds_lift)
        .add("seconds_dataset", d.seconds.total)
        .add("seconds_total", seconds_total)
        .add("out", out.string());
    std::cout << j.str() << std::endl;
    return 0;
  } catch (const cli::UsageError& e) {
    std::cerr << "scene_preview: error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "scene_preview: error: " << e.what() << "\n";
    return 2;
  }
}
