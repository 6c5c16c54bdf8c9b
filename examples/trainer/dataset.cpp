// examples/trainer/dataset.cpp — scene + ground truth + priors in one call, timed.
#include "trainer/dataset.hpp"

#include <chrono>
#include <stdexcept>

#include "trainer/progress.hpp"

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
  auto t0 = std::chrono::steady_clock::now();
  d.scene = make_scene(config.scene);
  d.seconds.scene = seconds_since(t0);

  RenderOptions ro;
  ro.supersample = config.supersample;
  ro.parallel = parallel;
  t0 = std::chrono::steady_clock::now();
  d.train = render_training_view(d.scene, ro);
  d.seconds.render_train = seconds_since(t0);

  ro.surface_points = config.covisibility;
  t0 = std::chrono::steady_clock::now();
  for (int v = 0; v < static_cast<int>(d.scene.test_cameras.size()); ++v) d.test.push_back(render_test_view(d.scene, v, ro));
  d.seconds.render_test = seconds_since(t0);

  if (config.covisibility) {
    t0 = std::chrono::steady_clock::now();
    for (const auto& view : d.test) d.test_covisible.push_back(covisibility_mask(d.scene, view, config.covisible_min_frames, parallel));
    d.seconds.covisibility = seconds_since(t0);
  }

  t0 = std::chrono::steady_clock::now();
  const PriorConfig priors =
      config.tracker_failures == TrackerFailures::scene
          ? config.priors
          : tracker_failures(config.priors, static_cast<double>(static_cast<int>(config.tracker_failures) - 1));
  d.priors = make_priors(d.scene, d.train, priors, parallel);
  d.seconds.priors = seconds_since(t0);
  d.seconds.total = seconds_since(start);
  return d;
}

}  // namespace trainer
