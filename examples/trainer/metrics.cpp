// examples/trainer/metrics.cpp — PSNR, SSIM (separable Gaussian filtering), 3D EPE.
#include "trainer/metrics.hpp"

#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace trainer {

namespace {

constexpr int kRadius = 5;  // 11x11 window
constexpr double kSigma = 1.5;

void check_same(const Image& a, const Image& b, const char* what) {
  if (a.width != b.width || a.height != b.height || a.channels != b.channels || a.empty())
    throw std::invalid_argument(std::string(what) + ": images must be non-empty and of equal size, got " +
                                std::to_string(a.width) + "x" + std::to_string(a.height) + "x" +
                                std::to_string(a.channels) + " and " + std::to_string(b.width) + "x" +
                                std::to_string(b.height) + "x" + std::to_string(b.channels));
}

std::array<double, 2 * kRadius + 1> gaussian_window() {
  std::array<double, 2 * kRadius + 1> w{};
  double sum = 0;
  // cppcheck-suppress containerOutOfBounds ; false positive: w has 2 kRadius + 1 entries
  for (int k = -kRadius; k <= kRadius; ++k) sum += w[k + kRadius] = std::exp(-0.5 * k * k / (kSigma * kSigma));
  for (double& v : w) v /= sum;
  return w;
}

// Valid-mode separable filtering of a single-channel W x H plane: (W-10) x (H-10) output.
void filter_valid(const std::vector<double>& in, int W, int H, const std::array<double, 2 * kRadius + 1>& g,
                  std::vector<double>* tmp, std::vector<double>* out) {
  const int OW = W - 2 * kRadius, OH = H - 2 * kRadius;
  tmp->assign(static_cast<std::size_t>(OW) * H, 0.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < OW; ++x) {
      double s = 0;
      // cppcheck-suppress containerOutOfBounds ; false positive: g has 2 kRadius + 1 entries
      for (int k = 0; k <= 2 * kRadius; ++k) s += g[k] * in[static_cast<std::size_t>(y) * W + x + k];
      (*tmp)[static_cast<std::size_t>(y) * OW + x] = s;
    }
  out->assign(static_cast<std::size_t>(OW) * OH, 0.0);
  for (int y = 0; y < OH; ++y)
    for (int x = 0; x < OW; ++x) {
      double s = 0;
      // cppcheck-suppress containerOutOfBounds ; false positive: g has 2 kRadius + 1 entries
      for (int k = 0; k <= 2 * kRadius; ++k) s += g[k] * (*tmp)[static_cast<std::size_t>(y + k) * OW + x];
      (*out)[static_cast<std::size_t>(y) * OW + x] = s;
    }
}

}  // namespace

double psnr(const Image& a, const Image& b, const std::uint8_t* mask, double peak) {
  check_same(a, b, "psnr");
  double sum = 0;
  long long n = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      if (mask && !mask[static_cast<std::size_t>(y) * a.width + x]) continue;
      for (int c = 0; c < a.channels; ++c) {
        const double d = static_cast<double>(a.at(x, y, c)) - b.at(x, y, c);
        sum += d * d;
      }
      n += a.channels;
    }
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  const double mse = sum / static_cast<double>(n);
  if (mse == 0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(peak * peak / mse);
}

Image ssim_map(const Image& a, const Image& b) {
  check_same(a, b, "ssim");
  const int W = a.width, H = a.height;
  if (W < 2 * kRadius + 1 || H < 2 * kRadius + 1)
    throw std::invalid_argument("ssim: images must be at least 11x11, got " + std::to_string(W) + "x" +
                                std::to_string(H));
  const double C1 = 0.01 * 0.01, C2 = 0.03 * 0.03;
  const auto g = gaussian_window();
  const int OW = W - 2 * kRadius, OH = H - 2 * kRadius;
  Image map(OW, OH, 1, 0.0f);
  const std::size_t n = static_cast<std::size_t>(W) * H;
  std::vector<double> x(n), y(n), xx(n), yy(n), xy(n), tmp, mx, my, mxx, myy, mxy;
  for (int c = 0; c < a.channels; ++c) {
    for (std::size_t i = 0; i < n; ++i) {
      x[i] = a.pixels[i * a.channels + c];
      y[i] = b.pixels[i * b.channels + c];
      xx[i] = x[i] * x[i];
      yy[i] = y[i] * y[i];
      xy[i] = x[i] * y[i];
    }
    filter_valid(x, W, H, g, &tmp, &mx);
    filter_valid(y, W, H, g, &tmp, &my);
    filter_valid(xx, W, H, g, &tmp, &mxx);
    filter_valid(yy, W, H, g, &tmp, &myy);
    filter_valid(xy, W, H, g, &tmp, &mxy);
    for (std::size_t i = 0; i < mx.size(); ++i) {
      const double ux = mx[i], uy = my[i];
      const double vx = mxx[i] - ux * ux, vy = myy[i] - uy * uy, cxy = mxy[i] - ux * uy;
      const double s = ((2 * ux * uy + C1) * (2 * cxy + C2)) / ((ux * ux + uy * uy + C1) * (vx + vy + C2));
      map.pixels[i] += static_cast<float>(s / a.channels);
    }
  }
  return map;
}

double ssim(const Image& a, const Image& b, const std::uint8_t* mask) {
  const Image map = ssim_map(a, b);
  double sum = 0;
  long long n = 0;
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x) {
      if (mask && !mask[static_cast<std::size_t>(y + kRadius) * a.width + x + kRadius]) continue;
      sum += map.at(x, y);
      ++n;
    }
  return n > 0 ? sum / static_cast<double>(n) : std::numeric_limits<double>::quiet_NaN();
}

TrackingError tracking_error(smg::PositionsView<const double> estimate, smg::PositionsView<const double> truth,
                             double extent, smg::VisibilityView<const std::uint8_t> mask) {
  if (estimate.frames() != truth.frames() || estimate.nodes() != truth.nodes())
    throw std::invalid_argument("tracking_error: estimate and truth must have the same [T][N] shape");
  if (!mask.empty() && (mask.frames() != truth.frames() || mask.nodes() != truth.nodes()))
    throw std::invalid_argument("tracking_error: mask must be [T][N] like the trajectories");
  if (!(extent > 0)) throw std::invalid_argument("tracking_error: extent must be > 0");
  TrackingError e;
  double sum = 0;
  long long in5 = 0, in10 = 0;
  for (smg::Index t = 0; t < truth.frames(); ++t)
    for (smg::Index i = 0; i < truth.nodes(); ++i) {
      if (!mask.empty() && !mask(t, i)) continue;
      const double d = (estimate(t, i) - truth(t, i)).norm();
      sum += d;
      in5 += d < 0.05 * extent;
      in10 += d < 0.10 * extent;
      ++e.samples;
    }
  if (e.samples == 0) {
    e.epe = e.within_5 = e.within_10 = std::numeric_limits<double>::quiet_NaN();
    return e;
  }
  const double n = static_cast<double>(e.samples);
  e.epe = sum / n;
  e.within_5 = static_cast<double>(in5) / n;
  e.within_10 = static_cast<double>(in10) / n;
  return e;
}

}  // namespace trainer
