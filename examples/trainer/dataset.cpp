// examples/trainer/dataset.cpp — scene + ground truth + priors in one call, timed.
#include "trainer/dataset.hpp"

#include <chrono>
#include <stdexcept>

#include "trainer/dycheck.hpp"
#include "trainer/progress.hpp"
#include "trainer/util.hpp"

namespace trainer {

void apply_scene_layout(SceneLayout layout, DatasetConfig* config) {
  config->scene.layout = layout;
  const PriorConfig defaults;
  config->priors.moving_depth_factor = layout == SceneLayout::occluder ? 3.0 : defaults.moving_depth_factor;
  config->priors.depth_edge_outlier_rate = layout == SceneLayout::occluder ? 0.45 : defaults.depth_edge_outlier_rate;
}

Dataset make_dataset(const DatasetConfig& config, smg::ParallelOptions parallel) {
  if (smg::Status st = validate_scene_config(config.scene); !st) throw std::invalid_argument(st.message());
  if (smg::Status st = validate_prior_config(config.priors); !st) throw std::invalid_argument(st.message());
  if (config.supersample < 1 || config.supersample > 8)
    throw std::invalid_argument("dataset: supersample must be in [1, 8]");
  if (config.covisible_min_frames < 1) throw std::invalid_argument("dataset: covisible_min_frames must be >= 1");
  const auto start = std::chrono::steady_clock::now();
  Dataset d;
  GroundTruth& g = d.truth.emplace();
  auto t0 = std::chrono::steady_clock::now();
  g.scene = make_scene(config.scene);
  d.seconds.scene = seconds_since(t0);

  RenderOptions ro;
  ro.supersample = config.supersample;
  ro.parallel = parallel;
  t0 = std::chrono::steady_clock::now();
  g.train = render_training_view(g.scene, ro);
  d.seconds.render_train = seconds_since(t0);

  ro.surface_points = config.covisibility;
  t0 = std::chrono::steady_clock::now();
  for (int v = 0; v < static_cast<int>(g.scene.test_cameras.size()); ++v) g.test.push_back(render_test_view(g.scene, v, ro));
  d.seconds.render_test = seconds_since(t0);

  if (config.covisibility) {
    t0 = std::chrono::steady_clock::now();
    for (const auto& view : g.test) g.test_covisible.push_back(covisibility_mask(g.scene, view, config.covisible_min_frames, parallel));
    d.seconds.covisibility = seconds_since(t0);
  }

  t0 = std::chrono::steady_clock::now();
  const PriorConfig priors =
      config.tracker_failures == TrackerFailures::scene
          ? config.priors
          : tracker_failures(config.priors, static_cast<double>(static_cast<int>(config.tracker_failures) - 1));
  d.priors = make_priors(g.scene, g.train, priors, parallel);
  d.seconds.priors = seconds_since(t0);

  // The sequence every stage reads: the training camera's views and images (copies of the
  // truth renders' colour), the scene's extent and seed.
  d.width = g.scene.width();
  d.height = g.scene.height();
  d.cameras = g.scene.train_cameras;
  for (int t = 0; t < g.scene.frames(); ++t) {
    d.images.push_back(g.train[sz(t)].rgb);
    d.time_ids.push_back(t);
    d.frame_names.push_back(dycheck_frame_name(0, t));
  }
  d.extent = g.scene.extent;
  d.seed = g.scene.config.seed;
  d.seconds.total = seconds_since(start);
  return d;
}

}  // namespace trainer
