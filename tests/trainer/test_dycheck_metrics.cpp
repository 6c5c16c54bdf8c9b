// Dycheck's mPSNR / mSSIM (trainer/dycheck_metrics.hpp) against direct per-pixel loops written
// from Dycheck's code (KAIR-BAIR/dycheck, dycheck/core/metrics/image.py), a hand-computed PSNR,
// its quantisation (dycheck/utils/image.py) and the argument checks.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "support/errors.hpp"
#include "support/random.hpp"
#include "trainer/ssim_reference.hpp"
#include "trainer/dycheck_metrics.hpp"
#include "trainer/metrics.hpp"

using trainer::Image;
using trainer::test::gauss;
using trainer::test::plain_ssim;
using trainer::test::random_image;

namespace {

using Mask = std::vector<std::uint8_t>;

// pred = gt + noise, so that the SSIM is far from both 0 and 1.
Image noisy_copy(smg::test::Rng& rng, const Image& gt, double amplitude) {
  Image im = gt;
  for (float& v : im.pixels) v = static_cast<float>(std::fmin(1.0, std::fmax(0.0, v + amplitude * rng.uniform())));
  return im;
}

Mask random_mask(smg::test::Rng& rng, int w, int h, double p_one) {
  Mask m(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  for (auto& v : m) v = rng.uniform(0, 1) < p_one ? 1 : 0;
  return m;
}

// Dycheck's compute_ssim map written per output position, with no intermediate images: the
// x-pass of convolve2d on each of the 11 rows of the window (sum f_j z m / count * 11, or 0 when
// the row holds no masked pixel), then the y-pass over the rows with a nonzero count (binarised
// mask), renormalised by 11 / (number of such rows). With `partial2d` instead: a 2D partial
// convolution (weights f_i f_j, renormalised by 121 / masked taps), which is NOT what Dycheck does.
std::vector<double> direct_map(const Image& a, const Image& b, const Mask& mask, bool partial2d = false) {
  const int W = a.width, H = a.height, C = a.channels, OW = W - 10, OH = H - 10;
  const auto m = [&](int x, int y) { return mask.empty() ? 1.0 : double(mask[std::size_t(y) * W + x]); };
  std::vector<double> out;
  for (int y = 0; y < OH; ++y)
    for (int x = 0; x < OW; ++x)
      for (int c = 0; c < C; ++c) {
        const auto filt = [&](const std::function<double(double, double)>& g) {
          if (partial2d) {
            double s = 0, n = 0;
            for (int r = 0; r < 11; ++r)
              for (int j = 0; j < 11; ++j) {
                const double mm = m(x + j, y + r);
                s += gauss(r) * gauss(j) * g(a.at(x + j, y + r, c), b.at(x + j, y + r, c)) * mm;
                n += mm;
              }
            return n > 0 ? s * 121 / n : 0.0;
          }
          double s = 0;
          int rows = 0;
          for (int r = 0; r < 11; ++r) {
            double row = 0, n = 0;
            for (int j = 0; j < 11; ++j) {
              const double mm = m(x + j, y + r);
              row += gauss(j) * g(a.at(x + j, y + r, c), b.at(x + j, y + r, c)) * mm;
              n += mm;
            }
            if (n == 0) continue;
            s += gauss(r) * (row * 11 / n);
            ++rows;
          }
          return rows > 0 ? s * 11 / rows : 0.0;
        };
        const double mu0 = filt([](double p, double) { return p; });
        const double mu1 = filt([](double, double q) { return q; });
        const double s00 = std::fmax(0.0, filt([](double p, double) { return p * p; }) - mu0 * mu0);
        const double s11 = std::fmax(0.0, filt([](double, double q) { return q * q; }) - mu1 * mu1);
        double s01 = filt([](double p, double q) { return p * q; }) - mu0 * mu1;
        s01 = (s01 > 0 ? 1.0 : s01 < 0 ? -1.0 : 0.0) * std::fmin(std::sqrt(s00 * s11), std::fabs(s01));
        const double c1 = 1e-4, c2 = 9e-4;
        out.push_back((2 * mu0 * mu1 + c1) * (2 * s01 + c2) / ((mu0 * mu0 + mu1 * mu1 + c1) * (s00 + s11 + c2)));
      }
  return out;
}

double max_abs_diff(const std::vector<double>& a, const std::vector<double>& b) {
  REQUIRE(a.size() == b.size());
  double d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
  return d;
}

template <class F>
std::string error_of(F&& f) {
  return smg::test::error_message<std::invalid_argument>(f, "(no std::invalid_argument)");
}

}  // namespace

TEST_CASE("dycheck ssim map: equals the direct per-window loops of Dycheck's masked convolution") {
  smg::test::Rng rng(11);
  const int W = 17, H = 23;
  for (int trial = 0; trial < 8; ++trial) {
    CAPTURE(trial);
    const Image a = random_image(rng, W, H);
    const Image b = noisy_copy(rng, a, 0.3);
    Mask mask;
    if (trial == 0) mask.assign(std::size_t(W) * H, 0);  // all zero
    if (trial == 1) mask.assign(std::size_t(W) * H, 1);  // all one
    if (trial == 2) mask = {};                           // empty = all one
    if (trial >= 3) mask = random_mask(rng, W, H, 0.15 * (trial - 2));
    if (trial == 7) {  // a block of zeros wider than a window: positions with no masked pixel
      mask.assign(std::size_t(W) * H, 1);
      for (int y = 3; y < 20; ++y)
        for (int x = 2; x < 16; ++x) mask[std::size_t(y) * W + x] = 0;
    }
    const std::vector<double> map = trainer::dycheck_ssim_map(a, b, mask);
    CHECK(map.size() == std::size_t(W - 10) * (H - 10) * 3);
    CHECK(max_abs_diff(map, direct_map(a, b, mask)) < 1e-12);

    // The means: the whole map (Dycheck), and the covisible window centres (ours).
    const trainer::DycheckSsim s = trainer::dycheck_ssim(a, b, mask);
    double total = 0, cov = 0;
    int ncov = 0;
    for (int y = 0; y < H - 10; ++y)
      for (int x = 0; x < W - 10; ++x)
        for (int c = 0; c < 3; ++c) {
          const double v = map[(std::size_t(y) * (W - 10) + x) * 3 + c];
          total += v;
          if (mask.empty() || mask[std::size_t(y + 5) * W + x + 5]) cov += v / 3, ncov += (c == 0);
        }
    CHECK(s.mean == doctest::Approx(total / double(map.size())).epsilon(1e-14));
    if (ncov > 0)
      CHECK(s.mean_covisible == doctest::Approx(cov / ncov).epsilon(1e-14));
    else
      CHECK(std::isnan(s.mean_covisible));
  }
}

TEST_CASE("dycheck ssim: all-zero mask gives 1 everywhere (mu = sigma = 0 is kept in the mean)") {
  smg::test::Rng rng(12);
  const Image a = random_image(rng, 19, 14), b = random_image(rng, 19, 14);
  const trainer::DycheckSsim s = trainer::dycheck_ssim(a, b, Mask(19 * 14, 0));
  CHECK(s.mean == 1.0);
  CHECK(std::isnan(s.mean_covisible));
}

TEST_CASE("dycheck ssim: Dycheck's two-pass renormalisation is not a 2D partial convolution") {
  smg::test::Rng rng(13);
  const Image a = random_image(rng, 17, 23);
  const Image b = noisy_copy(rng, a, 0.3);
  const Mask mask = random_mask(rng, 17, 23, 0.5);
  const std::vector<double> map = trainer::dycheck_ssim_map(a, b, mask);
  CHECK(max_abs_diff(map, direct_map(a, b, mask, /*partial2d=*/true)) > 1e-4);
  // ... with a full mask the two agree (both are the plain Gaussian filter).
  CHECK(max_abs_diff(trainer::dycheck_ssim_map(a, b), direct_map(a, b, {}, true)) < 1e-12);
}

TEST_CASE("dycheck ssim: an all-ones mask is plain SSIM; identical images give SSIM 1, PSNR +inf") {
  smg::test::Rng rng(14);
  const Image a = random_image(rng, 23, 17);
  const Image b = noisy_copy(rng, a, 0.5);
  const double plain = plain_ssim(a, b);
  CHECK(plain < 0.9);
  const Mask ones(23 * 17, 1);
  CHECK(trainer::dycheck_ssim(a, b, ones).mean == doctest::Approx(plain).epsilon(1e-12));
  CHECK(trainer::dycheck_ssim(a, b).mean == doctest::Approx(plain).epsilon(1e-12));
  CHECK(trainer::dycheck_ssim(a, b, ones).mean_covisible == doctest::Approx(plain).epsilon(1e-12));
  CHECK(trainer::ssim(a, b) == doctest::Approx(plain).epsilon(1e-6));  // trainer/metrics.hpp agrees

  const Mask cov = random_mask(rng, 23, 17, 0.6);
  CHECK(trainer::dycheck_ssim(a, a, cov).mean == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(trainer::dycheck_ssim(a, a).mean == doctest::Approx(1.0).epsilon(1e-15));
  // compute_psnr: log(0) = -inf -> +inf dB, for identical images and for an all-zero mask
  // (masked_mean's clip(1e-6) makes it 0 / 1e-6 = 0, not NaN).
  CHECK(trainer::dycheck_psnr(a, a, cov) == std::numeric_limits<double>::infinity());
  CHECK(trainer::dycheck_psnr(a, b, Mask(23 * 17, 0)) == std::numeric_limits<double>::infinity());

  const trainer::DycheckImageMetrics m = trainer::dycheck_image_metrics(a, a, cov);
  CHECK(m.mpsnr == std::numeric_limits<double>::infinity());
  CHECK(m.psnr == std::numeric_limits<double>::infinity());
  CHECK(m.mssim == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(m.mssim_covisible == doctest::Approx(1.0).epsilon(1e-15));
  CHECK(m.ssim == doctest::Approx(1.0).epsilon(1e-15));
}

TEST_CASE("dycheck quantisation: truncates after clipping, then k / 255 in float") {
  Image im(6, 1, 1);
  im.pixels = {0.5f / 255, 7.9f / 255, -0.3f, 1.7f, std::numeric_limits<float>::quiet_NaN(), 1.0f};
  const Image q = trainer::dycheck_quantize(im);
  CHECK(q.pixels[0] == 0.0f);
  CHECK(q.pixels[1] == 7.0f / 255.0f);  // rounding would give 8
  CHECK(q.pixels[2] == 0.0f);
  CHECK(q.pixels[3] == 1.0f);
  CHECK(q.pixels[4] == 0.0f);
  CHECK(q.pixels[5] == 1.0f);
  for (int k = 0; k < 256; ++k) {  // exact levels stay put
    Image e(1, 1, 1, static_cast<float>(k) / 255.0f);
    CHECK(trainer::dycheck_quantize(e).pixels[0] == static_cast<float>(k) / 255.0f);
  }
}

TEST_CASE("dycheck image metrics: values within one 8-bit level give identical metrics") {
  smg::test::Rng rng(15);
  const int W = 24, H = 18;
  // Levels k, inputs (k + u) / 255 with u in [0.1, 0.9): two draws of u, the same levels.
  std::vector<int> gk(std::size_t(W) * H * 3), pk(gk.size());
  for (std::size_t i = 0; i < gk.size(); ++i) {
    gk[i] = rng.integer(0, 254);
    pk[i] = std::min(254, std::max(0, gk[i] + rng.integer(-40, 40)));
  }
  const auto make = [&](const std::vector<int>& k) {
    Image im(W, H, 3);
    for (std::size_t i = 0; i < k.size(); ++i) im.pixels[i] = static_cast<float>((k[i] + rng.uniform(0.1, 0.9)) / 255);
    return im;
  };
  const Mask cov = random_mask(rng, W, H, 0.7);
  const Image g1 = make(gk), p1 = make(pk), g2 = make(gk), p2 = make(pk);
  CHECK(g1.pixels != g2.pixels);
  const trainer::DycheckImageMetrics m1 = trainer::dycheck_image_metrics(g1, p1, cov);
  const trainer::DycheckImageMetrics m2 = trainer::dycheck_image_metrics(g2, p2, cov);
  CHECK(m1.mpsnr == m2.mpsnr);
  CHECK(m1.mssim == m2.mssim);
  CHECK(m1.mssim_covisible == m2.mssim_covisible);
  CHECK(m1.psnr == m2.psnr);
  CHECK(m1.ssim == m2.ssim);
  // ... and they are the metrics of the quantised images.
  const Image gq = trainer::dycheck_quantize(g1), pq = trainer::dycheck_quantize(p1);
  CHECK(m1.mpsnr == trainer::dycheck_psnr(gq, pq, cov));
  CHECK(m1.mssim == trainer::dycheck_ssim(gq, pq, cov).mean);
  CHECK(m1.ssim == trainer::dycheck_ssim(gq, pq).mean);
  CHECK(m1.mpsnr != trainer::dycheck_psnr(g1, p1, cov));  // unquantised inputs differ
  CHECK(m1.mpsnr != m1.psnr);
  CHECK(m1.mssim != m1.ssim);
}

TEST_CASE("dycheck psnr: hand-computed 2x2 example") {
  // gt black; pred errors (after truncation to 8 bit): pixel (0,0) red 51/255 = 0.2, pixel
  // (1,0) green 102/255 = 0.4 (masked out), pixel (0,1) none, pixel (1,1) blue 1.
  Image gt(2, 2, 3, 0.0f), pred(2, 2, 3, 0.0f);
  pred.at(0, 0, 0) = 51.7f / 255;
  pred.at(1, 0, 1) = 102.5f / 255;
  pred.at(1, 1, 2) = 1.0f;
  const Mask cov = {1, 0, 1, 1};  // [y][x]
  const Image g = trainer::dycheck_quantize(gt), p = trainer::dycheck_quantize(pred);
  // mPSNR = -10 log10((0.2^2 + 1^2) / (3 pixels * 3 channels)) = 10 log10(9 / 1.04).
  CHECK(trainer::dycheck_psnr(g, p, cov) == doctest::Approx(9.372091701).epsilon(1e-8));
  // Unmasked: (0.04 + 0.16 + 1) / 12 = 0.1 -> 10 dB.
  CHECK(trainer::dycheck_psnr(g, p) == doctest::Approx(10.0).epsilon(1e-7));
}

TEST_CASE("dycheck metrics: bad sizes throw std::invalid_argument naming the argument") {
  const Image a(12, 11, 3, 0.5f), b(12, 11, 3, 0.25f);
  CHECK(error_of([&] { trainer::dycheck_image_metrics(a, Image(11, 12, 3), {}); }).find("pred") != std::string::npos);
  CHECK(error_of([&] { trainer::dycheck_image_metrics(a, Image(12, 11, 1), {}); }).find("pred") != std::string::npos);
  CHECK(error_of([&] { trainer::dycheck_image_metrics(Image(), Image(), {}); }).find("gt") != std::string::npos);
  CHECK(error_of([&] { trainer::dycheck_image_metrics(a, b, Mask(11 * 11, 1)); }).find("covisible") !=
        std::string::npos);
  CHECK(error_of([&] { trainer::dycheck_image_metrics(a, b, Mask(12 * 11, 255)); }).find("covisible") !=
        std::string::npos);
  CHECK(error_of([&] { trainer::dycheck_image_metrics(Image(10, 20, 3), Image(10, 20, 3), {}); }).find("gt") !=
        std::string::npos);
  CHECK(error_of([&] { trainer::dycheck_ssim_map(Image(20, 10, 3), Image(20, 10, 3)); }).find("11x11") !=
        std::string::npos);
  CHECK(error_of([&] { trainer::dycheck_psnr(a, Image(12, 12, 3)); }).find("dycheck_psnr") != std::string::npos);
  CHECK(error_of([&] { trainer::dycheck_psnr(a, b, Mask(3, 1)); }).find("mask") != std::string::npos);
  CHECK_NOTHROW(trainer::dycheck_image_metrics(a, b, {}));
  CHECK_NOTHROW(trainer::dycheck_psnr(Image(2, 2, 3), Image(2, 2, 3)));  // PSNR has no minimum size
}
