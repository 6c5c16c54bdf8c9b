// PNG writing (stb_image_write, read back with libpng: trainer::files::decode_png), composition helpers, colour maps, drawing.
#include <doctest/doctest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "trainer/file_formats.hpp"
#include "trainer/image_io.hpp"

using trainer::Image;
namespace fs = std::filesystem;

namespace {
fs::path image_temp_dir() {
  const fs::path d = fs::temp_directory_path() / "smg_test_trainer_image_io";
  fs::create_directories(d);
  return d;
}
Image gradient(int w, int h, int c) {
  Image im(w, h, c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k) im.at(x, y, k) = static_cast<float>((x + 3 * y + 7 * k) % 256) / 255.0f;
  return im;
}
}  // namespace

TEST_CASE("write_png round-trips 8-bit values for 1, 3 and 4 channels; values are clamped") {
  for (int c : {1, 3, 4}) {
    CAPTURE(c);
    Image im = gradient(37, 23, c);
    im.at(0, 0, 0) = 1.7f;   // clamped to 255
    im.at(1, 0, 0) = -0.3f;  // clamped to 0
    const std::string path = (image_temp_dir() / ("g" + std::to_string(c) + ".png")).string();
    trainer::write_png(path, im);
    const trainer::files::Pixels8 read =
        trainer::files::decode_png(trainer::files::read_bytes(path, path), path, trainer::files::image_of_size(37, 23));
    const int w = read.width, h = read.height;
    const unsigned char* data = read.pixels.data();
    CHECK(w == 37);
    CHECK(h == 23);
    CHECK(read.channels == c);
    int bad = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int k = 0; k < c; ++k) {
          const float v = std::min(1.0f, std::max(0.0f, im.at(x, y, k)));
          bad += data[(y * w + x) * c + k] != static_cast<unsigned char>(std::lround(v * 255.0f));
        }
    CHECK(bad == 0);
    CHECK(data[0] == 255);
    CHECK(data[c] == 0);
  }
}

TEST_CASE("write_png: a path that cannot be written throws, naming it") {
  const fs::path file = image_temp_dir() / "plain_file";
  std::ofstream(file) << "x";
  const std::string bad = (file / "sub.png").string();
  CHECK_THROWS_WITH_AS(trainer::write_png(bad, gradient(4, 4, 3)), ("cannot write PNG '" + bad + "'").c_str(),
                       std::runtime_error);
  CHECK_THROWS_AS(trainer::write_png((image_temp_dir() / "e.png").string(), Image()), std::runtime_error);
}

TEST_CASE("hstack, vstack, grid, upscale: sizes and placement") {
  const Image a = gradient(5, 4, 3), b = gradient(3, 6, 1);
  const Image h = trainer::hstack({a, b}, 2, 0.5f);
  CHECK(h.width == 10);
  CHECK(h.height == 6);
  CHECK(h.channels == 3);
  CHECK(h.at(4, 3, 1) == a.at(4, 3, 1));
  CHECK(h.at(5, 0, 0) == 0.5f);                // the gap
  CHECK(h.at(7, 5, 2) == b.at(0, 5, 0));       // grey expanded to RGB
  CHECK(h.at(0, 5, 0) == 0.5f);                // below the shorter part
  const Image v = trainer::vstack({a, a}, 1);
  CHECK(v.width == 5);
  CHECK(v.height == 9);
  CHECK(v.at(2, 5, 0) == a.at(2, 0, 0));
  std::vector<Image> cells(5, a);
  const Image g = trainer::grid(cells, 2, 1);
  CHECK(g.width == 11);
  CHECK(g.height == 3 * 4 + 2);
  const Image u = trainer::upscale(a, 3);
  CHECK(u.width == 15);
  CHECK(u.at(14, 11, 2) == a.at(4, 3, 2));
  CHECK_THROWS_AS(trainer::grid(cells, 0), std::invalid_argument);
}

TEST_CASE("colorize_depth: no depth is black, near is blue, far is red (turbo)") {
  const float depth[4] = {0.0f, 1.5f, 3.0f, 2.0f};
  const Image im = trainer::colorize_depth(depth, 4, 1, 1.0, 3.0);
  CHECK(im.at(0, 0, 0) + im.at(0, 0, 1) + im.at(0, 0, 2) == 0.0f);
  CHECK(im.at(1, 0, 2) > im.at(1, 0, 0) + 0.3f);  // a quarter of the range: blue
  CHECK(im.at(2, 0, 0) > im.at(2, 0, 2) + 0.3f);  // far end: dark red
  CHECK(im.at(3, 0, 1) > 0.8f);                   // middle: green
}

TEST_CASE("feature projection separates clusters and is reproducible") {
  // Four clusters in 8-D (three directions between them, so every PCA channel carries signal).
  std::vector<float> f;
  for (int i = 0; i < 300; ++i) {
    const int c = i % 4;
    for (int k = 0; k < 8; ++k) f.push_back((k == c ? 1.0f : 0.0f) + 0.01f * static_cast<float>((i * 7 + k) % 5));
  }
  const auto p = trainer::fit_feature_projection(f.data(), 300, 8);
  const auto q = trainer::fit_feature_projection(f.data(), 300, 8);
  CHECK(p.basis == q.basis);
  const Image im = trainer::colorize_features(f.data(), 300, 1, 8, p);
  auto color = [&](int i) { return Eigen::Vector3f(im.at(i, 0, 0), im.at(i, 0, 1), im.at(i, 0, 2)); };
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) CHECK((color(a) - color(b)).norm() > 0.3f);
  CHECK((color(0) - color(4)).norm() < 0.1f);  // same cluster, same colour
  CHECK_THROWS_AS(trainer::colorize_features(f.data(), 300, 1, 7, p), std::invalid_argument);
}

TEST_CASE("drawing: discs, lines, tracks and text stay inside the image") {
  Image im(40, 30, 3, 0.0f);
  trainer::draw_disc(im, 10.0, 10.0, 2.0, Eigen::Vector3f(1, 0, 0));
  CHECK(im.at(10, 10, 0) == 1.0f);
  CHECK(im.at(20, 20, 0) == 0.0f);
  trainer::draw_disc(im, -5.0, 100.0, 20.0, Eigen::Vector3f(1, 1, 1));  // clipped, no crash
  trainer::draw_line(im, 0, 29.5, 39.9, 29.5, Eigen::Vector3f(0, 1, 0));
  CHECK(im.at(39, 29, 1) == 1.0f);
  // Two frames of one track: a trail and a dot at frame 1.
  const double uv[] = {5.5, 5.5, 30.5, 20.5};
  const std::uint8_t vis[] = {1, 1};
  Image t(40, 30, 3, 0.0f);
  trainer::draw_tracks(t, uv, vis, 2, 1, 1, 4, 1);
  CHECK(t.at(30, 20, 0) + t.at(30, 20, 1) + t.at(30, 20, 2) > 0.5f);
  CHECK(t.at(18, 13, 0) + t.at(18, 13, 1) + t.at(18, 13, 2) > 0.1f);  // on the trail
  Image txt(60, 20, 3, 1.0f);
  trainer::draw_text(txt, 2, 2, "t=12\x01", Eigen::Vector3f(1, 0, 0), 1);
  int red = 0;
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 60; ++x) red += txt.at(x, y, 0) == 1.0f && txt.at(x, y, 1) == 0.0f;
  CHECK(red > 10);
  trainer::draw_text(txt, 55, 15, "clipped", Eigen::Vector3f(1, 1, 1), 2);  // no crash
}
