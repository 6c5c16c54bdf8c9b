// examples/trainer/data_evaluate.cpp — the evaluation of a scene from disk on its validation frames (data_evaluate.hpp).
#include "trainer/data_evaluate.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "trainer/dycheck_metrics.hpp"
#include "trainer/progress.hpp"
#include "trainer/util.hpp"

namespace trainer {

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

}  // namespace trainer
