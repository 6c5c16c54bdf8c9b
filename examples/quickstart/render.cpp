// Quick start 4: render Gaussians with smg::splat and run the backward pass.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <smg/smg.hpp>

namespace sp = smg::splat;

namespace {
void check(const smg::Status& s) {
  if (!s) {
    std::fprintf(stderr, "invalid input: %s\n", s.message().c_str());
    std::exit(1);
  }
}
}  // namespace

int main() {
  // Two Gaussians in front of a 64x48 pinhole camera (OpenCV axes: x right, y down, z forward;
  // the world-to-camera matrix is the identity), gsplat's parameterisation.
  const smg::Index G = 2, C = 3;
  std::vector<double> means = {0.0, 0.0, 3.0,  0.4, 0.2, 4.0};              // [G][3]
  std::vector<double> quats = {1, 0, 0, 0,  0.9, 0.1, 0.2, 0.3};           // [G][4] (w, x, y, z), any norm
  std::vector<double> log_scales = {-1.5, -1.5, -1.5,  -1.0, -2.0, -1.5};  // [G][3]
  std::vector<double> opacity_logits = {2.0, 1.0};                         // [G]
  std::vector<double> colors = {1, 0, 0,  0, 0, 1};                        // [G][C]
  sp::GaussianParams<double> params;
  params.means = {means.data(), G};
  params.quats = {quats.data(), G};
  params.log_scales = {log_scales.data(), G};
  params.opacity_logits = {opacity_logits.data(), G};
  params.colors = {colors.data(), G, C};

  sp::Camera<double> camera;
  camera.fx = camera.fy = 60;
  camera.cx = 32;
  camera.cy = 24;
  camera.width = 64;
  camera.height = 48;
  const sp::SplatSettings<double> settings;  // 16-px tiles, eps2d 0.3, alpha_max 0.99
  const smg::Index H = camera.height, W = camera.width;
  std::vector<double> image(H * W * C), alpha(H * W), depth(H * W);
  const sp::RenderImages<double> images{{image.data(), H, W, C}, {alpha.data(), H, W}, {depth.data(), H, W}};
  check(sp::validate_render(params, camera, settings, images, C));

  // Forward: image [H][W][C], alpha and expected depth [H][W]. The workspace keeps what the
  // backward needs (reuse it across iterations: it keeps its memory).
  sp::RenderWorkspace<double> ws;
  sp::render_forward<3>(params, camera, settings, ws, images);
  double loss = 0;
  for (double v : image) loss += v;
  std::printf("rendered %ldx%ld: sum of the image %.6f, %ld Gaussians visible\n", long(W), long(H), loss,
              long(ws.n_visible));

  // Backward of L = sum(image): dL/dimage = 1. Gaussian gradients are written (overwritten,
  // unlike the energies' gradient buffers); each view is optional.
  std::vector<double> grad_image(H * W * C, 1.0);
  sp::RenderImageGrads<double> grad_in;
  grad_in.image = {grad_image.data(), H, W, C};
  std::vector<double> g_means(G * 3), g_quats(G * 4), g_scales(G * 3), g_opacity(G), g_colors(G * C);
  sp::GaussianGrads<double> grads;
  grads.means = {g_means.data(), G};
  grads.quats = {g_quats.data(), G};
  grads.log_scales = {g_scales.data(), G};
  grads.opacity_logits = {g_opacity.data(), G};
  grads.colors = {g_colors.data(), G, C};
  check(sp::validate_render_backward(params, camera, settings, ws, grad_in, grads));
  sp::render_backward<3>(params, camera, settings, ws, grad_in, grads);

  // Check one gradient against a central difference of the forward.
  auto loss_at = [&](double logit) {
    std::vector<double> o = opacity_logits, img(H * W * C);
    o[0] = logit;
    sp::GaussianParams<double> p = params;
    p.opacity_logits = {o.data(), G};
    sp::RenderWorkspace<double> w2;
    sp::render_forward<3>(p, camera, settings, w2, sp::RenderImages<double>{{img.data(), H, W, C}, {}, {}});
    double s = 0;
    for (double v : img) s += v;
    return s;
  };
  const double h = 1e-6;
  const double fd = (loss_at(opacity_logits[0] + h) - loss_at(opacity_logits[0] - h)) / (2 * h);
  const double rel = std::abs(fd - g_opacity[0]) / std::abs(fd);
  std::printf("dL/d(opacity logit 0): analytic %.8f, central difference %.8f (rel. error %.1e)\n",
              g_opacity[0], fd, rel);
  std::printf("dL/d(mean 0) = (%.5f, %.5f, %.5f)\n", g_means[0], g_means[1], g_means[2]);
  const bool ok = ws.n_visible == 2 && rel < 1e-6;
  std::printf("quickstart render: %s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
