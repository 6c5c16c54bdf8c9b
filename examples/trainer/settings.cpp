// examples/trainer/settings.cpp — the table of smg_trainer's flags (settings.hpp).
#include "trainer/settings.hpp"

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>

#include "trainer/flags.hpp"

namespace trainer {

namespace {

const std::vector<std::string>& stage2_unobserved_names() {
  static const std::vector<std::string> names = {"move", "hold"};
  return names;
}

const std::vector<std::string>& on_off_names() {
  static const std::vector<std::string> names = {"on", "off"};
  return names;
}

// Position of `name` in `names` (a name get_choice has already checked).
double index_of(const std::string& name, const std::vector<std::string>& names) {
  return static_cast<double>(std::find(names.begin(), names.end(), name) - names.begin());
}
std::size_t as_index(double v) { return static_cast<std::size_t>(v); }

// A value as --help prints it: integers without a fraction, numbers in %g.
std::string format_value(SettingKind kind, double v) {
  if (kind == SettingKind::integer) return std::to_string(static_cast<long long>(v));
  std::array<char, 32> buf{};
  std::snprintf(buf.data(), buf.size(), "%g", v);
  return buf.data();
}

std::string join(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : " | ") + n;
  return s;
}

using K = SettingKind;
using C = TrainerConfig;

// The accessors of an integer setting of the generated scene (frames, width, height): one pair
// of functions serves every such row.
template <int SceneConfig::*F>
double scene_int(const C& c) {
  return static_cast<double>(c.dataset.scene.*F);
}
template <int SceneConfig::*F>
void set_scene_int(C& c, double v) {
  c.dataset.scene.*F = static_cast<int>(v);
}

}  // namespace

const std::vector<std::string>& export_layout_names() {
  static const std::vector<std::string> names = {"dycheck", "som", "mosca"};
  return names;
}

const std::vector<Setting>& settings() {
  // Accessors are captureless lambdas (function pointers): the table is data, built once.
  static const std::vector<Setting> table = {
      {"variant", K::choice, "ablation rung of docs/trainer.md", 0, 0, &variant_names,
       [](const C& c) { return index_of(to_string(c.variant.variant), variant_names()); },
       [](C& c, double v) { parse_variant(variant_names()[as_index(v)], &c.variant); }},
      {"scene", K::choice, "generated scene of docs/trainer.md", 0, 0, &scene_layout_names,
       [](const C& c) { return static_cast<double>(c.dataset.scene.layout); },
       [](C& c, double v) { apply_scene_layout(static_cast<SceneLayout>(as_index(v)), &c.dataset); }, "", true},
      {"tracker-failures", K::choice,
       "tracker failures of the generated priors: the scene layout's own, none, TAPIR-class typical rates or "
       "twice those (docs/trainer.md, \"Tracker failures\")",
       0, 0, &tracker_failure_names,
       [](const C& c) { return static_cast<double>(c.dataset.tracker_failures); },
       [](C& c, double v) { c.dataset.tracker_failures = static_cast<TrackerFailures>(as_index(v)); }, "", true},
      {"seed", K::integer, "scene, prior and training seed", 0, 2147483647, nullptr,
       [](const C& c) { return static_cast<double>(c.dataset.scene.seed); },
       [](C& c, double v) { c.dataset.scene.seed = static_cast<std::uint64_t>(v); }, "", true},
      {"out", K::text, "output folder (created if missing): pictures and metrics.json", 0, 0, nullptr, nullptr, nullptr,
       "trainer_out"},
      {"quick", K::flag, "small, fast run for CI (16 frames at 96x72, few iterations)"},
      {"threads", K::integer, "worker threads, 0 = all hardware threads", 0, 1024, nullptr,
       [](const C& c) { return static_cast<double>(c.threads); }, [](C& c, double v) { c.threads = static_cast<int>(v); }},
      {"frames", K::integer, "number of frames T", 4, 1000, nullptr,
       &scene_int<&SceneConfig::frames>, &set_scene_int<&SceneConfig::frames>, "", true},
      {"width", K::integer, "image width in pixels", 32, 4096, nullptr,
       &scene_int<&SceneConfig::width>, &set_scene_int<&SceneConfig::width>, "", true},
      {"height", K::integer, "image height in pixels", 32, 4096, nullptr,
       &scene_int<&SceneConfig::height>, &set_scene_int<&SceneConfig::height>, "", true},
      {"tracks", K::integer, "number of 2D tracks", 10, 1000000, nullptr,
       [](const C& c) { return static_cast<double>(c.dataset.priors.tracks); },
       [](C& c, double v) { c.dataset.priors.tracks = static_cast<int>(v); }, "", true},
      {"stage1-iters", K::integer, "stage-1 (nodes) iterations", 0, 1000000, nullptr,
       [](const C& c) { return static_cast<double>(c.stage1.iterations); },
       [](C& c, double v) { c.stage1.iterations = static_cast<int>(v); }},
      {"stage2-iters", K::integer, "stage-2 (Gaussians) iterations", 0, 1000000, nullptr,
       [](const C& c) { return static_cast<double>(c.stage2.iterations); },
       [](C& c, double v) { c.stage2.iterations = static_cast<int>(v); }},
      {"stage2-unobserved", K::choice,
       "stage 2 at a node's unobserved frames: move lets the photometric gradient reach its pose there, hold "
       "leaves it to the regularisers (no observation carries evidence; docs/results.md)",
       0, 0, &stage2_unobserved_names, [](const C& c) { return c.stage2.hold_unobserved ? 1.0 : 0.0; },
       [](C& c, double v) { c.stage2.hold_unobserved = v == 1.0; }},
      {"unit", K::number, "node selection unit in metres", 0.005, 1.0, nullptr,
       [](const C& c) { return c.nodes.unit; }, [](C& c, double v) { c.nodes.unit = v; }},
      {"lambda-depth", K::number, "weight of the expected-depth L1 loss", 0.0, 100.0, nullptr,
       [](const C& c) { return c.stage2.lambda_depth; }, [](C& c, double v) { c.stage2.lambda_depth = v; }},
      {"w-data", K::number, "weight of the node data term", 0.0, 1e6, nullptr,
       [](const C& c) { return c.node_loss.data_weight; }, [](C& c, double v) { c.node_loss.data_weight = v; }},
      {"w-rigidity", K::number, "weight of the rigidity term, ARAP or C-ARAP", 0.0, 1e6, nullptr,
       [](const C& c) { return c.node_loss.regularizers.carap.weight; },
       [](C& c, double v) { c.node_loss.regularizers.carap.weight = c.node_loss.regularizers.arap.weight = v; }},
      {"w-lrm", K::number, "weight of the LRM term", 0.0, 1e6, nullptr,
       [](const C& c) { return c.node_loss.regularizers.lrm.weight; },
       [](C& c, double v) { c.node_loss.regularizers.lrm.weight = v; }},
      {"w-accel", K::number, "weight of trajectory smoothness (squared node accelerations, E21, as MoSca and Shape-of-Motion); 0 = off", 0.0, 1e6, nullptr,
       [](const C& c) { return c.node_loss.regularizers.accel.weight; },
       [](C& c, double v) { c.node_loss.regularizers.accel.weight = v; }},
      {"alpha", K::number, "confidence floor alpha of C-ARAP and LRM, E7; 1 makes C-ARAP plain ARAP", 0.0, 1.0,
       nullptr, [](const C& c) { return c.node_loss.regularizers.carap.alpha; },
       [](C& c, double v) { c.node_loss.regularizers.carap.alpha = c.node_loss.regularizers.lrm.alpha = v; }},
      {"carap-reading", K::choice,
       "how C-ARAP moves the nodes: symmetric is the gradient of E9, directed lets term i-j move node i only "
       "(E20, docs/results.md)",
       0, 0, &carap_reading_names, [](const C& c) { return static_cast<double>(c.node_loss.carap_reading); },
       [](C& c, double v) { c.node_loss.carap_reading = static_cast<CarapReading>(as_index(v)); }},
      {"confidence-from", K::choice,
       "trajectories the confidences E6 are computed from: estimate (the current one), lifted (stage 1's start, "
       "once) or truth (procedural ground truth, an oracle)",
       0, 0, &confidence_source_names, [](const C& c) { return static_cast<double>(c.node_loss.confidence_source); },
       [](C& c, double v) { c.node_loss.confidence_source = static_cast<ConfidenceSource>(as_index(v)); }},
      {"confidence-visibility", K::choice,
       "off leaves out E6's visibility factor, as if every sample were observed", 0, 0, &on_off_names,
       [](const C& c) { return c.node_loss.confidence_visibility ? 0.0 : 1.0; },
       [](C& c, double v) { c.node_loss.confidence_visibility = v == 0.0; }},
      {"export-case", K::text,
       "write the stage-1 problem (lifted node tracks, visibility, ground truth, rotations, graph: .npy + "
       "case.json) into this folder and exit without training",
       0, 0, nullptr, nullptr, nullptr, "", true},
      {"data", K::text,
       "train on this scene folder (Dycheck iPhone layout plus priors/, Shape-of-Motion's flow3d_preprocessed/ "
       "or MoSca's layout, detected; docs/data.md) instead of the generated scene"},
      {"track-queries", K::text, "with --data: query pixels (Q.json) whose 3D tracks go to OUT/tracks3d.npy"},
      {"track-truth", K::text, "with --track-queries: true tracks [M][T][3] (.npy) to report the 3D EPE against"},
      {"export-dycheck", K::text,
       "write the generated scene in the Dycheck layout (docs/data.md) into this folder, with queries.json and "
       "their true tracks queries_tracks3d.npy, and exit",
       0, 0, nullptr, nullptr, nullptr, "", true},
      {"export-layout", K::choice,
       "with --export-dycheck: the layout written, som = Shape-of-Motion's, mosca = MoSca's, docs/data.md", 0, 0,
       &export_layout_names, nullptr, nullptr, "dycheck"},
      {"no-pictures", K::flag, "skip the PNG output"},
      {"no-view", K::flag, "skip OUT/view.html, the page of the run (docs/trainer.md)"},
      {"no-image-eval", K::flag, "skip rendering after stage 2 (and so the pictures, view.html and renders): metrics.json keeps the 3D errors only (for studies)"},
      {"ply", K::flag,
       "write OUT/ply/frame_<t>.ply for every frame t: the trained Gaussians at t in the 3DGS PLY layout "
       "(docs/trainer.md, \"Per-frame PLY\"); on by default with --quick"},
      {"no-ply", K::flag, "with --quick: skip OUT/ply/"},
      {"quiet", K::flag, "no progress lines"},
      {"help", K::flag, "print this help"}};
  return table;
}

std::string setting_default(const Setting& s, bool quick) {
  if (!s.get) return s.fixed_default;
  const double v = s.get(default_config(quick));
  if (s.kind == K::choice) return s.choices()[as_index(v)];
  return format_value(s.kind, v);
}

std::vector<cli::FlagSpec> setting_flags() {
  std::vector<cli::FlagSpec> out;
  for (const Setting& s : settings()) {
    std::string help = s.help;
    std::string notes;
    if (s.kind == K::choice) notes = join(s.choices());
    if (s.kind == K::integer || s.kind == K::number)
      notes = "in [" + format_value(s.kind, s.lo) + ", " + format_value(s.kind, s.hi) + "]";
    const std::string d = setting_default(s, false), dq = setting_default(s, true);
    if (!d.empty()) notes += (notes.empty() ? "" : "; ") + std::string("default ") + d;
    if (dq != d) notes += ", quick " + dq;
    if (s.generated_only) notes += (notes.empty() ? "" : "; ") + std::string("not with --data");
    if (!notes.empty()) help += " (" + notes + ")";
    // Only flags outside TrainerConfig carry their default into cli::Args (read with args.get);
    // a config setting is applied only when given, so that default_config stays the one source.
    out.push_back({s.name, s.get ? "" : s.fixed_default, help, s.kind == K::flag});
  }
  return out;
}

void apply_settings(const cli::Args& args, TrainerConfig* config) {
  for (const Setting& s : settings()) {
    if (!s.set || !args.given(s.name)) continue;
    double v = 0;
    switch (s.kind) {
      case K::integer: v = static_cast<double>(flags::int_in(args, s.name, static_cast<long long>(s.lo),
                                                             static_cast<long long>(s.hi)));
        break;
      case K::number: v = flags::double_in(args, s.name, s.lo, s.hi); break;
      case K::choice: v = index_of(args.get_choice(s.name, s.choices()), s.choices()); break;
      case K::text:
      case K::flag: continue;
    }
    s.set(*config, v);
  }
}

}  // namespace trainer
