// examples/trainer/dycheck_metrics.cpp — Dycheck's mPSNR / mSSIM (see dycheck_metrics.hpp for
// the source lines followed).
#include "trainer/dycheck_metrics.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>

namespace trainer {

namespace {

constexpr int kSize = 11;  // compute_ssim: filter_size = 11
constexpr int kHalf = kSize / 2;
constexpr double kFilterSigma = 1.5;  // filter_sigma
constexpr double kK1 = 0.01, kK2 = 0.03, kMaxVal = 1.0;
constexpr int kQuantities = 5;  // x, y, x^2, y^2, x*y

std::string size_of(const Image& im) {
  return std::to_string(im.width) + "x" + std::to_string(im.height) + "x" + std::to_string(im.channels);
}

// Throws unless a and b are non-empty and of equal size, and the mask is empty or [H][W] 0/1; the
// message names the function and the argument.
struct ArgNames {
  const char* fn;
  const char* a;
  const char* b;
  const char* mask;
};
void check_inputs(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask, ArgNames n) {
  const std::string fn = n.fn;
  if (a.empty() || a.width <= 0 || a.height <= 0 || a.channels <= 0 ||
      a.pixels.size() != static_cast<std::size_t>(a.width) * static_cast<std::size_t>(a.height) *
                             static_cast<std::size_t>(a.channels))
    throw std::invalid_argument(fn + ": " + n.a + " must be a non-empty, consistent image, got " + size_of(a));
  if (b.width != a.width || b.height != a.height || b.channels != a.channels || b.pixels.size() != a.pixels.size())
    throw std::invalid_argument(fn + ": " + n.b + " must have " + n.a + "'s size " + size_of(a) + ", got " +
                                size_of(b));
  if (mask.empty()) return;
  if (mask.size() != static_cast<std::size_t>(a.width) * static_cast<std::size_t>(a.height))
    throw std::invalid_argument(fn + ": " + n.mask + " must be empty or [H][W] = " + std::to_string(a.height) + "x" +
                                std::to_string(a.width) + " bytes, got " + std::to_string(mask.size()));
  for (std::uint8_t m : mask)
    if (m > 1) throw std::invalid_argument(fn + ": " + n.mask + " values must be 0 or 1, got " + std::to_string(m));
}

ArgNames plain(const char* fn) { return ArgNames{fn, "a", "b", "mask"}; }

// compute_ssim: hw = filter_size // 2; shift = (2 hw - filter_size + 1) / 2 (= 0 for odd sizes);
// f_i = ((i - hw + shift) / sigma)^2; filt = exp(-0.5 f_i); filt /= sum(filt). Symmetric, so
// jsp.signal.convolve2d's kernel flip changes nothing.
std::array<double, kSize> gaussian_filter() {
  std::array<double, kSize> f{};
  double sum = 0;
  for (int i = 0; i < kSize; ++i) {
    const double t = (i - kHalf) / kFilterSigma;
    sum += f[static_cast<std::size_t>(i)] = std::exp(-0.5 * t * t);
  }
  for (double& v : f) v /= sum;
  return f;
}

}  // namespace

Image dycheck_quantize(const Image& img) {
  Image out = img;
  for (float& v : out.pixels) {
    // to_uint8: (img * UINT8_MAX).clip(0.0, UINT8_MAX).astype(np.uint8) — a float32 product,
    // clipped, truncated toward zero. NaN (undefined for numpy's cast) becomes 0 here.
    float s = v * 255.0f;
    if (!(s > 0.0f)) s = 0.0f;
    if (s > 255.0f) s = 255.0f;
    const auto k = static_cast<std::uint8_t>(s);
    // to_float32: img.astype(np.float32) / UINT8_MAX, in float32.
    v = static_cast<float>(k) / 255.0f;
  }
  return out;
}

double dycheck_psnr(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask) {
  check_inputs(a, b, mask, plain("dycheck_psnr"));
  const std::size_t pixels = static_cast<std::size_t>(a.width) * static_cast<std::size_t>(a.height);
  const auto C = static_cast<std::size_t>(a.channels);
  // compute_psnr: mse = (img0 - img1) ** 2; masked_mean(mse, mask) = (x * mask).sum() /
  // mask.sum().clip(1e-6) with the (H, W, 1) mask broadcast to (H, W, C).
  double num = 0, den = 0;
  for (std::size_t p = 0; p < pixels; ++p) {
    const double m = mask.empty() ? 1.0 : static_cast<double>(mask[p]);
    for (std::size_t c = 0; c < C; ++c) {
      const double d = static_cast<double>(a.pixels[p * C + c]) - static_cast<double>(b.pixels[p * C + c]);
      num += d * d * m;
      den += m;
    }
  }
  // -10.0 / jnp.log(10.0) * jnp.log(masked_mean): log(0) = -inf gives +inf.
  return -10.0 / std::log(10.0) * std::log(num / std::max(den, 1e-6));
}

std::vector<double> dycheck_ssim_map(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask) {
  check_inputs(a, b, mask, plain("dycheck_ssim_map"));
  if (a.width < kSize || a.height < kSize)
    throw std::invalid_argument("dycheck_ssim_map: a must be at least 11x11, got " + size_of(a));
  const int W = a.width, H = a.height, C = a.channels;
  const int OW = W - 2 * kHalf, OH = H - 2 * kHalf;
  const auto f = gaussian_filter();
  const std::size_t Q = static_cast<std::size_t>(C) * kQuantities;  // doubles per position
  const auto mask_at = [&](int x, int y) {
    return mask.empty() ? std::uint8_t{1} : mask[static_cast<std::size_t>(y) * W + x];
  };

  // Streaming over input rows: pass 1 (x) fills a ring of the last 11 filtered rows, pass 2 (y)
  // combines them into one output row; memory is O(11 W), not O(H W).
  const std::size_t rowQ = static_cast<std::size_t>(OW) * Q;
  std::vector<double> zrow(static_cast<std::size_t>(W) * Q);  // one input row of z * m
  std::vector<double> ring(rowQ * kSize, 0.0);                  // pass-1 rows y % 11
  std::vector<std::uint8_t> ring_m(static_cast<std::size_t>(OW) * kSize, 0);
  const double c1 = (kK1 * kMaxVal) * (kK1 * kMaxVal), c2 = (kK2 * kMaxVal) * (kK2 * kMaxVal);
  std::vector<double> map(static_cast<std::size_t>(OW) * OH * C);
  std::vector<double> acc(rowQ);
  std::vector<int> count(static_cast<std::size_t>(OW));
  for (int yin = 0; yin < H; ++yin) {
    // The five quantities z (x, y, x^2, y^2, x y per channel) times the mask: convolve2d's z * m.
    for (int x = 0; x < W; ++x) {
      const double m = mask_at(x, yin);
      double* z = &zrow[static_cast<std::size_t>(x) * Q];
      for (int c = 0; c < C; ++c) {
        const double p = a.at(x, yin, c), q = b.at(x, yin, c);
        z[c * kQuantities + 0] = p * m;
        z[c * kQuantities + 1] = q * m;
        z[c * kQuantities + 2] = p * p * m;
        z[c * kQuantities + 3] = q * q * m;
        z[c * kQuantities + 4] = p * q * m;
      }
    }

    // Pass 1 (filt_fn2, filt[None, :]: along x). convolve2d returns
    // jnp.where(m_ != 0, z_ * ones_like(f).sum() / m_, 0) and the new mask (m_ != 0). As 11
    // shifted axpys over the row (position x, quantity k at x * Q + k), which vectorise.
    const auto slot = static_cast<std::size_t>(yin % kSize);
    double* out = &ring[slot * rowQ];
    std::uint8_t* out_m = &ring_m[slot * static_cast<std::size_t>(OW)];
    std::fill(out, out + rowQ, 0.0);
    for (int j = 0; j < kSize; ++j) {
      const double fj = f[static_cast<std::size_t>(j)];
      const double* z = zrow.data() + static_cast<std::size_t>(j) * Q;
      for (std::size_t i = 0; i < rowQ; ++i) out[i] += fj * z[i];
    }
    for (int x = 0; x < OW; ++x) {
      int n = 0;
      for (int j = 0; j < kSize; ++j) n += mask_at(x + j, yin);
      double* o = out + static_cast<std::size_t>(x) * Q;
      out_m[x] = n != 0 ? 1 : 0;
      for (std::size_t k = 0; k < Q; ++k) o[k] = n != 0 ? o[k] * kSize / n : 0.0;  // where(m_ != 0, ..., 0)
    }
    if (yin < kSize - 1) continue;

    // Pass 2 (filt_fn1, filt[:, None]: along y) over pass-1 rows y .. y+10 and their binarised
    // mask; z * m needs no product as pass 1 left z = 0 where m = 0. Then SSIM per channel.
    const int y = yin - (kSize - 1);
    std::fill(acc.begin(), acc.end(), 0.0);
    std::fill(count.begin(), count.end(), 0);
    for (int r = 0; r < kSize; ++r) {
      const double fr = f[static_cast<std::size_t>(r)];
      const auto src = static_cast<std::size_t>((y + r) % kSize);
      const double* z = &ring[src * rowQ];
      for (std::size_t i = 0; i < rowQ; ++i) acc[i] += fr * z[i];
      const std::uint8_t* m = &ring_m[src * static_cast<std::size_t>(OW)];
      for (int x = 0; x < OW; ++x) count[static_cast<std::size_t>(x)] += m[x];
    }
    for (int x = 0; x < OW; ++x) {
      const int n = count[static_cast<std::size_t>(x)];
      const double* s = &acc[static_cast<std::size_t>(x) * Q];
      for (int c = 0; c < C; ++c) {
        std::array<double, kQuantities> v{};
        for (std::size_t k = 0; k < kQuantities; ++k)
          v[k] = n != 0 ? s[static_cast<std::size_t>(c) * kQuantities + k] * kSize / n : 0.0;
        // compute_ssim: mu00 = mu0 * mu0, ...; sigma00 = filt(img0**2) - mu00, ...
        const double mu0 = v[0], mu1 = v[1];
        const double mu00 = mu0 * mu0, mu11 = mu1 * mu1, mu01 = mu0 * mu1;
        // "Clip the variances and covariances to valid values."
        const double sigma00 = std::max(0.0, v[2] - mu00);
        const double sigma11 = std::max(0.0, v[3] - mu11);
        double sigma01 = v[4] - mu01;
        const double sign = sigma01 > 0 ? 1.0 : (sigma01 < 0 ? -1.0 : 0.0);  // jnp.sign
        sigma01 = sign * std::min(std::sqrt(sigma00 * sigma11), std::abs(sigma01));
        const double numer = (2 * mu01 + c1) * (2 * sigma01 + c2);
        const double denom = (mu00 + mu11 + c1) * (sigma00 + sigma11 + c2);
        map[(static_cast<std::size_t>(y) * OW + x) * C + c] = numer / denom;
      }
    }
  }
  return map;
}

DycheckSsim dycheck_ssim(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask) {
  const std::vector<double> map = dycheck_ssim_map(a, b, mask);
  const int OW = a.width - 2 * kHalf, OH = a.height - 2 * kHalf, C = a.channels;
  DycheckSsim r;
  // ssim = ssim_map.mean(): every position and channel, masked out or not.
  double total = 0;
  for (double v : map) total += v;
  r.mean = total / static_cast<double>(map.size());
  // Our extra: channel-averaged map over the positions whose window centre is masked.
  double cov = 0;
  long long n = 0;
  for (int y = 0; y < OH; ++y)
    for (int x = 0; x < OW; ++x) {
      if (!mask.empty() && mask[static_cast<std::size_t>(y + kHalf) * a.width + x + kHalf] == 0) continue;
      double s = 0;
      for (int c = 0; c < C; ++c) s += map[(static_cast<std::size_t>(y) * OW + x) * C + c];
      cov += s / C;
      ++n;
    }
  r.mean_covisible = n > 0 ? cov / static_cast<double>(n) : std::numeric_limits<double>::quiet_NaN();
  return r;
}

DycheckImageMetrics dycheck_image_metrics(const Image& gt, const Image& pred,
                                          const std::vector<std::uint8_t>& covisible) {
  check_inputs(gt, pred, covisible, ArgNames{"dycheck_image_metrics", "gt", "pred", "covisible"});
  if (gt.width < kSize || gt.height < kSize)
    throw std::invalid_argument("dycheck_image_metrics: gt must be at least 11x11, got " + size_of(gt));
  // NovelView.finalize: rgb = to_quantized_float32(batch["rgb"]), pred_rgb likewise.
  const Image g = dycheck_quantize(gt), p = dycheck_quantize(pred);
  DycheckImageMetrics m;
  m.mpsnr = dycheck_psnr(g, p, covisible);
  const DycheckSsim s = dycheck_ssim(g, p, covisible);
  m.mssim = s.mean;
  m.mssim_covisible = s.mean_covisible;
  m.psnr = dycheck_psnr(g, p);
  m.ssim = dycheck_ssim(g, p).mean;
  return m;
}

}  // namespace trainer
