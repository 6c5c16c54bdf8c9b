// PSNR, SSIM and 3D tracking error on hand-checkable cases and against a direct
// (non-separable) SSIM written from the paper's definition.
#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "support/random.hpp"
#include "trainer/metrics.hpp"
#include "trainer/ssim_reference.hpp"

using trainer::Image;
using trainer::test::plain_ssim;
using trainer::test::random_image;

namespace {

Image constant(int w, int h, int c, float v) { return Image(w, h, c, v); }

}  // namespace

TEST_CASE("psnr: identical images are infinite, a uniform error of 0.1 is 20 dB, masks select pixels") {
  const Image a = constant(16, 12, 3, 0.5f);
  CHECK(std::isinf(trainer::psnr(a, a)));
  const Image b = constant(16, 12, 3, 0.6f);
  CHECK(trainer::psnr(a, b) == doctest::Approx(20.0).epsilon(1e-5));
  CHECK(trainer::psnr(a, b, nullptr, 255.0) == doctest::Approx(20.0 + 20 * std::log10(255.0)).epsilon(1e-5));
  // Half of the pixels wrong by 0.2, the other half right: MSE 0.02, 16.99 dB; masked to the
  // right half: infinite.
  Image c = a;
  std::vector<std::uint8_t> mask(16 * 12, 0);
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 16; ++x) {
      if (x < 8)
        for (int k = 0; k < 3; ++k) c.at(x, y, k) = 0.7f;
      else
        mask[static_cast<std::size_t>(y) * 16 + x] = 1;
    }
  CHECK(trainer::psnr(a, c) == doctest::Approx(10 * std::log10(1 / 0.02)).epsilon(1e-5));
  CHECK(std::isinf(trainer::psnr(a, c, mask.data())));
  std::vector<std::uint8_t> none(16 * 12, 0);
  CHECK(std::isnan(trainer::psnr(a, c, none.data())));
  CHECK_THROWS_AS(trainer::psnr(a, constant(16, 11, 3, 0.5f)), std::invalid_argument);
}

TEST_CASE("ssim: identical images give 1, constant images the luminance term, symmetric") {
  SMG_TEST_RNG(rng, 2);
  const Image a = random_image(rng, 24, 20, 3);
  CHECK(trainer::ssim(a, a) == doctest::Approx(1.0).epsilon(1e-12));
  // Constant images: zero variances, so SSIM = (2 mu_x mu_y + C1) / (mu_x^2 + mu_y^2 + C1).
  const double C1 = 1e-4;
  const double expect = (2 * 0.2 * 0.6 + C1) / (0.04 + 0.36 + C1);
  CHECK(trainer::ssim(constant(20, 20, 1, 0.2f), constant(20, 20, 1, 0.6f)) == doctest::Approx(expect).epsilon(1e-6));
  const Image b = random_image(rng, 24, 20, 3);
  CHECK(trainer::ssim(a, b) == doctest::Approx(trainer::ssim(b, a)).epsilon(1e-12));
  // The map covers the valid window positions: (W - 10) x (H - 10).
  const Image m = trainer::ssim_map(a, b);
  CHECK(m.width == 14);
  CHECK(m.height == 10);
  CHECK(m.channels == 1);
  CHECK_THROWS_AS(trainer::ssim(constant(10, 20, 1, 0), constant(10, 20, 1, 0)), std::invalid_argument);
}

TEST_CASE("ssim: the separable implementation equals the direct definition; decreases with noise") {
  SMG_TEST_RNG(rng, 9);
  Image a = random_image(rng, 30, 22, 3);
  // Smooth it a bit so that the structure term matters.
  for (int y = 0; y < a.height; ++y)
    for (int x = 1; x < a.width; ++x)
      for (int c = 0; c < 3; ++c) a.at(x, y, c) = 0.5f * (a.at(x, y, c) + a.at(x - 1, y, c));
  double previous = 1.0;
  for (double sigma : {0.02, 0.05, 0.1, 0.2}) {
    Image b = a;
    for (float& v : b.pixels) v = static_cast<float>(std::clamp(v + sigma * rng.normal(), 0.0, 1.0));
    const double s = trainer::ssim(a, b);
    CHECK(s == doctest::Approx(plain_ssim(a, b)).epsilon(1e-6));
    CHECK(s < previous);
    previous = s;
  }
}

TEST_CASE("ssim: masked mean over window centres") {
  smg::test::Rng rng(4);
  const Image a = random_image(rng, 26, 21, 3), b = random_image(rng, 26, 21, 3);
  std::vector<std::uint8_t> all(26 * 21, 1);
  CHECK(trainer::ssim(a, b, all.data()) == doctest::Approx(trainer::ssim(a, b)).epsilon(1e-12));
  // Only the window centred on pixel (12, 9): map entry (7, 4).
  std::vector<std::uint8_t> one(26 * 21, 0);
  one[9 * 26 + 12] = 1;
  CHECK(trainer::ssim(a, b, one.data()) == doctest::Approx(trainer::ssim_map(a, b).at(7, 4)).epsilon(1e-12));
  std::vector<std::uint8_t> border(26 * 21, 0);
  border[0] = 1;  // no window is centred at the corner
  CHECK(std::isnan(trainer::ssim(a, b, border.data())));
}

TEST_CASE("tracking_error: EPE and thresholds at 5% and 10% of the extent, with a mask") {
  // 1 frame, 4 points with errors 0, 0.03, 0.07, 0.2; extent 1.
  const double truth[] = {0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3};
  const double est[] = {0, 0, 0, 1.03, 1, 1, 2, 2.07, 2, 3, 3, 3.2};
  const smg::PositionsView<const double> T(truth, 1, 4), E(est, 1, 4);
  const auto e = trainer::tracking_error(E, T, 1.0);
  CHECK(e.samples == 4);
  CHECK(e.epe == doctest::Approx((0 + 0.03 + 0.07 + 0.2) / 4));
  CHECK(e.within_5 == doctest::Approx(0.5));
  CHECK(e.within_10 == doctest::Approx(0.75));
  // Extent 2: thresholds 0.1 and 0.2 (strict): 0.2 is not within.
  CHECK(trainer::tracking_error(E, T, 2.0).within_10 == doctest::Approx(0.75));
  CHECK(trainer::tracking_error(E, T, 2.0).within_5 == doctest::Approx(0.75));
  const std::uint8_t m[] = {0, 1, 0, 1};
  const auto em = trainer::tracking_error(E, T, 1.0, smg::VisibilityView<const std::uint8_t>(m, 1, 4));
  CHECK(em.samples == 2);
  CHECK(em.epe == doctest::Approx(0.115));
  CHECK(em.within_5 == doctest::Approx(0.5));
  const std::uint8_t none[] = {0, 0, 0, 0};
  CHECK(std::isnan(trainer::tracking_error(E, T, 1.0, smg::VisibilityView<const std::uint8_t>(none, 1, 4)).epe));
  CHECK_THROWS_AS(trainer::tracking_error(E, smg::PositionsView<const double>(truth, 1, 3), 1.0), std::invalid_argument);
  CHECK_THROWS_AS(trainer::tracking_error(E, T, 0.0), std::invalid_argument);
}
