// examples/trainer/dycheck_metrics.hpp — Dycheck's image metrics (mPSNR, mSSIM), as its code
// computes them.
//
// Reference: KAIR-BAIR/dycheck, read at commit b19e8f0d:
//   dycheck/core/tasks/novel_view.py   (NovelView.finalize: quantise, then compute_psnr/ssim)
//   dycheck/utils/image.py             (to_quantized_float32 = to_float32(to_uint8(img)))
//   dycheck/core/metrics/image.py      (compute_psnr, compute_ssim)
//   dycheck/nn/functional/common.py    (masked_mean)
//
// What Dycheck does, and what these functions replicate:
//
// * Quantisation (to_uint8): k = uint8(clip(x * 255, 0, 255)) — truncation toward zero, not
//   rounding — then k / 255 in float32 (to_float32). Ground truth, prediction and the
//   covisible mask all go through it; the mask here is already 0/1 bytes, for which it is exact.
//
// * mPSNR (compute_psnr + masked_mean): -10 / ln 10 * ln( sum(m (a - b)^2) / max(sum(m), 1e-6) ),
//   the mask [H][W] broadcast over the channels (so sum(m) = covisible pixels * C). Identical
//   images give ln 0 = -inf, i.e. +inf dB; an all-zero mask gives 0 / 1e-6 = 0, also +inf.
//
// * mSSIM (compute_ssim): 1D Gaussian f_i = exp(-((i - 5) / 1.5)^2 / 2), i = 0..10, normalised to
//   sum 1, K1 = 0.01, K2 = 0.03, max value 1. Each local mean is filtered by two separable
//   "valid" passes, first along x (width), then along y, each pass a partial convolution:
//     z' = conv(z * m, f);  n = conv(m, ones(11));  out = n != 0 ? z' * 11 / n : 0;
//     m_next = (n != 0)
//   i.e. the renormalisation is by the *count* of masked taps (11 / n), not by the filter weight
//   they carry, and the second pass uses the binarised first-pass mask. This is therefore not a
//   2D partial convolution with an 11x11 count. sigma_xx = filt(x^2) - mu_x^2 clipped at 0,
//   sigma_xy = sign(sigma_xy) min(sqrt(sigma_xx sigma_yy), |sigma_xy|); the SSIM map is
//   (H-10) x (W-10) x C and mSSIM is its plain mean over all entries — positions whose window
//   holds no masked pixel have mu = sigma = 0 and so SSIM exactly 1, and they are included.
//
// Differences: Dycheck computes in float32 (jax, Precision.HIGHEST); here every sum and the
// filter are double. `mssim_covisible` (the mean SSIM over window centres on covisible pixels)
// is an extra of ours, not a Dycheck number.
#pragma once

#include <cstdint>
#include <vector>

#include "trainer/image.hpp"

namespace trainer {

// Dycheck's to_quantized_float32: each value x becomes float(k) / 255.0f with
// k = trunc(clip(x * 255, 0, 255)) (x * 255 in float; NaN becomes 0). Same size as `img`.
Image dycheck_quantize(const Image& img);

// Dycheck's compute_psnr with a [H][W] 0/1 mask (empty = all ones), in dB, on the values as given
// (no quantisation). +inf for identical images and for an all-zero mask (Dycheck's
// max(sum m, 1e-6) guard). Throws std::invalid_argument when the images differ in size or are
// empty, or the mask has a wrong size or a value other than 0/1.
double dycheck_psnr(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask = {});

// Dycheck's masked SSIM map, [H-10][W-10][C] doubles (row-major; entry (x, y, c) is the window
// whose top-left image pixel is (x, y), centre (x+5, y+5)), on the values as given. Mask
// convention and errors as dycheck_psnr; also throws when the images are smaller than 11x11.
std::vector<double> dycheck_ssim_map(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask = {});

struct DycheckSsim {
  double mean = 0;            // Dycheck's mSSIM: the mean of the whole map (all positions, channels)
  double mean_covisible = 0;  // mean over the positions whose centre pixel is masked (NaN if none)
};
// Both means of dycheck_ssim_map(a, b, mask).
DycheckSsim dycheck_ssim(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask = {});

// One validation frame, as NovelView.finalize evaluates it: gt and pred quantised
// (dycheck_quantize), then the metrics with the covisible mask and unmasked (mask all ones).
struct DycheckImageMetrics {
  double mpsnr = 0;            // dB, covisible pixels
  double mssim = 0;            // Dycheck's masked SSIM (mean of the whole map)
  double mssim_covisible = 0;  // same map, mean over covisible window centres (our extra)
  double psnr = 0;             // dB, all pixels
  double ssim = 0;             // all pixels
};
// gt, pred: [H][W][C] in [0, 1], at least 11x11; covisible: [H][W] 0/1, empty = all ones.
// Throws std::invalid_argument as dycheck_ssim_map.
DycheckImageMetrics dycheck_image_metrics(const Image& gt, const Image& pred,
                                          const std::vector<std::uint8_t>& covisible);

}  // namespace trainer
