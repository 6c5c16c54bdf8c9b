// tests/trainer/ssim_reference.hpp — SSIM written straight from Wang et al. (2004), for the tests
// of the trainer's metrics (trainer/metrics.hpp) and of Dycheck's masked SSIM
// (trainer/dycheck_metrics.hpp); and the random images both compare on.
#pragma once

#include <cmath>

#include "support/random.hpp"
#include "trainer/image.hpp"

namespace trainer::test {

// w x h x c image of uniform values in [0, 1).
inline Image random_image(smg::test::Rng& rng, int w, int h, int c = 3) {
  Image im(w, h, c);
  for (float& v : im.pixels) v = static_cast<float>(rng.uniform(0, 1));
  return im;
}

// f_i: the normalised 1D Gaussian of the 11-tap SSIM window (sigma 1.5), i in [0, 11).
inline double gauss(int i) {
  double sum = 0;
  for (int k = 0; k < 11; ++k) sum += std::exp(-0.5 * ((k - 5) / 1.5) * ((k - 5) / 1.5));
  return std::exp(-0.5 * ((i - 5) / 1.5) * ((i - 5) / 1.5)) / sum;
}

// Plain SSIM: for each valid 11x11 window position, the means, variances and covariance weighted
// by the 2D Gaussian window f_i f_j (centred moments); the mean over positions and channels.
inline double plain_ssim(const Image& a, const Image& b) {
  double total = 0;
  long long n = 0;
  for (int c = 0; c < a.channels; ++c)
    for (int y = 0; y + 11 <= a.height; ++y)
      for (int x = 0; x + 11 <= a.width; ++x) {
        double mx = 0, my = 0;
        for (int i = 0; i < 11; ++i)
          for (int j = 0; j < 11; ++j) {
            mx += gauss(i) * gauss(j) * a.at(x + j, y + i, c);
            my += gauss(i) * gauss(j) * b.at(x + j, y + i, c);
          }
        double vx = 0, vy = 0, cxy = 0;
        for (int i = 0; i < 11; ++i)
          for (int j = 0; j < 11; ++j) {
            const double w = gauss(i) * gauss(j);
            const double dx = a.at(x + j, y + i, c) - mx, dy = b.at(x + j, y + i, c) - my;
            vx += w * dx * dx;
            vy += w * dy * dy;
            cxy += w * dx * dy;
          }
        total += (2 * mx * my + 1e-4) * (2 * cxy + 9e-4) / ((mx * mx + my * my + 1e-4) * (vx + vy + 9e-4));
        ++n;
      }
  return total / double(n);
}

}  // namespace trainer::test
