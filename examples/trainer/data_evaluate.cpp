// examples/trainer/data_evaluate.cpp — the evaluation of a scene from disk on its validation frames (data_evaluate.hpp).
#include "trainer/data_evaluate.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "trainer/progress.hpp"
#include "trainer/util.hpp"

namespace trainer {

void evaluate_frames(const Dataset& d, const Nodes& nodes, const GaussianModel<float>& model,
                     smg::ParallelOptions parallel, std::vector<FrameScore>* frames, FrameScore* mean,
                     std::vector<Image>* renders) {
  NodeState<float> ns;
  ns.assign(nodes);
  ModelRenderer<float> renderer;
  frames->clear();
  if (renders) renders->clear();
  for (const EvalFrame& f : d.eval) {
    Image img(f.camera.width, f.camera.height, 3);
    renderer.render(model, ns, f.frame, splat_camera<float>(f.camera), img.data(), nullptr, nullptr, parallel);
    for (float& v : img.pixels) v = std::clamp(v, 0.0f, 1.0f);
    FrameScore s;
    static_cast<DycheckImageMetrics&>(s) = dycheck_image_metrics(f.rgb, img, f.covisible);
    s.name = f.name;
    frames->push_back(s);
    if (renders) renders->push_back(std::move(img));
  }
  const double V = std::max<double>(1.0, static_cast<double>(frames->size()));
  FrameScore& m = *mean;
  m.name = "mean";
  int covisible_frames = 0;
  for (const FrameScore& s : *frames) {
    m.mpsnr += s.mpsnr / V;
    m.mssim += s.mssim / V;
    m.psnr += s.psnr / V;
    m.ssim += s.ssim / V;
    // NaN where a frame has no covisible pixel: left out of that mean only.
    if (std::isfinite(s.mssim_covisible)) {
      m.mssim_covisible += s.mssim_covisible;
      ++covisible_frames;
    }
  }
  m.mssim_covisible = covisible_frames > 0 ? m.mssim_covisible / covisible_frames : 0.0;
}

}  // namespace trainer
