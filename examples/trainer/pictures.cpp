// examples/trainer/pictures.cpp — strips, contact sheet and node overlays (pictures.hpp).
#include "trainer/pictures.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "trainer/frames.hpp"
#include "trainer/image_io.hpp"
#include "trainer/util.hpp"

namespace trainer {

namespace {

Image labelled(Image im, const std::string& text) {
  draw_text(im, 2, 2, text, Eigen::Vector3f(1, 1, 1));
  return im;
}

Image abs_error(const Image& a, const Image& b, float gain) {
  Image e(a.width, a.height, 3);
  for (std::size_t k = 0; k < e.pixels.size(); ++k) e.pixels[k] = std::min(1.0f, gain * std::abs(a.pixels[k] - b.pixels[k]));
  return e;
}

Image node_overlay(const TrainerResult& r, const Camera& cam, const Image& gt, int t) {
  Image im = gt;
  for (float& p : im.pixels) p *= 0.45f;
  const Nodes& n = r.nodes;
  const double extent = r.data.extent;
  for (int i = 0; i < n.count; ++i) {
    const std::size_t s = sz(t) * n.count + i;
    const Eigen::Vector3d x = Eigen::Map<const Eigen::Vector3d>(n.positions.data() + 3 * s);
    const Eigen::Vector3d y = Eigen::Map<const Eigen::Vector3d>(n.truth.data() + 3 * s);
    double zx, zy;
    const Eigen::Vector2d ux = cam.project(x, &zx), uy = cam.project(y, &zy);
    if (zx <= 0 || zy <= 0) continue;
    const double err = (x - y).norm();
    const Eigen::Vector3f col = err < 0.05 * extent   ? Eigen::Vector3f(0.2f, 1.0f, 0.2f)
                                : err < 0.1 * extent ? Eigen::Vector3f(1.0f, 0.6f, 0.1f)
                                                     : Eigen::Vector3f(1.0f, 0.15f, 0.15f);
    draw_line(im, uy.x(), uy.y(), ux.x(), ux.y(), col * 0.7f);
    draw_disc(im, uy.x(), uy.y(), 1.6, Eigen::Vector3f(1, 1, 1));
    draw_disc(im, ux.x(), ux.y(), 1.2, col);
  }
  return im;
}

}  // namespace

std::vector<std::string> write_pictures(const std::string& dir, const TrainerResult& r, int shown) {
  namespace fs = std::filesystem;
  const GroundTruth& g = need_truth(r.data, "write_pictures");  // the test views
  const Scene& scene = g.scene;
  const int T = r.data.frames(), V = static_cast<int>(scene.test_cameras.size());
  const std::vector<std::vector<Image>>& renders = r.evaluation.renders;
  const std::vector<int> frames = spread_frames(T, shown);
  std::vector<std::string> written;
  auto save = [&](const std::string& name, const Image& im) {
    const std::string path = (fs::path(dir) / name).string();
    write_png(path, im);
    written.push_back(path);
  };
  // Strips per test view.
  for (int v = 0; v < V; ++v) {
    std::vector<Image> rows;
    for (int t : frames) {
      const Image& gt = g.test[sz(v)][sz(t)].rgb;
      const Image& im = renders[sz(v)][sz(t)];
      rows.push_back(hstack({labelled(gt, "truth t=" + std::to_string(t)), labelled(im, "render"),
                             labelled(abs_error(im, gt, 4.0f), "|error| x4")}));
    }
    save(scene.test_views[sz(v)].name + ".png", vstack(rows));
  }
  // Contact sheet over time.
  {
    const std::vector<int> cols = spread_frames(T, 8);
    std::vector<Image> rows;
    auto row = [&](const std::string& label, auto get) {
      std::vector<Image> cells;
      cells.reserve(cols.size());
      for (int t : cols)
        cells.push_back(labelled(get(t), (cells.empty() ? label + " " : std::string()) + "t=" + std::to_string(t)));
      rows.push_back(hstack(cells));
    };
    row("train truth", [&](int t) { return r.data.images[sz(t)]; });
    row("train render", [&](int t) { return renders[sz(V)][sz(t)]; });
    for (int v = 0; v < V; ++v) {
      const std::string& name = scene.test_views[sz(v)].name;
      row(name + " truth", [&](int t) { return g.test[sz(v)][sz(t)].rgb; });
      row(name + " render", [&](int t) { return renders[sz(v)][sz(t)]; });
    }
    save("contact_sheet.png", vstack(rows, 3));
  }
  // Nodes from the test views.
  {
    std::vector<Image> rows;
    for (int v = 0; v < V; ++v) {
      std::vector<Image> cells;
      for (int t : spread_frames(T, 4))
        cells.push_back(labelled(upscale(node_overlay(r, scene.test_cameras[sz(v)], g.test[sz(v)][sz(t)].rgb, t), 2),
                                 scene.test_views[sz(v)].name + " nodes t=" + std::to_string(t)));
      rows.push_back(hstack(cells));
    }
    save("nodes.png", vstack(rows));
  }
  return written;
}

}  // namespace trainer
