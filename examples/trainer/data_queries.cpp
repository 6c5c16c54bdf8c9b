// examples/trainer/data_queries.cpp — 3D query tracks: reading, carrying through time, scoring (data_queries.hpp).
#include "trainer/data_queries.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "json_read.hpp"
#include "trainer/dycheck.hpp"  // DataError
#include "trainer/util.hpp"

namespace trainer {

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
  const int W = d.width, H = d.height;
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
                                 const GaussianModel<float>& model, smg::ParallelOptions parallel,
                                 std::vector<double>* node_weight) {
  const int T = d.frames(), W = d.width, H = d.height, M = q.count(), N = nodes.count;
  const int t = static_cast<int>(std::find(d.frame_names.begin(), d.frame_names.end(), q.frame) - d.frame_names.begin());
  if (t >= T) throw DataError("queries: frame '" + q.frame + "' is not a training frame");
  const Camera& cam = d.cameras[sz(t)];
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
  if (node_weight) {
    node_weight->assign(sz(N), 0.0);
    for (int i = 0; i < M; ++i)
      for (int k = 0; k < D; ++k)
        if (drivers[sz(i) * D + sz(k)] >= 0) (*node_weight)[sz(drivers[sz(i) * D + sz(k)])] += weights[sz(i) * D + sz(k)];
  }

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
  smg::skin_blend(ns.skin_nodes(), pts, t_query, out, smg::SkinOptions{}, parallel);
  std::vector<float> result(sz(M) * T * 3);  // [M][T][3], the layout of tracks3d.npy
  for (int f = 0; f < T; ++f)
    for (int i = 0; i < M; ++i)
      for (int c = 0; c < 3; ++c) result[(sz(i) * T + f) * 3 + c] = pos[(sz(f) * M + i) * 3 + c];
  return result;
}

QueryTrackError query_track_error(const std::vector<float>& est, const std::vector<float>& truth,
                                  const std::vector<std::uint8_t>* mask) {
  QueryTrackError e;
  const std::size_t n = std::min(est.size(), truth.size()) / 3;
  if (mask && mask->size() != n) throw std::invalid_argument("query_track_error: mask must be [M][T] like the tracks");
  for (std::size_t s = 0; s < n; ++s) {
    if (mask && !(*mask)[s]) continue;
    const double dx = est[s * 3] - truth[s * 3], dy = est[s * 3 + 1] - truth[s * 3 + 1],
                 dz = est[s * 3 + 2] - truth[s * 3 + 2];
    const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
    e.epe += r;
    e.within_5cm += r < 0.05 ? 1 : 0;
    e.within_10cm += r < 0.10 ? 1 : 0;
    ++e.samples;
  }
  if (e.samples == 0) {
    e.epe = e.within_5cm = e.within_10cm = std::numeric_limits<double>::quiet_NaN();
    return e;
  }
  const double c = static_cast<double>(e.samples);
  e.epe /= c;
  e.within_5cm /= c;
  e.within_10cm /= c;
  return e;
}

QueryScore score_queries(const QuerySet& set, const Dataset& d, const Nodes& nodes, const GaussianModel<float>& model,
                         smg::ParallelOptions parallel) {
  QueryScore s;
  s.tracks = carry_queries(set.queries, d, nodes, model, parallel, &s.node_weight);
  if (set.truth.empty()) return s;
  const std::size_t M = sz(set.queries.count()), T = sz(d.frames());
  if (set.truth.size() != M * T * 3) throw std::invalid_argument("score_queries: truth must be [M][T][3]");
  s.scored = true;
  s.all = query_track_error(s.tracks, set.truth);
  if (set.visible.size() == M * T) {
    std::vector<std::uint8_t> hidden(set.visible.size());
    for (std::size_t k = 0; k < hidden.size(); ++k) hidden[k] = set.visible[k] ? 0 : 1;
    s.visible = query_track_error(s.tracks, set.truth, &set.visible);
    s.hidden = query_track_error(s.tracks, set.truth, &hidden);
  }
  if (set.semantic_class.size() == M) {
    std::vector<int> classes(set.semantic_class);
    std::sort(classes.begin(), classes.end());
    classes.erase(std::unique(classes.begin(), classes.end()), classes.end());
    for (int c : classes) {
      std::vector<std::uint8_t> mask(M * T, 0);
      for (std::size_t i = 0; i < M; ++i)
        if (set.semantic_class[i] == c) std::fill(mask.begin() + static_cast<std::ptrdiff_t>(i * T),
                                                   mask.begin() + static_cast<std::ptrdiff_t>((i + 1) * T), 1);
      s.by_class.emplace_back(c, query_track_error(s.tracks, set.truth, &mask));
    }
  }
  return s;
}

}  // namespace trainer
