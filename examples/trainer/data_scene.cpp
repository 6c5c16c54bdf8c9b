// examples/trainer/data_scene.cpp — a scene from disk turned into the trainer's Dataset, and its length scale (data_scene.hpp).
#include "trainer/data_scene.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "trainer/util.hpp"

namespace trainer {

Dataset dataset_from_dycheck(DycheckScene&& s) {
  const int T = s.frames(), W = s.width, H = s.height;
  if (T < 2) throw DataError("splits/train.json: at least 2 training frames are needed, got " + std::to_string(T));
  Dataset d;
  d.source = s.root;
  d.width = W;
  d.height = H;
  d.cameras = std::move(s.train_cameras);
  for (const DycheckFrame& f : s.train) {
    d.time_ids.push_back(f.time);
    d.frame_names.push_back(f.name);
  }
  d.images = std::move(s.train_rgb);

  Priors& p = d.priors;
  p.frames = T;
  p.width = W;
  p.height = H;
  p.depth = std::move(s.depth);
  p.object_mask = std::move(s.dynamic_mask);
  p.has_mask = std::move(s.has_mask);
  if (std::none_of(p.has_mask.begin(), p.has_mask.end(), [](std::uint8_t m) { return m != 0; }))
    throw DataError("priors/masks: no training frame has a dynamic mask");
  p.feature_dim = s.feature_dim;
  p.feature_width = s.feature_width;
  p.feature_height = s.feature_height;
  p.features = std::move(s.features);
  p.has_features = std::move(s.has_features);

  // Tracks: reported positions and visibility only. The truth fields stay empty (lift_tracks then
  // leaves LiftedTracks' truth at zero, and nothing reports errors against it).
  Tracks& tr = p.tracks;
  const DycheckTracks& in = s.tracks;
  tr.frames = T;
  tr.count = in.count;
  tr.uv.assign(in.uv.begin(), in.uv.end());
  tr.visible = in.visible;
  tr.query_frame.assign(in.query_t.begin(), in.query_t.end());

  for (std::size_t v = 0; v < s.val.size(); ++v) {
    EvalFrame e;
    e.name = s.val[v].name;
    e.time_id = s.val[v].time;
    e.frame = nearest_frame(d.time_ids, e.time_id);
    e.camera = s.val_cameras[v];
    e.rgb = std::move(s.val_rgb[v]);
    e.covisible = std::move(s.val_covisible[v]);
    d.eval.push_back(std::move(e));
  }
  return d;
}

double lifted_extent(const LiftedTracks& l) {
  std::array<std::vector<double>, 3> axis;
  for (std::size_t s = 0; s < l.visible.size(); ++s) {
    if (!l.visible[s]) continue;
    for (int c = 0; c < 3; ++c) axis[sz(c)].push_back(l.positions[s * 3 + sz(c)]);
  }
  if (axis[0].size() < 16) return 0.0;
  double d2 = 0;
  for (auto& a : axis) {
    // Nearest-rank percentiles; nth_element keeps this O(samples).
    const std::size_t n = a.size(), lo = n * 2 / 100, hi = n - 1 - n * 2 / 100;
    std::nth_element(a.begin(), a.begin() + static_cast<long>(lo), a.end());
    const double vlo = a[lo];
    std::nth_element(a.begin(), a.begin() + static_cast<long>(hi), a.end());
    const double vhi = a[hi];
    d2 += (vhi - vlo) * (vhi - vlo);
  }
  return std::sqrt(d2);
}

int nearest_frame(const std::vector<int>& time_ids, int time_id) {
  int best = 0;
  for (int t = 1; t < static_cast<int>(time_ids.size()); ++t)
    if (std::abs(time_ids[sz(t)] - time_id) < std::abs(time_ids[sz(best)] - time_id)) best = t;
  return best;
}

}  // namespace trainer
