// examples/trainer/data_export.cpp — the procedural dataset in the Dycheck layout (data_export.hpp).
#include "trainer/data_export.hpp"

#include <algorithm>
#include <stdexcept>

#include "trainer/util.hpp"

namespace trainer {

DycheckScene to_dycheck(const Dataset& d, int val_gap, int cell) {
  const GroundTruth& g = need_truth(d, "to_dycheck");
  if (g.test.size() != g.scene.test_cameras.size() || g.test_covisible.size() != g.test.size())
    throw std::invalid_argument("to_dycheck: needs the procedural dataset with test views and covisibility");
  const Scene& sc = g.scene;
  const int T = d.frames(), W = d.width, H = d.height;
  if (cell < 1 || W % cell != 0 || H % cell != 0)
    throw std::invalid_argument("to_dycheck: feature_cell must divide the image size");
  DycheckScene s;
  s.width = W;
  s.height = H;
  const std::size_t plane = sz(W) * H;
  for (int t = 0; t < T; ++t) {
    s.train.push_back({dycheck_frame_name(0, t), 0, t});
    s.train_cameras.push_back(d.cameras[sz(t)]);
    s.train_rgb.push_back(d.images[sz(t)]);
  }
  s.depth = d.priors.depth;
  for (int v = 0; v < static_cast<int>(g.test.size()); ++v)
    for (int t = 0; t < T; ++t) {
      if (val_gap > 0 && t % val_gap == val_gap - 1) continue;
      s.val.push_back({dycheck_frame_name(v + 1, t), v + 1, t});
      s.val_cameras.push_back(sc.test_cameras[sz(v)]);
      s.val_rgb.push_back(g.test[sz(v)][sz(t)].rgb);
      const std::uint8_t* m = g.test_covisible[sz(v)].data() + sz(t) * plane;
      s.val_covisible.emplace_back(m, m + plane);
    }
  const Tracks& tr = d.priors.tracks;
  s.tracks.count = tr.count;
  s.tracks.frames = T;
  s.tracks.uv.assign(tr.uv.begin(), tr.uv.end());
  s.tracks.visible = tr.visible;
  s.tracks.query_t.assign(tr.query_frame.begin(), tr.query_frame.end());
  s.dynamic_mask = d.priors.object_mask;
  s.has_mask.assign(sz(T), 1);
  // Feature maps on the coarse grid: the per-pixel maps sampled at the cell centres.
  const int w = W / cell, h = H / cell, C = d.priors.feature_dim;
  s.feature_width = w;
  s.feature_height = h;
  s.feature_dim = C;
  s.features.assign(sz(T) * w * h * C, 0.0f);
  std::vector<double> f(sz(C));
  for (int t = 0; t < T; ++t)
    for (int a = 0; a < h; ++a)
      for (int b = 0; b < w; ++b) {
        sample_features(d.priors, t, (b + 0.5) * cell, (a + 0.5) * cell, f.data());
        for (int c = 0; c < C; ++c) s.features[((sz(t) * h + a) * w + b) * C + c] = static_cast<float>(f[sz(c)]);
      }
  s.has_features.assign(sz(T), 1);
  return s;
}

QuerySet export_query_set(const Dataset& d, int count) {
  const GroundTruth& g = need_truth(d, "export_queries");  // the true tracks and the bodies
  const Tracks& tr = d.priors.tracks;
  const int T = tr.frames, N = tr.count;
  std::vector<int> picked;
  for (int i = 0; i < N; ++i) {
    const int b = tr.body[sz(i)];
    // Any object track truly visible at frame 0 (its true pixel there is the query).
    if (!tr.visible_true[sz(i)] || b < 0 || !g.scene.bodies[sz(b)].foreground) continue;
    picked.push_back(i);
  }
  // Spread the choice over the candidates (they are in track order).
  const int M = std::min(count, static_cast<int>(picked.size()));
  std::vector<int> chosen;
  chosen.reserve(sz(M));
  for (int k = 0; k < M; ++k) chosen.push_back(picked[sz(k) * picked.size() / sz(M)]);
  QuerySet s;
  s.queries.frame = dycheck_frame_name(0, 0);
  s.truth.assign(sz(M) * T * 3, 0.0f);
  s.semantic_class.assign(sz(M), 0);
  s.visible.assign(sz(M) * T, 0);
  for (int k = 0; k < M; ++k) {
    const int i = chosen[sz(k)];
    s.queries.xy.push_back(tr.uv_true[sz(i) * 2]);
    s.queries.xy.push_back(tr.uv_true[sz(i) * 2 + 1]);
    s.semantic_class[sz(k)] = g.scene.bodies[sz(tr.body[sz(i)])].semantic_class;
    for (int t = 0; t < T; ++t) {
      s.visible[sz(k) * T + sz(t)] = tr.visible_true[sz(t) * N + i];
      for (int c = 0; c < 3; ++c)
        s.truth[(sz(k) * T + t) * 3 + c] = static_cast<float>(tr.positions_true[(sz(t) * N + i) * 3 + c]);
    }
  }
  return s;
}

void export_queries(const Dataset& d, int count, TrackQueries* q, std::vector<float>* truth) {
  QuerySet s = export_query_set(d, count);
  *q = std::move(s.queries);
  *truth = std::move(s.truth);
}

}  // namespace trainer
