// examples/trainer/image.hpp — a float image, row-major [H][W][C], values in [0, 1].
//
// The layout is the one a splatter writes (image [H][W][C]) so renders and ground truth compare
// element by element. Pixel (x, y) is column x, row y.
#pragma once

#include <cstddef>
#include <vector>

namespace trainer {

struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> pixels;  // [height][width][channels]

  Image() = default;
  Image(int w, int h, int c, float fill = 0.0f)
      : width(w), height(h), channels(c),
        pixels(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(c), fill) {}

  bool empty() const { return pixels.empty(); }
  std::size_t index(int x, int y, int c = 0) const {
    return (static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + static_cast<std::size_t>(x)) *
               static_cast<std::size_t>(channels) +
           static_cast<std::size_t>(c);
  }
  float& at(int x, int y, int c = 0) { return pixels[index(x, y, c)]; }
  float at(int x, int y, int c = 0) const { return pixels[index(x, y, c)]; }
  float* data() { return pixels.data(); }
  const float* data() const { return pixels.data(); }
};

}  // namespace trainer
