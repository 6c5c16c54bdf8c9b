// tests/splat/splat_scene.hpp — owning storage for small splatting scenes in tests: random
// Gaussians in front of a camera, casts between float and double, one-call render helpers and
// the scalar loss used by the finite-difference checks.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include <doctest/doctest.h>

#include "smg/splat.hpp"
#include "support/random.hpp"

namespace smg::test {

template <class S>
struct SplatScene {
  Index G = 0, C = 3;
  int sh_degree = -1;
  std::vector<S> means, quats, log_scales, logits, colors;

  Index color_cols() const { return sh_degree < 0 ? C : C * splat::sh_basis_count(sh_degree); }
  splat::GaussianParams<S> params() const {
    splat::GaussianParams<S> p;
    p.means = {means.data(), G};
    p.quats = {quats.data(), G};
    p.log_scales = {log_scales.data(), G};
    p.opacity_logits = {logits.data(), G};
    p.colors = {colors.data(), G, color_cols()};
    p.sh_degree = sh_degree;
    return p;
  }
  template <class T>
  SplatScene<T> cast() const {
    SplatScene<T> o;
    o.G = G;
    o.C = C;
    o.sh_degree = sh_degree;
    auto cv = [](const std::vector<S>& v) { return std::vector<T>(v.begin(), v.end()); };
    o.means = cv(means);
    o.quats = cv(quats);
    o.log_scales = cv(log_scales);
    o.logits = cv(logits);
    o.colors = cv(colors);
    return o;
  }
  // All parameters as one flat vector (means, quats, log_scales, logits, colors) and back.
  std::vector<S*> flat() {
    std::vector<S*> out;
    for (auto* v : {&means, &quats, &log_scales, &logits, &colors})
      for (auto& x : *v) out.push_back(&x);
    return out;
  }
  void add(const Vector3<double>& m, const Quaternion<double>& q, const Vector3<double>& ls,
           double logit, const std::vector<double>& col) {
    for (int k = 0; k < 3; ++k) means.push_back(S(m(k)));
    quats.push_back(S(q.w()));
    quats.push_back(S(q.x()));
    quats.push_back(S(q.y()));
    quats.push_back(S(q.z()));
    for (int k = 0; k < 3; ++k) log_scales.push_back(S(ls(k)));
    logits.push_back(S(logit));
    for (double c : col) colors.push_back(S(c));
    ++G;
  }
};

// A camera looking down +z from the origin, rotated by `rot` and shifted by `t` (world ->
// camera), with the principal point at the image centre.
template <class S>
splat::Camera<S> test_camera(int width, int height, double focal,
                             const Quaternion<double>& rot = Quaternion<double>::Identity(),
                             const Vector3<double>& t = Vector3<double>::Zero()) {
  splat::Camera<S> cam;
  Matrix4<double> V = Matrix4<double>::Identity();
  V.topLeftCorner<3, 3>() = rot.toRotationMatrix();
  V.topRightCorner<3, 1>() = t;
  cam.viewmat = V.cast<S>();
  cam.fx = cam.fy = S(focal);
  cam.cx = S(0.5 * width);
  cam.cy = S(0.5 * height);
  cam.width = width;
  cam.height = height;
  return cam;
}

// World point that the camera sees at pixel (u, v) and depth z.
template <class S>
Vector3<double> world_at_pixel(const splat::Camera<S>& cam, double u, double v, double z) {
  const Vector3<double> pc((u - double(cam.cx)) / double(cam.fx) * z,
                           (v - double(cam.cy)) / double(cam.fy) * z, z);
  const Matrix4<double> V = cam.viewmat.template cast<double>();
  return V.topLeftCorner<3, 3>().transpose() * (pc - V.topRightCorner<3, 1>());
}

// n random Gaussians seen by `cam` at depths [z0, z1], projected standard deviation around
// sigma_px pixels, opacities in [o0, o1], colours in [0, 1].
template <class S>
SplatScene<double> random_scene(Rng& rng, const splat::Camera<S>& cam, Index n, Index C,
                                double sigma_px, double z0 = 2.0, double z1 = 5.0,
                                double o0 = 0.2, double o1 = 0.7, double margin = 0.1) {
  SplatScene<double> s;
  s.C = C;
  for (Index i = 0; i < n; ++i) {
    const double z = rng.uniform(z0, z1);
    const double u = rng.uniform(-margin, 1 + margin) * cam.width;
    const double v = rng.uniform(-margin, 1 + margin) * cam.height;
    const double world_sigma = sigma_px * z / double(cam.fx);
    Vector3<double> ls;
    for (int k = 0; k < 3; ++k) ls(k) = std::log(world_sigma * rng.uniform(0.5, 1.5));
    const double o = rng.uniform(o0, o1);
    std::vector<double> col;
    for (Index k = 0; k < C; ++k) col.push_back(rng.uniform(0, 1));
    // unnormalised quaternion: exercises the raw-4-vector path
    Quaternion<double> q = rng.quaternion();
    q.coeffs() *= rng.uniform(0.5, 2.0);
    s.add(world_at_pixel(cam, u, v, z), q, ls, std::log(o / (1 - o)), col);
  }
  return s;
}

template <class S>
struct Rendered {
  std::vector<S> image, alpha, depth;
};

template <int C, class S>
Rendered<S> render(const SplatScene<S>& scene, const splat::Camera<S>& cam,
                   const splat::SplatSettings<S>& set, splat::RenderWorkspace<S>& ws,
                   int threads = 2) {
  Rendered<S> r;
  const Index H = cam.height, W = cam.width;
  r.image.assign(static_cast<std::size_t>(H * W * scene.C), S(-7));
  r.alpha.assign(static_cast<std::size_t>(H * W), S(-7));
  r.depth.assign(static_cast<std::size_t>(H * W), S(-7));
  splat::RenderImages<S> out{{r.image.data(), H, W, scene.C}, {r.alpha.data(), H, W}, {r.depth.data(), H, W}};
  const Status st = splat::validate_render(scene.params(), cam, set, out, C > 0 ? C : -1);
  REQUIRE_MESSAGE(st.is_ok(), st.message());
  splat::render_forward<C>(scene.params(), cam, set, ws, out, {threads, 0});
  return r;
}

// Output gradients and the loss L = Σ gI·image + Σ gA·alpha + Σ gD·depth.
struct LossWeights {
  std::vector<double> image, alpha, depth;
};
inline LossWeights random_weights(Rng& rng, Index H, Index W, Index C, bool use_alpha = true,
                                  bool use_depth = true) {
  LossWeights w;
  for (Index k = 0; k < H * W * C; ++k) w.image.push_back(rng.uniform(-1, 1));
  for (Index k = 0; k < H * W; ++k) w.alpha.push_back(use_alpha ? rng.uniform(-1, 1) : 0.0);
  for (Index k = 0; k < H * W; ++k) w.depth.push_back(use_depth ? 0.3 * rng.uniform(-1, 1) : 0.0);
  return w;
}
template <class S>
double loss(const Rendered<S>& r, const LossWeights& w) {
  double L = 0;
  for (std::size_t k = 0; k < r.image.size(); ++k) L += w.image[k] * double(r.image[k]);
  for (std::size_t k = 0; k < r.alpha.size(); ++k) L += w.alpha[k] * double(r.alpha[k]);
  for (std::size_t k = 0; k < r.depth.size(); ++k) L += w.depth[k] * double(r.depth[k]);
  return L;
}

// All gradient outputs of render_backward, owning storage.
template <class S>
struct SceneGrads {
  std::vector<S> means, quats, quats_tangent, log_scales, logits, colors, means2d;
  splat::GaussianGrads<S> views(const SplatScene<S>& s) {
    means.assign(static_cast<std::size_t>(3 * s.G), S(99));
    quats.assign(static_cast<std::size_t>(4 * s.G), S(99));
    quats_tangent.assign(static_cast<std::size_t>(3 * s.G), S(99));
    log_scales.assign(static_cast<std::size_t>(3 * s.G), S(99));
    logits.assign(static_cast<std::size_t>(s.G), S(99));
    colors.assign(static_cast<std::size_t>(s.G * s.color_cols()), S(99));
    means2d.assign(static_cast<std::size_t>(2 * s.G), S(99));
    splat::GaussianGrads<S> g;
    g.means = {means.data(), s.G};
    g.quats = {quats.data(), s.G};
    g.quats_tangent = {quats_tangent.data(), s.G};
    g.log_scales = {log_scales.data(), s.G};
    g.opacity_logits = {logits.data(), s.G};
    g.colors = {colors.data(), s.G, s.color_cols()};
    g.means2d = {means2d.data(), s.G};
    return g;
  }
  // Same flat order as SplatScene::flat().
  std::vector<double> flat() const {
    std::vector<double> out;
    for (const auto* v : {&means, &quats, &log_scales, &logits, &colors})
      for (const auto& x : *v) out.push_back(double(x));
    return out;
  }
};

template <int C, class S>
SceneGrads<S> backward(const SplatScene<S>& scene, const splat::Camera<S>& cam,
                       const splat::SplatSettings<S>& set, splat::RenderWorkspace<S>& ws,
                       const LossWeights& w, int threads = 2) {
  const Index H = cam.height, W = cam.width;
  const std::vector<S> gi(w.image.begin(), w.image.end()), ga(w.alpha.begin(), w.alpha.end()),
      gd(w.depth.begin(), w.depth.end());
  const splat::RenderImageGrads<S> gin{{gi.data(), H, W, scene.C}, {ga.data(), H, W}, {gd.data(), H, W}};
  SceneGrads<S> out;
  const auto views = out.views(scene);
  const Status st = splat::validate_render_backward(scene.params(), cam, set, ws, gin, views);
  REQUIRE_MESSAGE(st.is_ok(), st.message());
  splat::render_backward<C>(scene.params(), cam, set, ws, gin, views, {threads, 0});
  return out;
}

}  // namespace smg::test
