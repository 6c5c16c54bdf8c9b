// examples/trainer/metrics.hpp — image quality (PSNR, SSIM) and 3D tracking error (EPE).
//
// Images are trainer::Image, [H][W][C] floats in [0, 1]. Masks are [H][W] bytes (nonzero = use),
// or null for the whole image.
//
// SSIM is Wang, Bovik, Sheikh & Simoncelli (2004): 11x11 Gaussian window, sigma 1.5 (normalised
// to sum 1), K1 = 0.01, K2 = 0.03, dynamic range 1, population (biased) variances, computed per
// channel over the "valid" window positions (no padding; the map is (H-10) x (W-10)) and averaged
// over positions and channels. This is the reference MATLAB ssim.m per channel and equals
// scikit-image's structural_similarity(gaussian_weights=True, sigma=1.5,
// use_sample_covariance=False, data_range=1, channel_axis=-1) after its border crop.
#pragma once

#include <cstdint>
#include <vector>

#include "smg/core/views.hpp"
#include "trainer/image.hpp"

namespace trainer {

// Peak signal-to-noise ratio in dB, 10 log10(peak^2 / MSE), MSE over the masked pixels and all
// channels. +inf for identical images; NaN for an empty mask. Throws std::invalid_argument on
// a size mismatch.
double psnr(const Image& a, const Image& b, const std::uint8_t* mask = nullptr, double peak = 1.0);

// SSIM map, channel-averaged, over the valid window positions: an (W-10) x (H-10) one-channel
// image whose pixel (x, y) belongs to the window centred on image pixel (x+5, y+5). Throws
// std::invalid_argument when the images differ in size or are smaller than 11x11.
Image ssim_map(const Image& a, const Image& b);

// Mean SSIM. With a mask: the mean over the window positions whose centre pixel is masked
// (NaN if none is).
double ssim(const Image& a, const Image& b, const std::uint8_t* mask = nullptr);

// 3D end-point error of estimated trajectories against the truth, both [T][N][3], over the
// samples where `mask` [T][N] is 1 (all samples when the mask view is empty).
struct TrackingError {
  double epe = 0;         // mean Euclidean error, world units
  double within_5 = 0;    // fraction of samples with error < 0.05 * extent
  double within_10 = 0;   // fraction with error < 0.10 * extent
  long long samples = 0;  // samples counted (NaN metrics when 0)
};
TrackingError tracking_error(smg::PositionsView<const double> estimate, smg::PositionsView<const double> truth,
                             double extent, smg::VisibilityView<const std::uint8_t> mask = {});

}  // namespace trainer
