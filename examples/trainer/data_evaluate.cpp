// examples/trainer/data_evaluate.cpp — the evaluation of a scene from disk on its validation frames (data_evaluate.hpp).
#include "trainer/data_evaluate.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "trainer/dycheck_metrics.hpp"
#include "trainer/progress.hpp"
#include "trainer/util.hpp"

namespace trainer {

void evaluate_frames(const Dataset& d, const Nodes& nodes, const GaussianModel<float>& model,
                     smg::ParallelOptions parallel, bool keep_renders, Evaluation* e) {
  Evaluation& ev = *e;
  NodeState<float> ns;
  ns.assign(nodes);
  ModelRenderer<float> renderer;
  ev.frames.clear();
  ev.frame_renders.clear();
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
    if (keep_renders) ev.frame_renders.push_back(std::move(img));
  }
  const double V = std::max<double>(1.0, static_cast<double>(ev.frames.size()));
  ev.frames_mean.name = "mean";
  int covisible_frames = 0;
  for (const FrameScore& s : ev.frames) {
    ev.frames_mean.mpsnr += s.mpsnr / V;
    ev.frames_mean.mssim += s.mssim / V;
    ev.frames_mean.psnr += s.psnr / V;
    ev.frames_mean.ssim += s.ssim / V;
    // NaN where a frame has no covisible pixel: left out of that mean only.
    if (std::isfinite(s.mssim_covisible)) {
      ev.frames_mean.mssim_covisible += s.mssim_covisible;
      ++covisible_frames;
    }
  }
  ev.frames_mean.mssim_covisible = covisible_frames > 0 ? ev.frames_mean.mssim_covisible / covisible_frames : 0.0;
}

}  // namespace trainer
