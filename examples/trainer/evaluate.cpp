// examples/trainer/evaluate.cpp — the evaluation of a run: test-view image metrics and node tracking error (the
// validation frames are data_evaluate.cpp).
#include "trainer/evaluate.hpp"

#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include "trainer/progress.hpp"
#include "trainer/util.hpp"

namespace trainer {

namespace {

double mean(const std::vector<double>& v) {
  double s = 0;
  int n = 0;
  for (double x : v)
    if (std::isfinite(x)) {
      s += x;
      ++n;
    }
  return n ? s / n : std::nan("");
}

Image to_image(const std::vector<float>& rgb, int W, int H) {
  Image im(W, H, 3);
  im.pixels = rgb;
  return im;
}

}  // namespace

TrackMetrics track_metrics(const Scene& scene, const Nodes& n) {
  const int T = n.frames, N = n.count;
  const int box = scene.find_body("box"), ball = scene.find_body("ball");
  auto masked = [&](auto pick) {
    std::vector<std::uint8_t> mask(sz(T) * N, 0);
    for (int t = 0; t < T; ++t)
      for (int i = 0; i < N; ++i) mask[sz(t) * N + i] = pick(t, i) ? 1 : 0;
    return tracking_error(n.positions_view(), n.truth_view(), scene.extent,
                          smg::VisibilityView<const std::uint8_t>(mask.data(), T, N));
  };
  const auto body = [&](int i) { return n.body[sz(i)]; };
  const auto hidden = [&](int t, int i) { return n.visible[sz(t) * N + i] == 0; };
  TrackMetrics m;
  m.all = tracking_error(n.positions_view(), n.truth_view(), scene.extent);
  m.box = masked([&](int, int i) { return body(i) == box; });
  m.arm = masked([&](int, int i) {  // every link of the arm (two, or the bending layout's six)
    return body(i) >= 0 && scene.bodies[sz(body(i))].semantic_class == classes::arm;
  });
  m.ball = masked([&](int, int i) { return body(i) == ball; });
  m.hidden = masked([&](int t, int i) { return hidden(t, i); });
  m.box_hidden = masked([&](int t, int i) { return body(i) == box && hidden(t, i); });
  return m;
}

NodeErrorSplit node_error_split(const Scene& scene, const Nodes& n, const std::vector<double>& confidence,
                                const std::vector<double>& node_weight) {
  const int T = n.frames, N = n.count;
  if (confidence.size() != sz(T) * N) throw std::invalid_argument("node_error_split: confidence must be [T][N]");
  if (node_weight.size() != sz(N)) throw std::invalid_argument("node_error_split: node_weight must be [N]");
  if (n.failed_report.size() != sz(T) * N) throw std::invalid_argument("node_error_split: needs Nodes::failed_report");
  auto masked = [&](auto pick) {
    std::vector<std::uint8_t> mask(sz(T) * N, 0);
    for (int t = 0; t < T; ++t)
      for (int i = 0; i < N; ++i) mask[sz(t) * N + i] = pick(sz(t) * N + i, i) ? 1 : 0;
    return tracking_error(n.positions_view(), n.truth_view(), scene.extent,
                          smg::VisibilityView<const std::uint8_t>(mask.data(), T, N));
  };
  NodeErrorSplit s;
  s.failed = masked([&](std::size_t k, int) { return n.failed_report[k] != 0; });
  s.clean = masked([&](std::size_t k, int) { return n.failed_report[k] == 0; });
  s.conf_low = masked([&](std::size_t k, int) { return confidence[k] < 0.3; });
  s.conf_mid = masked([&](std::size_t k, int) { return confidence[k] >= 0.3 && confidence[k] < 0.7; });
  s.conf_high = masked([&](std::size_t k, int) { return confidence[k] >= 0.7; });
  s.driving = masked([&](std::size_t, int i) { return node_weight[sz(i)] > 0; });
  s.idle = masked([&](std::size_t, int i) { return !(node_weight[sz(i)] > 0); });
  double num = 0, den = 0;
  const auto est = n.positions_view();
  const auto tru = n.truth_view();
  for (int t = 0; t < T; ++t)
    for (int i = 0; i < N; ++i) {
      num += node_weight[sz(i)] * (est(t, i) - tru(t, i)).norm();
      den += node_weight[sz(i)];
    }
  s.weighted_epe = den > 0 ? num / den : std::numeric_limits<double>::quiet_NaN();
  return s;
}

namespace {

// The test-view part of evaluate(): both test views and the training view against the truth.
void evaluate_views(const Dataset& d, const Nodes& nodes, const GaussianModel<float>& model,
                    smg::ParallelOptions parallel, bool keep_renders, Evaluation& e) {
  const GroundTruth& g = *d.truth;
  const Scene& scene = g.scene;
  const int T = d.frames(), W = d.width, H = d.height;
  const std::size_t plane = sz(W) * H;
  const int V = static_cast<int>(scene.test_cameras.size());
  const int box = scene.find_body("box");
  std::vector<std::vector<Image>>* renders = keep_renders ? &e.renders : nullptr;
  NodeState<float> ns;
  ns.assign(nodes);
  ModelRenderer<float> renderer;
  std::vector<float> rgb(plane * 3);
  if (renders) renders->assign(sz(V) + 1, std::vector<Image>());
  for (int v = 0; v <= V; ++v) {
    const bool train = v == V;
    ViewMetrics vm;
    vm.name = train ? "train" : scene.test_views[sz(v)].name;
    std::vector<double> psnr, ssim, psnr_m, ssim_m, psnr_obj;
    for (int t = 0; t < T; ++t) {
      const Camera& cam = train ? d.cameras[sz(t)] : scene.test_cameras[sz(v)];
      renderer.render(model, ns, t, splat_camera<float>(cam), rgb.data(), nullptr, nullptr, parallel);
      const Image im = to_image(rgb, W, H);
      const RenderOutput& gt = train ? g.train[sz(t)] : g.test[sz(v)][sz(t)];
      psnr.push_back(trainer::psnr(im, gt.rgb));
      if (!train) {
        ssim.push_back(trainer::ssim(im, gt.rgb));
        if (!g.test_covisible.empty()) {
          const std::uint8_t* cm = g.test_covisible[sz(v)].data() + sz(t) * plane;
          psnr_m.push_back(trainer::psnr(im, gt.rgb, cm));
          ssim_m.push_back(trainer::ssim(im, gt.rgb, cm));
        }
        std::vector<std::uint8_t> bm(plane), om(plane);
        bool any_box = false, any_obj = false;
        for (std::size_t k = 0; k < plane; ++k) {
          const int b = gt.body[k];
          bm[k] = b == box ? 1 : 0;
          om[k] = b >= 0 && scene.bodies[sz(b)].foreground ? 1 : 0;
          any_box |= bm[k] != 0;
          any_obj |= om[k] != 0;
        }
        vm.psnr_box_per_frame.push_back(any_box ? trainer::psnr(im, gt.rgb, bm.data()) : std::nan(""));
        psnr_obj.push_back(any_obj ? trainer::psnr(im, gt.rgb, om.data()) : std::nan(""));
      }
      if (renders) (*renders)[sz(v)].push_back(im);
    }
    vm.psnr_per_frame = psnr;
    vm.psnr = mean(psnr);
    if (train) {
      e.train_psnr = vm.psnr;
      continue;
    }
    vm.ssim = mean(ssim);
    vm.psnr_masked = mean(psnr_m);
    vm.ssim_masked = mean(ssim_m);
    vm.psnr_box = mean(vm.psnr_box_per_frame);
    vm.psnr_objects = mean(psnr_obj);
    e.views.push_back(vm);
  }
  e.mean.name = "mean";
  for (const ViewMetrics& vm : e.views) {
    e.mean.psnr += vm.psnr / V;
    e.mean.ssim += vm.ssim / V;
    e.mean.psnr_masked += vm.psnr_masked / V;
    e.mean.ssim_masked += vm.ssim_masked / V;
    e.mean.psnr_box += vm.psnr_box / V;
    e.mean.psnr_objects += vm.psnr_objects / V;
  }
  e.tracks = track_metrics(scene, nodes);
}

}  // namespace

Evaluation evaluate(const Dataset& d, const Nodes& nodes, const GaussianModel<float>& model,
                    smg::ParallelOptions parallel, bool keep_renders) {
  const auto t0 = std::chrono::steady_clock::now();
  Evaluation e;
  if (d.truth) evaluate_views(d, nodes, model, parallel, keep_renders, e);
  if (!d.eval.empty())
    evaluate_frames(d, nodes, model, parallel, &e.frames, &e.frames_mean, keep_renders ? &e.frame_renders : nullptr);
  e.seconds = seconds_since(t0);
  return e;
}

}  // namespace trainer
