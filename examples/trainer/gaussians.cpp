// examples/trainer/gaussians.cpp — stage-2 model: init, render + backward with DQB, pruning.
#include "trainer/gaussians.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "trainer/progress.hpp"
#include "trainer/util.hpp"

namespace trainer {

namespace {

using Clock = std::chrono::steady_clock;

template <class S>
void keep_rows(std::vector<S>& v, const std::vector<std::uint8_t>& keep, std::size_t width) {
  std::size_t w = 0;
  for (std::size_t r = 0; r < keep.size(); ++r) {
    if (!keep[r]) continue;
    if (w != r) std::copy(v.begin() + static_cast<long>(r * width), v.begin() + static_cast<long>((r + 1) * width),
                          v.begin() + static_cast<long>(w * width));
    ++w;
  }
  v.resize(w * width);
}

}  // namespace

template <class S>
void GaussianTable<S>::resize(int G) {
  means.resize(sz(G) * 3);
  quats.resize(sz(G) * 4);
  log_scales.resize(sz(G) * 3);
  opacity.resize(sz(G));
  colors.resize(sz(G) * 3);
}

template <class S>
void GaussianTable<S>::fill(S value) {
  for (auto* v : {&means, &quats, &log_scales, &opacity, &colors}) std::fill(v->begin(), v->end(), value);
}

template <class S>
void GaussianTable<S>::compact(const std::vector<std::uint8_t>& keep) {
  keep_rows(means, keep, 3);
  keep_rows(quats, keep, 4);
  keep_rows(log_scales, keep, 3);
  keep_rows(opacity, keep, 1);
  keep_rows(colors, keep, 3);
}

template <class S>
void GaussianTable<S>::push_row(const GaussianTable& o, int r) {
  const std::size_t R = sz(r);
  means.insert(means.end(), o.means.begin() + static_cast<long>(3 * R), o.means.begin() + static_cast<long>(3 * R + 3));
  quats.insert(quats.end(), o.quats.begin() + static_cast<long>(4 * R), o.quats.begin() + static_cast<long>(4 * R + 4));
  log_scales.insert(log_scales.end(), o.log_scales.begin() + static_cast<long>(3 * R),
                    o.log_scales.begin() + static_cast<long>(3 * R + 3));
  opacity.push_back(o.opacity[R]);
  colors.insert(colors.end(), o.colors.begin() + static_cast<long>(3 * R), o.colors.begin() + static_cast<long>(3 * R + 3));
}

template <class S>
void NodeState<S>::assign(const Nodes& n) {
  frames = n.frames;
  count = n.count;
  positions.resize(n.positions.size());
  rotations.resize(n.rotations.size());
  for (std::size_t k = 0; k < n.positions.size(); ++k) positions[k] = static_cast<S>(n.positions[k]);
  for (std::size_t k = 0; k < n.rotations.size(); ++k) rotations[k] = static_cast<S>(n.rotations[k]);
}

template <class S>
void ModelGrads<S>::zero(int G, int T, int N) {
  table.resize(G);
  table.fill(S(0));
  node_positions.assign(sz(T) * N * 3, S(0));
  node_rotations.assign(sz(T) * N * 3, S(0));
}

template <class S>
smg::splat::Camera<S> splat_camera(const Camera& c) {
  smg::splat::Camera<S> s;
  s.viewmat = c.world_to_camera.cast<S>();
  s.fx = static_cast<S>(c.fx);
  s.fy = static_cast<S>(c.fy);
  s.cx = static_cast<S>(c.cx);
  s.cy = static_cast<S>(c.cy);
  s.width = c.width;
  s.height = c.height;
  return s;
}

template <class S>
GaussianModel<S> init_model(const Dataset& d, const Nodes& nodes, const InitOptions& o, smg::ParallelOptions parallel) {
  const int W = d.width, H = d.height, T = d.frames();
  const std::size_t plane = sz(W) * H;
  GaussianModel<S> m;
  GaussianTable<S>& g = m.table;
  auto add = [&](const Eigen::Vector3d& p, const float* rgb, double sigma) {
    for (int c = 0; c < 3; ++c) {
      g.means.push_back(static_cast<S>(p(c)));
      g.log_scales.push_back(static_cast<S>(std::log(sigma)));
      g.colors.push_back(static_cast<S>(rgb[c]));
    }
    g.quats.insert(g.quats.end(), {S(1), S(0), S(0), S(0)});
    g.opacity.push_back(static_cast<S>(std::log(o.opacity / (1 - o.opacity))));
  };
  // Every s-th pixel (s = max(1, stride)) of the listed training frames that has a depth value and
  // is (object) or is not (!object) in the object mask: visit(t, point, rgb, sigma).
  auto for_each_sample = [&](const std::vector<int>& frames, int stride, bool object, auto&& visit) {
    const int s = std::max(1, stride);
    for (int t : frames) {
      if (t < 0 || t >= T) continue;
      const Camera& cam = d.cameras[sz(t)];
      for (int y = s / 2; y < H; y += s)
        for (int x = s / 2; x < W; x += s) {
          const std::size_t pix = sz(y) * W + x;
          const float z = d.priors.depth[sz(t) * plane + pix];
          if (z <= 0 || (d.priors.object_mask[sz(t) * plane + pix] != 0) != object) continue;
          visit(t, cam.unproject(Eigen::Vector2d(x + 0.5, y + 0.5), z), &d.images[sz(t)].pixels[pix * 3],
                o.scale * s * z / cam.fx);
        }
    }
  };
  // Static: non-object pixels with a depth value.
  for_each_sample(o.static_frames, o.static_stride, false,
                  [&](int, const Eigen::Vector3d& p, const float* rgb, double sigma) { add(p, rgb, sigma); });
  m.fixed = g.size();
  // Dynamic: object pixels, attached to the nearest node at their frame.
  const int N = nodes.count;
  const double max_d = o.max_anchor_distance * nodes.unit;
  std::vector<std::int32_t> anchor;
  for_each_sample(o.dynamic_frames, o.dynamic_stride, true,
                  [&](int t, const Eigen::Vector3d& p, const float* rgb, double sigma) {
                    int best = -1;
                    double best_d2 = std::numeric_limits<double>::infinity();
                    for (int i = 0; i < N; ++i) {
                      const double d2 =
                          (Eigen::Map<const Eigen::Vector3d>(nodes.positions.data() + (sz(t) * N + i) * 3) - p)
                              .squaredNorm();
                      if (d2 < best_d2) {
                        best_d2 = d2;
                        best = i;
                      }
                    }
                    if (best < 0 || std::sqrt(best_d2) > max_d) return;
                    add(p, rgb, sigma);
                    anchor.push_back(best);
                    m.skin.t_ref.push_back(t);
                  });
  // Drivers (anchor + its graph neighbours) and weights.
  const int P = static_cast<int>(anchor.size());
  const smg::NeighborsView<double> graph = nodes.graph.view();
  m.skin.width = static_cast<int>(smg::skin_driver_width(graph));
  m.skin.drivers.assign(sz(P) * m.skin.width, -1);
  m.skin.weights.assign(sz(P) * m.skin.width, S(0));
  m.skin.sigma.assign(sz(N), static_cast<S>(o.sigma * nodes.unit));
  const smg::SkinIndexView anchors(anchor.data(), P);
  smg::TableView<std::int32_t, Eigen::Dynamic> drivers(m.skin.drivers.data(), P, m.skin.width);
  check(smg::validate_skin_drivers(graph, anchors, N, drivers), "skin_drivers");
  smg::skin_drivers(graph, anchors, drivers, parallel);
  NodeState<S> ns;
  ns.assign(nodes);
  update_skinning_weights(m, ns, parallel);
  return m;
}

template <class S>
void update_skinning_weights(GaussianModel<S>& m, const NodeState<S>& n, smg::ParallelOptions parallel) {
  const int P = m.dynamic(), D = m.skin.width;
  if (P == 0) return;
  const smg::PositionsView<const S> x(n.positions.data(), n.frames, n.count);
  const smg::SkinDriversView drivers(m.skin.drivers.data(), P, D);
  const smg::SkinIndexView t_ref(m.skin.t_ref.data(), P);
  const smg::TableView<const S, 3> points(m.table.means.data() + sz(m.fixed) * 3, P);
  const smg::TableView<const S, 1> sigma(m.skin.sigma.data(), n.count);
  smg::TableView<S, Eigen::Dynamic> w(m.skin.weights.data(), P, D);
  check(smg::validate_skinning_weights<S>(x, drivers, t_ref, points, sigma, w), "skinning_weights");
  smg::skinning_weights<S>(x, drivers, t_ref, points, sigma, w, parallel);
}

template <class S>
smg::splat::GaussianParams<S> ModelRenderer<S>::params(const GaussianModel<S>& m) const {
  const int G = m.count();
  smg::splat::GaussianParams<S> p;
  p.means = smg::TableView<const S, 3>(means_.data(), G);
  p.quats = smg::TableView<const S, 4>(quats_.data(), G);
  p.log_scales = smg::TableView<const S, 3>(m.table.log_scales.data(), G);
  p.opacity_logits = smg::TableView<const S, 1>(m.table.opacity.data(), G);
  p.colors = smg::TableView<const S, Eigen::Dynamic>(m.table.colors.data(), G, 3);
  return p;
}

template <class S>
smg::SkinPoints<S> skin_points(const GaussianModel<S>& m) {
  const int P = m.dynamic(), F = m.fixed, D = m.skin.width;
  smg::SkinPoints<S> pts;
  pts.drivers = smg::SkinDriversView(m.skin.drivers.data(), P, D);
  pts.weights = smg::TableView<const S, Eigen::Dynamic>(m.skin.weights.data(), P, D);
  pts.t_ref = smg::SkinIndexView(m.skin.t_ref.data(), P);
  pts.positions = smg::TableView<const S, 3>(m.table.means.data() + sz(F) * 3, P);
  pts.quaternions = smg::TableView<const S, 4>(m.table.quats.data() + sz(F) * 4, P);
  return pts;
}

template <class S>
void pose_model(const GaussianModel<S>& m, const NodeState<S>& n, int t, std::vector<S>* means, std::vector<S>* quats,
                smg::ParallelOptions parallel) {
  const int G = m.count(), F = m.fixed, P = m.dynamic();
  means->resize(sz(G) * 3);
  quats->resize(sz(G) * 4);
  std::copy(m.table.means.begin(), m.table.means.begin() + static_cast<long>(sz(F) * 3), means->begin());
  std::copy(m.table.quats.begin(), m.table.quats.begin() + static_cast<long>(sz(F) * 4), quats->begin());
  if (P == 0) return;
  const smg::SkinPoints<S> pts = skin_points(m);
  const std::int32_t tq[1] = {t};
  const smg::SkinIndexView t_query(tq, 1);
  smg::SkinBlendOutputs<S> out;
  out.positions = smg::SequenceView<S, 3>(means->data() + sz(F) * 3, 1, P);
  out.quaternions = smg::SequenceView<S, 4>(quats->data() + sz(F) * 4, 1, P);
  check(smg::validate_skin_blend(n.skin_nodes(), pts, t_query, out), "skin_blend");
  smg::skin_blend(n.skin_nodes(), pts, t_query, out, smg::SkinOptions{}, parallel);
}

template <class S>
void ModelRenderer<S>::render(const GaussianModel<S>& m, const NodeState<S>& n, int t,
                              const smg::splat::Camera<S>& cam, S* image, S* alpha, S* depth,
                              smg::ParallelOptions parallel) {
  const auto t0 = Clock::now();
  t_ = t;
  pose_model(m, n, t, &means_, &quats_, parallel);
  const auto t1 = Clock::now();
  times_.skin_forward += std::chrono::duration<double>(t1 - t0).count();
  const smg::splat::GaussianParams<S> p = params(m);
  smg::splat::SplatSettings<S> settings;
  smg::splat::RenderImages<S> img;
  img.image = smg::SequenceView<S, Eigen::Dynamic>(image, cam.height, cam.width, 3);
  if (alpha) img.alpha = smg::SequenceView<S, 1>(alpha, cam.height, cam.width);
  if (depth) img.depth = smg::SequenceView<S, 1>(depth, cam.height, cam.width);
  check(smg::splat::validate_render(p, cam, settings, img, 3), "render_forward");
  smg::splat::render_forward<3>(p, cam, settings, ws_, img, parallel);
  times_.render_forward += seconds_since(t1);
}

template <class S>
void ModelRenderer<S>::backward(const GaussianModel<S>& m, const NodeState<S>& n, const smg::splat::Camera<S>& cam,
                                const S* grad_image, const S* grad_depth, ModelGrads<S>& out,
                                smg::ParallelOptions parallel) {
  const auto t0 = Clock::now();
  const int G = m.count(), F = m.fixed, P = m.dynamic();
  g_.resize(G);
  g_quats_tangent_.resize(sz(G) * 3);
  const smg::splat::GaussianParams<S> p = params(m);
  smg::splat::SplatSettings<S> settings;
  smg::splat::RenderImageGrads<S> gin;
  gin.image = smg::SequenceView<const S, Eigen::Dynamic>(grad_image, cam.height, cam.width, 3);
  if (grad_depth) gin.depth = smg::SequenceView<const S, 1>(grad_depth, cam.height, cam.width);
  smg::splat::GaussianGrads<S> gg;
  gg.means = smg::TableView<S, 3>(g_.means.data(), G);
  gg.quats = smg::TableView<S, 4>(g_.quats.data(), G);
  gg.quats_tangent = smg::TableView<S, 3>(g_quats_tangent_.data(), G);
  gg.log_scales = smg::TableView<S, 3>(g_.log_scales.data(), G);
  gg.opacity_logits = smg::TableView<S, 1>(g_.opacity.data(), G);
  gg.colors = smg::TableView<S, Eigen::Dynamic>(g_.colors.data(), G, 3);
  check(smg::splat::validate_render_backward(p, cam, settings, ws_, gin, gg), "render_backward");
  smg::splat::render_backward<3>(p, cam, settings, ws_, gin, gg, parallel);
  GaussianTable<S>& o = out.table;
  for (std::size_t k = 0; k < sz(G) * 3; ++k) {
    o.log_scales[k] += g_.log_scales[k];
    o.colors[k] += g_.colors[k];
  }
  for (std::size_t k = 0; k < sz(G); ++k) o.opacity[k] += g_.opacity[k];
  for (std::size_t k = 0; k < sz(F) * 3; ++k) o.means[k] += g_.means[k];
  for (std::size_t k = 0; k < sz(F) * 4; ++k) o.quats[k] += g_.quats[k];
  const auto t1 = Clock::now();
  times_.render_backward += std::chrono::duration<double>(t1 - t0).count();
  if (P == 0) return;
  const smg::SkinPoints<S> pts = skin_points(m);
  const std::int32_t tq[1] = {t_};
  const smg::SkinIndexView t_query(tq, 1);
  smg::SkinBlendOutputGradients<S> go;
  go.positions = smg::SequenceView<const S, 3>(g_.means.data() + sz(F) * 3, 1, P);
  go.rotations = smg::SequenceView<const S, 3>(g_quats_tangent_.data() + sz(F) * 3, 1, P);
  smg::SkinBlendGradients<S> gs;
  gs.node_positions = smg::PositionsView<S>(out.node_positions.data(), n.frames, n.count);
  gs.node_rotations = smg::TangentsView<S>(out.node_rotations.data(), n.frames, n.count);
  gs.points = smg::TableView<S, 3>(o.means.data() + sz(F) * 3, P);
  gs.point_quaternions = smg::TableView<S, 4>(o.quats.data() + sz(F) * 4, P);
  check(smg::validate_skin_blend_backward(n.skin_nodes(), pts, t_query, go, gs), "skin_blend_backward");
  smg::skin_blend_backward(n.skin_nodes(), pts, t_query, go, gs, skin_ws_, smg::SkinOptions{}, parallel);
  times_.skin_backward += seconds_since(t1);
}

template <class S>
int prune(GaussianModel<S>& m, double min_opacity, double max_scale, std::vector<std::uint8_t>* keep_out) {
  const int G = m.count();
  std::vector<std::uint8_t> keep(sz(G), 1);
  const double min_logit = std::log(min_opacity / (1 - min_opacity)), max_log_scale = std::log(max_scale);
  int removed = 0, removed_fixed = 0;
  for (int r = 0; r < G; ++r) {
    const S* ls = m.table.log_scales.data() + sz(r) * 3;
    const double big = std::max({static_cast<double>(ls[0]), static_cast<double>(ls[1]), static_cast<double>(ls[2])});
    if (static_cast<double>(m.table.opacity[sz(r)]) < min_logit || big > max_log_scale) {
      keep[sz(r)] = 0;
      ++removed;
      if (r < m.fixed) ++removed_fixed;
    }
  }
  if (removed > 0) {
    m.table.compact(keep);
    const int D = m.skin.width;
    std::vector<std::uint8_t> keep_dyn(keep.begin() + m.fixed, keep.end());
    keep_rows(m.skin.drivers, keep_dyn, sz(D));
    keep_rows(m.skin.weights, keep_dyn, sz(D));
    keep_rows(m.skin.t_ref, keep_dyn, 1);
    m.fixed -= removed_fixed;
  }
  if (keep_out) *keep_out = std::move(keep);
  return removed;
}

#define TRAINER_INSTANTIATE(S)                                                                                  \
  template struct GaussianTable<S>;                                                                             \
  template struct NodeState<S>;                                                                                 \
  template struct ModelGrads<S>;                                                                                \
  template class ModelRenderer<S>;                                                                              \
  template smg::splat::Camera<S> splat_camera<S>(const Camera&);                                                \
  template GaussianModel<S> init_model<S>(const Dataset&, const Nodes&, const InitOptions&, smg::ParallelOptions); \
  template void update_skinning_weights<S>(GaussianModel<S>&, const NodeState<S>&, smg::ParallelOptions);       \
  template smg::SkinPoints<S> skin_points<S>(const GaussianModel<S>&);                                          \
  template void pose_model<S>(const GaussianModel<S>&, const NodeState<S>&, int, std::vector<S>*, std::vector<S>*, \
                              smg::ParallelOptions);                                                            \
  template int prune<S>(GaussianModel<S>&, double, double, std::vector<std::uint8_t>*);
TRAINER_INSTANTIATE(float)
TRAINER_INSTANTIATE(double)
#undef TRAINER_INSTANTIATE

}  // namespace trainer
