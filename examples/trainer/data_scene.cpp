// examples/trainer/data_scene.cpp — a scene from disk in the trainer (data_scene.hpp).
#include "trainer/data_scene.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <utility>

#include "json_read.hpp"
#include "trainer/dycheck_metrics.hpp"
#include "trainer/progress.hpp"
#include "trainer/util.hpp"

namespace trainer {

namespace {

std::string frame_name(int camera, int time) {
  std::array<char, 32> b{};
  std::snprintf(b.data(), b.size(), "%d_%05d", camera, time);
  return b.data();
}

}  // namespace

Dataset dataset_from_dycheck(DycheckScene&& s) {
  const int T = s.frames(), W = s.width, H = s.height;
  if (T < 2) throw DataError("splits/train.json: at least 2 training frames are needed, got " + std::to_string(T));
  Dataset d;
  d.has_truth = false;
  d.source = s.root;
  d.scene.config.frames = T;
  d.scene.config.width = W;
  d.scene.config.height = H;
  d.scene.train_cameras = std::move(s.train_cameras);
  for (const DycheckFrame& f : s.train) {
    d.time_ids.push_back(f.time);
    d.frame_names.push_back(f.name);
  }
  d.train.resize(sz(T));
  for (int t = 0; t < T; ++t) {
    RenderOutput& o = d.train[sz(t)];
    o.width = W;
    o.height = H;
    o.rgb = std::move(s.train_rgb[sz(t)]);
  }

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

DataEvaluation evaluate_frames(const Dataset& d, const Nodes& nodes, const GaussianModel<float>& model,
                               smg::ParallelOptions parallel, std::vector<Image>* renders) {
  const auto t0 = std::chrono::steady_clock::now();
  DataEvaluation ev;
  NodeState<float> ns;
  ns.assign(nodes);
  ModelRenderer<float> renderer;
  if (renders) renders->clear();
  for (const EvalFrame& f : d.eval) {
    Image img(f.camera.width, f.camera.height, 3);
    renderer.render(model, ns, f.frame, splat_camera<float>(f.camera), img.data(), nullptr, nullptr, parallel);
    for (float& v : img.pixels) v = std::clamp(v, 0.0f, 1.0f);
    const DycheckImageMetrics m = dycheck_image_metrics(f.rgb, img, f.covisible);
    FrameScore s;
    s.name = f.name;
    s.mpsnr = m.mpsnr;
    s.mssim = m.mssim;
    s.mssim_covisible = m.mssim_covisible;
    s.psnr = m.psnr;
    s.ssim = m.ssim;
    ev.frames.push_back(s);
    if (renders) renders->push_back(std::move(img));
  }
  const double V = std::max<double>(1.0, static_cast<double>(ev.frames.size()));
  ev.mean.name = "mean";
  int covisible_frames = 0;
  for (const FrameScore& s : ev.frames) {
    ev.mean.mpsnr += s.mpsnr / V;
    ev.mean.mssim += s.mssim / V;
    ev.mean.psnr += s.psnr / V;
    ev.mean.ssim += s.ssim / V;
    // NaN where a frame has no covisible pixel: left out of that mean only.
    if (std::isfinite(s.mssim_covisible)) {
      ev.mean.mssim_covisible += s.mssim_covisible;
      ++covisible_frames;
    }
  }
  ev.mean.mssim_covisible = covisible_frames > 0 ? ev.mean.mssim_covisible / covisible_frames : 0.0;
  ev.seconds = seconds_since(t0);
  return ev;
}

TrackQueries read_track_queries(const std::string& path, const Dataset& d) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw DataError(path + ": cannot open");
  std::stringstream ss;
  ss << f.rdbuf();
  TrackQueries q;
  try {
    const json::Value root = json::parse(ss.str());
    const json::Value& frame = json::get(root, "frame");
    if (!frame.is_string()) throw json::Error("'frame' is not a string");
    q.frame = frame.string;
    const json::Value& pts = json::get(root, "xy_2x");
    if (!pts.is_array()) throw json::Error("'xy_2x' is not an array");
    for (std::size_t i = 0; i < pts.items.size(); ++i) {
      const json::Value& p = pts.items[i];
      if (!p.is_array() || p.items.size() != 2 || !p.items[0].is_number() || !p.items[1].is_number())
        throw json::Error("xy_2x[" + std::to_string(i) + "] is not [x, y]");
      q.xy.push_back(p.items[0].number);
      q.xy.push_back(p.items[1].number);
    }
  } catch (const json::Error& e) {
    throw DataError(path + ": " + e.what());
  }
  const auto it = std::find(d.frame_names.begin(), d.frame_names.end(), q.frame);
  if (it == d.frame_names.end()) throw DataError(path + ": frame '" + q.frame + "' is not a training frame");
  if (q.count() == 0) throw DataError(path + ": xy_2x is empty");
  const int W = d.scene.width(), H = d.scene.height();
  for (int i = 0; i < q.count(); ++i) {
    const double x = q.xy[sz(i) * 2], y = q.xy[sz(i) * 2 + 1];
    if (!(x >= 0 && x < W && y >= 0 && y < H))
      throw DataError(path + ": xy_2x[" + std::to_string(i) + "] is outside the " + std::to_string(W) + "x" +
                      std::to_string(H) + " image");
  }
  return q;
}

void write_track_queries(const std::string& path, const TrackQueries& q) {
  std::ofstream f(path);
  f << "{\"frame\": \"" << q.frame << "\", \"xy_2x\": [";
  std::array<char, 64> b{};
  for (int i = 0; i < q.count(); ++i) {
    std::snprintf(b.data(), b.size(), "%s[%.9g, %.9g]", i ? ", " : "", q.xy[sz(i) * 2], q.xy[sz(i) * 2 + 1]);
    f << b.data();
  }
  f << "]}\n";
  if (!f) throw DataError(path + ": cannot write");
}

std::vector<float> carry_queries(const TrackQueries& q, const Dataset& d, const Nodes& nodes,
                                 const GaussianModel<float>& model, smg::ParallelOptions parallel) {
  const int T = d.scene.frames(), W = d.scene.width(), H = d.scene.height(), M = q.count(), N = nodes.count;
  const int t = static_cast<int>(std::find(d.frame_names.begin(), d.frame_names.end(), q.frame) - d.frame_names.begin());
  if (t >= T) throw DataError("queries: frame '" + q.frame + "' is not a training frame");
  const Camera& cam = d.scene.train_cameras[sz(t)];
  NodeState<float> ns;
  ns.assign(nodes);
  // The model's depth at the query frame, for queries where the sensor has none.
  std::vector<float> rendered(sz(W) * H), image(sz(W) * H * 3);
  ModelRenderer<float> renderer;
  renderer.render(model, ns, t, splat_camera<float>(cam), image.data(), nullptr, rendered.data(), parallel);

  std::vector<float> points(sz(M) * 3), quats(sz(M) * 4, 0.0f);
  std::vector<std::int32_t> anchor(sz(M)), t_ref(sz(M), t);
  for (int i = 0; i < M; ++i) {
    const Eigen::Vector2d uv(q.xy[sz(i) * 2], q.xy[sz(i) * 2 + 1]);
    const std::size_t pix = sz(std::min(static_cast<int>(uv.y()), H - 1)) * W + sz(std::min(static_cast<int>(uv.x()), W - 1));
    double z = d.priors.depth[sz(t) * W * H + pix];
    if (!(z > 0)) z = rendered[pix];
    const Eigen::Vector3d p = cam.unproject(uv, z > 0 ? z : 1e-3);
    int best = 0;
    double best_d2 = std::numeric_limits<double>::infinity();
    for (int k = 0; k < N; ++k) {
      const double d2 = (Eigen::Map<const Eigen::Vector3d>(nodes.positions.data() + (sz(t) * N + k) * 3) - p).squaredNorm();
      if (d2 < best_d2) {
        best_d2 = d2;
        best = k;
      }
    }
    anchor[sz(i)] = best;
    for (int c = 0; c < 3; ++c) points[sz(i) * 3 + sz(c)] = static_cast<float>(p(c));
    quats[sz(i) * 4] = 1.0f;
  }
  const smg::NeighborsView<double> graph = nodes.graph.view();
  const int D = static_cast<int>(smg::skin_driver_width(graph));
  std::vector<std::int32_t> drivers(sz(M) * D, -1);
  std::vector<float> weights(sz(M) * D, 0.0f);
  const smg::SkinIndexView anchors(anchor.data(), M);
  smg::TableView<std::int32_t, Eigen::Dynamic> dv(drivers.data(), M, D);
  check(smg::validate_skin_drivers(graph, anchors, N, dv), "skin_drivers");
  smg::skin_drivers(graph, anchors, dv, parallel);
  const smg::PositionsView<const float> x(ns.positions.data(), T, N);
  const smg::SkinDriversView dcv(drivers.data(), M, D);
  const smg::SkinIndexView tr(t_ref.data(), M);
  const smg::TableView<const float, 3> pv(points.data(), M);
  const smg::TableView<const float, 1> sigma(model.skin.sigma.data(), N);
  smg::TableView<float, Eigen::Dynamic> wv(weights.data(), M, D);
  check(smg::validate_skinning_weights<float>(x, dcv, tr, pv, sigma, wv), "skinning_weights");
  smg::skinning_weights<float>(x, dcv, tr, pv, sigma, wv, parallel);

  smg::SkinPoints<float> pts;
  pts.drivers = dcv;
  pts.weights = smg::TableView<const float, Eigen::Dynamic>(weights.data(), M, D);
  pts.t_ref = tr;
  pts.positions = pv;
  pts.quaternions = smg::TableView<const float, 4>(quats.data(), M);
  std::vector<std::int32_t> times(sz(T));
  for (int f = 0; f < T; ++f) times[sz(f)] = f;
  const smg::SkinIndexView t_query(times.data(), T);
  std::vector<float> pos(sz(T) * M * 3), rot(sz(T) * M * 4);  // [T][M][...]
  smg::SkinBlendOutputs<float> out;
  out.positions = smg::SequenceView<float, 3>(pos.data(), T, M);
  out.quaternions = smg::SequenceView<float, 4>(rot.data(), T, M);
  check(smg::validate_skin_blend(ns.skin_nodes(), pts, t_query, out), "skin_blend");
  smg::SkinOptions so;
  so.parallel = parallel;
  smg::skin_blend(ns.skin_nodes(), pts, t_query, out, so);
  std::vector<float> result(sz(M) * T * 3);  // [M][T][3], the layout of tracks3d.npy
  for (int f = 0; f < T; ++f)
    for (int i = 0; i < M; ++i)
      for (int c = 0; c < 3; ++c) result[(sz(i) * T + f) * 3 + c] = pos[(sz(f) * M + i) * 3 + c];
  return result;
}

QueryTrackError query_track_error(const std::vector<float>& est, const std::vector<float>& truth) {
  QueryTrackError e;
  const std::size_t n = std::min(est.size(), truth.size()) / 3;
  if (n == 0) return e;
  for (std::size_t s = 0; s < n; ++s) {
    const double dx = est[s * 3] - truth[s * 3], dy = est[s * 3 + 1] - truth[s * 3 + 1],
                 dz = est[s * 3 + 2] - truth[s * 3 + 2];
    const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
    e.epe += r;
    e.within_5cm += r < 0.05 ? 1 : 0;
    e.within_10cm += r < 0.10 ? 1 : 0;
  }
  e.epe /= static_cast<double>(n);
  e.within_5cm /= static_cast<double>(n);
  e.within_10cm /= static_cast<double>(n);
  return e;
}

DycheckScene to_dycheck(const Dataset& d, int val_gap, int cell) {
  const Scene& sc = d.scene;
  const int T = sc.frames(), W = sc.width(), H = sc.height();
  if (!d.has_truth || d.test.size() != sc.test_cameras.size() || d.test_covisible.size() != d.test.size())
    throw std::invalid_argument("to_dycheck: needs the procedural dataset with test views and covisibility");
  if (cell < 1 || W % cell != 0 || H % cell != 0)
    throw std::invalid_argument("to_dycheck: feature_cell must divide the image size");
  DycheckScene s;
  s.width = W;
  s.height = H;
  const std::size_t plane = sz(W) * H;
  for (int t = 0; t < T; ++t) {
    s.train.push_back({frame_name(0, t), 0, t});
    s.train_cameras.push_back(sc.train_cameras[sz(t)]);
    s.train_rgb.push_back(d.train[sz(t)].rgb);
  }
  s.depth = d.priors.depth;
  for (int v = 0; v < static_cast<int>(d.test.size()); ++v)
    for (int t = 0; t < T; ++t) {
      if (val_gap > 0 && t % val_gap == val_gap - 1) continue;
      s.val.push_back({frame_name(v + 1, t), v + 1, t});
      s.val_cameras.push_back(sc.test_cameras[sz(v)]);
      s.val_rgb.push_back(d.test[sz(v)][sz(t)].rgb);
      const std::uint8_t* m = d.test_covisible[sz(v)].data() + sz(t) * plane;
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

void export_queries(const Dataset& d, int count, TrackQueries* q, std::vector<float>* truth) {
  const Tracks& tr = d.priors.tracks;
  const int T = tr.frames, N = tr.count;
  std::vector<int> picked;
  for (int i = 0; i < N; ++i) {
    const int b = tr.body[sz(i)];
    // Any object track truly visible at frame 0 (its true pixel there is the query).
    if (!tr.visible_true[sz(i)] || b < 0 || !d.scene.bodies[sz(b)].foreground) continue;
    picked.push_back(i);
  }
  // Spread the choice over the candidates (they are in track order).
  const int M = std::min(count, static_cast<int>(picked.size()));
  std::vector<int> chosen;
  chosen.reserve(sz(M));
  for (int k = 0; k < M; ++k) chosen.push_back(picked[sz(k) * picked.size() / sz(M)]);
  q->frame = frame_name(0, 0);
  q->xy.clear();
  truth->assign(sz(M) * T * 3, 0.0f);
  for (int k = 0; k < M; ++k) {
    const int i = chosen[sz(k)];
    q->xy.push_back(tr.uv_true[sz(i) * 2]);
    q->xy.push_back(tr.uv_true[sz(i) * 2 + 1]);
    for (int t = 0; t < T; ++t)
      for (int c = 0; c < 3; ++c)
        (*truth)[(sz(k) * T + t) * 3 + c] = static_cast<float>(tr.positions_true[(sz(t) * N + i) * 3 + c]);
  }
}

}  // namespace trainer
