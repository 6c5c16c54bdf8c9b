// smg/splat/rasterize.hpp — per-tile front-to-back compositing and its analytic backward.
//
// One tile of W x W pixels composites its depth-sorted Gaussian list:
//   sigma = ½ (a dx² + c dy²) + b dx dy,  dx = mean_x - px, dy = mean_y - py        (R9)
//   alpha = min(alpha_max, o exp(-sigma)); skip when sigma < 0 or alpha < 1/255        (R10)
//   if T (1 - alpha) <= 1e-4 the pixel is done and this Gaussian is NOT composited     (R11)
//   C += alpha T c,  D += alpha T z,  T *= 1 - alpha                                   (R12)
// The loops run Gaussian-outer, pixel-inner with the pixel state in structure-of-arrays
// form. A Gaussian visits, row by row, only the groups of 4 (8 with AVX) pixels that meet its
// ellipse {sigma <= ln(255 o) + 1e-3}, outside of which alpha < 1/255 for certain; the set
// visited is a superset of the pixels that pass (R10), so the result is that of testing
// every pixel of the tile, as gsplat does. Every per-pixel decision is a branch-free select
// so that the lane loops vectorise. The backward walks the same lists front to back,
// recomputing T as the forward did, and obtains the "behind" sums from the stored totals
// (R16)-(R19). Per-(Gaussian, tile) partial gradients are written to their own row, so the
// reduction over tiles (render.hpp) is deterministic. Internal to render.hpp.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "smg/core/scalar.hpp"
#include "smg/core/types.hpp"
#include "smg/splat/settings.hpp"
#include "smg/splat/workspace.hpp"

namespace smg::splat::detail {
// The lane groups below follow __AVX__: an ISA-specific namespace (smg/core/config.hpp).
inline namespace SMG_ISA_NAMESPACE {

// Fields of a projected record (RenderWorkspace::proj), followed by the C colour values.
// kExtY: half height of the ellipse {sigma <= cut}; per row dy its x-extent is
// mean_x + (b/a) dy ± sqrt(2 a cut - (ac - b²) dy²) / a, from kBoA, kInvA, kTwoACut, kDetQ.
enum RecordField : int {
  kMx, kMy, kConA, kConB, kConC, kOpa, kDepth, kExtY, kBoA, kInvA, kTwoACut, kDetQ, kRecordFields
};
// Fields of a per-(Gaussian, tile) gradient row, followed by the C colour gradients.
enum GradField : int { kGMx, kGMy, kGConA, kGConB, kGConC, kGOpa, kGDepth, kGradFields };

template <int C>
constexpr int record_stride(Index channels) {
  return C > 0 ? kRecordFields + C : kRecordFields + static_cast<int>(channels);
}
template <int C>
constexpr int grad_stride(Index channels) {
  return C > 0 ? kGradFields + C : kGradFields + static_cast<int>(channels);
}

// Branch-free building blocks. GCC (without -ffast-math) keeps floating-point operations
// that could trap out of if-converted code, and readily sinks them into branches of a
// ternary; a loop with such a branch is not vectorised. So every per-pixel choice below is
// a bitwise select between values computed unconditionally, and exp's clamp works on bits.
template <class S>
using Bits = typename smg::detail::FloatBits<S>::Unsigned;  // S's bits as an unsigned integer

// c ? a : b, bitwise.
template <class S>
inline S select(bool c, S a, S b) {
  using U = Bits<S>;
  U ua, ub;
  std::memcpy(&ua, &a, sizeof(S));
  std::memcpy(&ub, &b, sizeof(S));
  const U m = U(0) - U(c);
  const U r = (ua & m) | (ub & ~m);
  S out;
  std::memcpy(&out, &r, sizeof(S));
  return out;
}

// x with |x| limited to lim_bits (the bit pattern of a positive limit), sign kept.
template <class S>
inline S clamp_magnitude(S x, Bits<S> lim_bits) {
  using U = Bits<S>;
  constexpr U sign_bit = U(1) << (8 * sizeof(S) - 1);
  U u;
  std::memcpy(&u, &x, sizeof(S));
  const U mag = u & ~sign_bit;
  u = (u & sign_bit) | (mag < lim_bits ? mag : lim_bits);
  std::memcpy(&x, &u, sizeof(S));
  return x;
}

// 2^n from tn = n + magic, n an integer rounded by the 1.5·2^p trick (p the mantissa bits): the
// low bits of tn − magic are n, so the exponent field n + bias is (tn − magic) + bias in integer
// arithmetic, shifted into place. Precondition: n + bias in [1, 2·bias].
template <class S>
SMG_FORCE_INLINE S exp2_rounded(S tn, S magic) {
  using U = Bits<S>;
  constexpr int mantissa = std::numeric_limits<S>::digits - 1;        // 23 or 52
  constexpr U bias = U(std::numeric_limits<S>::max_exponent - 1);     // 127 or 1023
  U tb, mb;
  std::memcpy(&tb, &tn, sizeof(S));
  std::memcpy(&mb, &magic, sizeof(S));
  const U bits = (tb - mb + bias) << mantissa;
  S scale;
  std::memcpy(&scale, &bits, sizeof(S));
  return scale;
}

// exp(-x) for the alpha of (R10), vectorisable (a libm call is not): |x| clamped to 87
// (float) / 700 (double), Cody-Waite reduction x = n ln2 + r with n rounded by the 1.5·2^p
// trick, a polynomial for e^r on |r| <= ln2/2 (Cephes' expf coefficients in float, Taylor
// through r^13 in double), 2^n assembled from n's bits. Relative error <= 1.4 ulp (float),
// 1.6 ulp (double) against libm, measured over the clamped range.
inline float exp_neg(float x) {
  x = clamp_magnitude(x, 0x42ae0000u);  // 87.0f
  const float magic = 12582912.0f;      // 1.5 * 2^23: t + magic rounds t to an integer
  const float t = x * -1.44269504088896341f;
  const float tn = t + magic;
  const float n = tn - magic;
  const float r = (-x - n * 0.693359375f) - n * -2.12194440e-4f;
  const float z = r * r;
  float p = 1.9875691500e-4f;
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  const float er = p * z + r + 1.0f;
  return er * exp2_rounded(tn, magic);  // n + 127 in [1, 253]
}
inline double exp_neg(double x) {
  x = clamp_magnitude(x, 0x4085e00000000000ull);  // 700.0
  const double magic = 6755399441055744.0;        // 1.5 * 2^52
  const double t = x * -1.4426950408889634074;
  const double tn = t + magic;
  const double n = tn - magic;
  const double r = (-x - n * 6.93145751953125e-1) - n * 1.42860682030941723212e-6;
  double p = 1.0 / 6227020800.0;  // 1/13!
  p = p * r + 1.0 / 479001600.0;
  p = p * r + 1.0 / 39916800.0;
  p = p * r + 1.0 / 3628800.0;
  p = p * r + 1.0 / 362880.0;
  p = p * r + 1.0 / 40320.0;
  p = p * r + 1.0 / 5040.0;
  p = p * r + 1.0 / 720.0;
  p = p * r + 1.0 / 120.0;
  p = p * r + 1.0 / 24.0;
  p = p * r + 1.0 / 6.0;
  p = p * r + 0.5;
  p = p * r + 1.0;
  p = p * r + 1.0;
  return p * exp2_rounded(tn, magic);  // n + 1023 in [13, 2033]
}

// sigma of (R9) with the per-row terms c dy², b dy hoisted; forward and backward call this one
// function so that they make the same skip decisions.
template <class S>
inline S pixel_sigma(S a, S cdy2, S bdy, S dx) {
  return S(0.5) * (a * dx * dx + cdy2) + bdy * dx;
}

// Rows [r0, r1] of the tile (0-based, within the image) that the Gaussian's alpha >= 1/255
// ellipse can reach; r0 > r1 when none.
template <class S>
inline void row_range(S my, S ext_y, int y0, int rows, int* r0, int* r1) {
  // pixel centre y0 + r + 0.5 within [my - ext_y, my + ext_y], one row of slack each side.
  const S lo = my - ext_y - S(0.5) - S(y0) - S(1);
  const S hi = my + ext_y - S(0.5) - S(y0) + S(1);
  *r0 = lo <= S(0) ? 0 : (lo >= S(rows) ? rows : static_cast<int>(std::ceil(lo)));
  *r1 = hi >= S(rows - 1) ? rows - 1 : (hi < S(0) ? -1 : static_cast<int>(std::floor(hi)));
}

// Records are read in depth order, i.e. at scattered addresses: fetch a few ahead.
inline void prefetch(const void* p) {
#if defined(__GNUC__) || defined(__clang__)
  __builtin_prefetch(p);
#else
  (void)p;
#endif
}
constexpr int kPrefetchAhead = 6;

// Lanes are processed in groups of one vector of float: 4 (SSE2, the x86-64 baseline) or 8
// (when compiled for AVX). A Gaussian's row span is ~5 pixels on average in trained scenes,
// so whole 16-pixel rows would waste 2/3 of the work. (Measured: 8-lane groups are 10% slower
// on SSE2 and 12% faster on AVX-512 hardware built with -march=native.)
#if defined(__AVX__)
constexpr int kGroup = 8;
#else
constexpr int kGroup = 4;
#endif

// Groups [g0, g1) of the tile row at dy (pixel centres x0 + l + 0.5) that can hold a pixel
// with sigma <= cut; g0 >= g1 when none. One lane of slack each side covers rounding.
template <class S, int W>
inline void lane_groups(const S* rec, S dy, int x0, int* g0, int* g1) {
  const S D = rec[kTwoACut] - rec[kDetQ] * dy * dy;
  if (!(D > S(0))) {
    *g0 = *g1 = 0;
    return;
  }
  const S hw = std::sqrt(D) * rec[kInvA];
  const S xc = rec[kMx] + rec[kBoA] * dy - (S(x0) + S(0.5));
  const S lo = xc - hw - S(1), hi = xc + hw + S(2);
  const int l0 = lo <= S(0) ? 0 : (lo >= S(W) ? W : static_cast<int>(lo));
  const int l1 = hi <= S(0) ? 0 : (hi >= S(W) ? W : static_cast<int>(hi));
  *g0 = l0 / kGroup;
  *g1 = (l1 + kGroup - 1) / kGroup;
}

// Row r of a Gaussian's footprint in the tile at (x0, y0): returns dy = mean_y − (y0 + r + 0.5),
// the vertical offset of the row's pixel centres in (R9), and the lane groups [g0, g1) it covers.
template <class S, int W>
SMG_FORCE_INLINE S footprint_row(const S* rec, S my, int y0, int r, int x0, int* g0, int* g1) {
  const S dy = my - (S(y0 + r) + S(0.5));
  lane_groups<S, W>(rec, dy, x0, g0, g1);
  return dy;
}

// Scratch of one tile (per parallel chunk), in S values.
template <int W>
constexpr Index tile_scratch_size(Index channels) {
  // forward: T, T_done, last, depth accumulator, w, C colour accumulators;
  // backward: T, P, K, gz, last, h, w_masked, C colour gradients, group accumulators.
  return Index(W) * W * (6 + channels) + Index(kGroup) * (kGradFields + channels);
}

template <class S, int C, int W>
struct TileContext {
  const RenderWorkspace<S>* ws;
  Index channels;
  S alpha_max;
  const S* background;  // [C] or null
};

// Forward of one group of kGroup pixels of a row. __restrict: the per-pixel arrays do not alias,
// which the vectoriser needs to know.
template <class S, int C>
inline void forward_group(const S* __restrict px, S mx, S a, S cdy2, S bdy, S o, S z,
                          const S* __restrict col, S alpha_max, S irel, S* __restrict Tr,
                          S* __restrict Tdr, S* __restrict lastr, S* __restrict acczr,
                          S* __restrict wr, S* __restrict accr, int acc_stride) {
  const S thr = kAlphaMin<S>;
  const S tmin = kTransmittanceMin<S>;
  for (int l = 0; l < kGroup; ++l) {
    const S dx = mx - px[l];
    const S sigma = pixel_sigma(a, cdy2, bdy, dx);
    const S ao = o * exp_neg(sigma);
    const S alpha = select(ao < alpha_max, ao, alpha_max);
    const S Tl = Tr[l], Td = Tdr[l], lo = lastr[l];
    const S next_T = Tl * (S(1) - alpha);
    const S wv = alpha * Tl;
    const bool valid = (Tl > S(0)) & (sigma >= S(0)) & (alpha >= thr);  // (R10)
    const bool stop = valid & (next_T <= tmin);                          // (R11)
    const bool comp = valid & !stop;
    const S w = select(comp, wv, S(0));
    Tr[l] = select(comp, next_T, select(stop, S(0), Tl));               // (R12)
    Tdr[l] = select(stop, Tl, Td);
    lastr[l] = select(comp, irel, lo);
    acczr[l] += w * z;
    if constexpr (C > 0) {
      for (int k = 0; k < C; ++k) accr[k * acc_stride + l] += w * col[k];
    } else {
      wr[l] = w;
    }
  }
}

// Forward of one tile: composites its list and writes the pixels of the tile into the
// outputs and the per-pixel state the backward needs. A pixel's transmittance is set to 0
// when it is done (its final value kept in T_done), so "T > 0" is "still compositing".
template <class S, int C, int W>
void forward_tile(const TileContext<S, C, W>& cx, RenderWorkspace<S>& ws, Index tile, S* scratch,
                  S* image, S* alpha_out, S* depth_out) {
  constexpr int WW = W * W;
  const int nc = C > 0 ? C : static_cast<int>(cx.channels);
  const int stride = record_stride<C>(cx.channels);
  const int tx = static_cast<int>(tile % ws.tiles_x), ty = static_cast<int>(tile / ws.tiles_x);
  const int x0 = tx * W, y0 = ty * W;
  const int wx = std::min(W, ws.width - x0), wy = std::min(W, ws.height - y0);
  S* T = scratch;          // transmittance, 0 once done
  S* Tdone = T + WW;       // transmittance when done
  S* last = Tdone + WW;    // list position (relative) of the last composited Gaussian, -1
  S* accz = last + WW;     // Σ w z
  S* wbuf = accz + WW;     // weights of the current row (dynamic C only)
  S* acc = wbuf + WW;      // [nc][WW] Σ w c
  for (int p = 0; p < WW; ++p) {
    const int r = p / W, l = p % W;
    T[p] = (r < wy && l < wx) ? S(1) : S(0);  // pixels outside the image never composite
    Tdone[p] = S(0);
    last[p] = S(-1);
    accz[p] = S(0);
    wbuf[p] = S(0);
  }
  for (int k = 0; k < nc * WW; ++k) acc[k] = S(0);
  S px[W];
  for (int l = 0; l < W; ++l) px[l] = S(x0 + l) + S(0.5);

  const S alpha_max = cx.alpha_max;
  const std::int64_t begin = ws.tile_offsets[tile], end = ws.tile_offsets[tile + 1];
  for (std::int64_t i = begin; i < end; ++i) {
    // Every 8 Gaussians: stop when every pixel of the tile is done.
    if (((i - begin) & 7) == 7) {
      bool any = false;
      for (int p = 0; p < WW; ++p) any = any || T[p] > S(0);
      if (!any) break;
    }
    const S irel = S(i - begin);
    if (i + kPrefetchAhead < end)
      prefetch(ws.proj.data() + Index(ws.tile_gauss[i + kPrefetchAhead]) * stride);
    const S* rec = ws.proj.data() + Index(ws.tile_gauss[i]) * stride;
    const S mx = rec[kMx], my = rec[kMy], a = rec[kConA], b = rec[kConB], c = rec[kConC];
    const S o = rec[kOpa], z = rec[kDepth];
    const S* col = rec + kRecordFields;
    int r0, r1;
    row_range(my, rec[kExtY], y0, wy, &r0, &r1);
    for (int r = r0; r <= r1; ++r) {
      int g0, g1;
      const S dy = footprint_row<S, W>(rec, my, y0, r, x0, &g0, &g1);
      const S cdy2 = c * dy * dy, bdy = b * dy;
      const int row = r * W;
      for (int gq = g0; gq < g1; ++gq) {
        const int o4 = row + gq * kGroup;
        // all four pixels done (or outside the image): nothing to composite
        bool live = false;
        for (int l = 0; l < kGroup; ++l) live |= T[o4 + l] > S(0);
        if (!live) continue;
        forward_group<S, C>(px + gq * kGroup, mx, a, cdy2, bdy, o, z, col, alpha_max, irel, T + o4,
                            Tdone + o4, last + o4, accz + o4, wbuf + o4, acc + o4, WW);
      }
      if constexpr (C <= 0) {
        for (int k = 0; k < nc; ++k) {
          const S ck = col[k];
          S* ak = acc + k * WW + row;
          for (int l = g0 * kGroup; l < g1 * kGroup; ++l) ak[l] += wbuf[row + l] * ck;
        }
      }
    }
  }

  const S* bg = cx.background;
  for (int r = 0; r < wy; ++r) {
    for (int l = 0; l < wx; ++l) {
      const int p = r * W + l;
      const Index pix = Index(y0 + r) * ws.width + (x0 + l);
      const S Tf = T[p] > S(0) ? T[p] : Tdone[p];
      S* img = image + pix * nc;
      S* fg = ws.fg.data() + pix * nc;
      for (int k = 0; k < nc; ++k) {
        fg[k] = acc[k * WW + p];
        img[k] = acc[k * WW + p] + (bg ? Tf * bg[k] : S(0));
      }
      ws.final_T[pix] = Tf;
      ws.last[pix] = last[p] < S(0) ? -1 : static_cast<std::int32_t>(begin + std::int64_t(last[p]));
      ws.depth_raw[pix] = accz[p];
      const S A = S(1) - Tf;
      if (alpha_out) alpha_out[pix] = A;
      if (depth_out) depth_out[pix] = accz[p] / std::max(A, kDepthAlphaFloor<S>);
    }
  }
}

// The per-pixel backward of one Gaussian on one group of kGroup pixels of a row, accumulating
// into kGroup-lane accumulators (summed per Gaussian afterwards, in a fixed order). For a dynamic
// channel count, h (in) and the masked weights (out) go through hbuf / wmbuf and the channel
// loops run outside.
template <class S, int C>
inline void backward_group(const S* __restrict px, S mx, S dy, S a, S cdy2, S bdy, S o, S z,
                           const S* __restrict col, S alpha_max, S irel, S* __restrict Tr,
                           S* __restrict Pr, const S* __restrict Kr, const S* __restrict gzr,
                           const S* __restrict lastr, const S* __restrict gr, int g_stride,
                           const S* __restrict hbuf, S* __restrict wmbuf, S* __restrict lg) {
  const S thr = kAlphaMin<S>;
  S* __restrict lg_mx = lg;                // Σ v_sigma dx
  S* __restrict lg_my = lg + kGroup;       // Σ v_sigma dy
  S* __restrict lg_xx = lg + 2 * kGroup;   // Σ v_sigma dx²
  S* __restrict lg_xy = lg + 3 * kGroup;   // Σ v_sigma dx dy
  S* __restrict lg_yy = lg + 4 * kGroup;   // Σ v_sigma dy²
  S* __restrict lg_o = lg + 5 * kGroup;    // Σ dL/do
  S* __restrict lg_z = lg + 6 * kGroup;    // Σ w dL/dD
  S* __restrict lg_c = lg + 7 * kGroup;    // [C][kGroup] Σ w dL/dC
  for (int l = 0; l < kGroup; ++l) {
    const S dx = mx - px[l];
    const S sigma = pixel_sigma(a, cdy2, bdy, dx);
    const S vis = exp_neg(sigma);
    const S alpha_raw = o * vis;
    const S alpha = select(alpha_raw < alpha_max, alpha_raw, alpha_max);
    const S Tl = Tr[l], Pl = Pr[l], Kl = Kr[l], gzl = gzr[l];
    const bool valid = (irel <= lastr[l]) & (sigma >= S(0)) & (alpha >= thr);
    const S w = alpha * Tl;
    S h;
    if constexpr (C > 0) {
      h = gzl * z;
      for (int k = 0; k < C; ++k) h += gr[k * g_stride + l] * col[k];
    } else {
      h = hbuf[l];
    }
    const S Pn = Pl + w * h;
    const S one_minus = S(1) - alpha;
    // dL/dalpha_i = T_i h_i - (K - P_i) / (1 - alpha_i)   (R18)
    const S v_alpha = h * Tl - (Kl - Pn) / one_minus;
    const S wm = select(valid, w, S(0));
    lg_z[l] += wm * gzl;
    if constexpr (C > 0) {
      for (int k = 0; k < C; ++k) lg_c[k * kGroup + l] += wm * gr[k * g_stride + l];
    } else {
      wmbuf[l] = wm;
    }
    // The clamp's flat side passes no gradient to opacity or the footprint.  (R19)
    const bool free = valid & (alpha_raw <= alpha_max);
    const S vs = select(free, -alpha_raw * v_alpha, S(0));  // dL/dsigma
    lg_o[l] += select(free, vis * v_alpha, S(0));
    const S vsdx = vs * dx, vsdy = vs * dy;
    lg_mx[l] += vsdx;
    lg_my[l] += vsdy;
    lg_xx[l] += vsdx * dx;
    lg_xy[l] += vsdx * dy;
    lg_yy[l] += vsdy * dy;
    Tr[l] = select(valid, Tl * one_minus, Tl);
    Pr[l] = select(valid, Pn, Pl);
  }
  (void)C;
}

// Sum of the kGroup lanes of a group accumulator, in a fixed order.
template <class S>
inline S group_sum(const S* v) {
  S t[kGroup];
  for (int l = 0; l < kGroup; ++l) t[l] = v[l];
  for (int h = kGroup / 2; h >= 1; h /= 2)
    for (int l = 0; l < h; ++l) t[l] += t[l + h];
  return t[0];
}

// Backward of one tile. grad_image [H][W][C], grad_alpha / grad_depth [H][W] may be null.
// Writes one gradient row per entry of the tile's list (zeros past the last composited one).
template <class S, int C, int W>
void backward_tile(const TileContext<S, C, W>& cx, RenderWorkspace<S>& ws, Index tile, S* scratch,
                   const S* grad_image, const S* grad_alpha, const S* grad_depth) {
  constexpr int WW = W * W;
  const int nc = C > 0 ? C : static_cast<int>(cx.channels);
  const int stride = record_stride<C>(cx.channels);
  const int gstride = grad_stride<C>(cx.channels);
  const int tx = static_cast<int>(tile % ws.tiles_x), ty = static_cast<int>(tile / ws.tiles_x);
  const int x0 = tx * W, y0 = ty * W;
  const int wx = std::min(W, ws.width - x0), wy = std::min(W, ws.height - y0);
  const std::int64_t begin = ws.tile_offsets[tile], end = ws.tile_offsets[tile + 1];

  S* T = scratch;
  S* P = T + WW;         // running Σ_{j <= i} w_j h_j
  S* K = P + WW;         // per-pixel constant of (R18)
  S* gz = K + WW;        // dL/dD_raw
  S* last = gz + WW;     // relative list position of the last composited Gaussian, -1
  S* hbuf = last + WW;   // h of the current row (dynamic C only)
  S* g = hbuf + WW;      // [nc][WW] dL/dC
  S* lg = g + nc * WW;   // [kGradFields + nc][kGroup] group accumulators
  S wmbuf[W];            // masked weights of the current row (dynamic C only)
  std::int64_t max_last = begin - 1;
  const S* bg = cx.background;
  for (int p = 0; p < WW; ++p) {
    const int r = p / W, l = p % W;
    T[p] = S(1);
    P[p] = S(0);
    hbuf[p] = S(0);
    if (r >= wy || l >= wx) {
      last[p] = S(-1);
      K[p] = gz[p] = S(0);
      for (int k = 0; k < nc; ++k) g[k * WW + p] = S(0);
      continue;
    }
    const Index pix = Index(y0 + r) * ws.width + (x0 + l);
    const std::int64_t lp = ws.last[pix];
    last[p] = lp < 0 ? S(-1) : S(lp - begin);
    max_last = std::max(max_last, lp);
    const S Tn = ws.final_T[pix];
    const S A = S(1) - Tn;
    const S Draw = ws.depth_raw[pix];
    const S Afl = std::max(A, kDepthAlphaFloor<S>);
    S gA = grad_alpha ? grad_alpha[pix] : S(0);
    S gzp = S(0);
    if (grad_depth) {  // E = D / max(A, floor): dE/dD = 1/max(A, floor), dE/dA = -E/A (A > floor)
      const S gE = grad_depth[pix];
      gzp = gE / Afl;
      if (A > kDepthAlphaFloor<S>) gA -= gE * (Draw / Afl) / A;
    }
    // K = g·fg + gz D + T_N (g·bg - gA)   (R18)
    S Kp = gzp * Draw;
    S gbg = S(0);
    for (int k = 0; k < nc; ++k) {
      const S gk = grad_image ? grad_image[pix * nc + k] : S(0);
      g[k * WW + p] = gk;
      Kp += gk * ws.fg[pix * nc + k];
      if (bg) gbg += gk * bg[k];
    }
    K[p] = Kp + Tn * (gbg - gA);
    gz[p] = gzp;
  }
  S px[W];
  for (int l = 0; l < W; ++l) px[l] = S(x0 + l) + S(0.5);
  // Per group of pixels: the last list position any of them composited; later Gaussians
  // skip the group.
  constexpr int kGroupsPerRow = W / kGroup;
  S group_last[W * kGroupsPerRow];
  for (int q = 0; q < W * kGroupsPerRow; ++q) {
    const S* lq = last + q * kGroup;
    S m = lq[0];
    for (int l = 1; l < kGroup; ++l) m = std::max(m, lq[l]);
    group_last[q] = m;
  }
  const S alpha_max = cx.alpha_max;
  const int nfields = kGradFields + nc;

  for (std::int64_t i = begin; i <= max_last; ++i) {
    const S irel = S(i - begin);
    if (i + kPrefetchAhead <= max_last)
      prefetch(ws.proj.data() + Index(ws.tile_gauss[i + kPrefetchAhead]) * stride);
    const S* rec = ws.proj.data() + Index(ws.tile_gauss[i]) * stride;
    const S mx = rec[kMx], my = rec[kMy], a = rec[kConA], b = rec[kConB], c = rec[kConC];
    const S o = rec[kOpa], z = rec[kDepth];
    const S* col = rec + kRecordFields;
    for (int k = 0; k < nfields * kGroup; ++k) lg[k] = S(0);
    int r0, r1;
    row_range(my, rec[kExtY], y0, wy, &r0, &r1);
    for (int r = r0; r <= r1; ++r) {
      int g0, g1;
      const S dy = footprint_row<S, W>(rec, my, y0, r, x0, &g0, &g1);
      if (g0 >= g1) continue;
      const S cdy2 = c * dy * dy, bdy = b * dy;
      const int row = r * W;
      const int l0 = g0 * kGroup, l1 = g1 * kGroup;
      if constexpr (C <= 0) {  // h = gz z + Σ_k g_k c_k, channel loop outside the lane loop
        for (int l = l0; l < l1; ++l) hbuf[row + l] = gz[row + l] * z;
        for (int k = 0; k < nc; ++k) {
          const S ck = col[k];
          const S* gk = g + k * WW + row;
          for (int l = l0; l < l1; ++l) hbuf[row + l] += gk[l] * ck;
        }
      }
      for (int gq = g0; gq < g1; ++gq) {
        const int o4 = row + gq * kGroup;
        if (irel > group_last[r * kGroupsPerRow + gq]) continue;
        backward_group<S, C>(px + gq * kGroup, mx, dy, a, cdy2, bdy, o, z, col, alpha_max, irel,
                             T + o4, P + o4, K + o4, gz + o4, last + o4, g + o4, WW, hbuf + o4,
                             wmbuf + gq * kGroup, lg);
        if constexpr (C <= 0) {
          for (int k = 0; k < nc; ++k) {
            const S* gk = g + k * WW + o4;
            S* lk = lg + (kGradFields + k) * kGroup;
            for (int l = 0; l < kGroup; ++l) lk[l] += wmbuf[gq * kGroup + l] * gk[l];
          }
        }
      }
    }
    S* out = ws.isect_grad.data() + ws.tile_src[i] * gstride;
    const S smx = group_sum(lg), smy = group_sum(lg + kGroup);
    // sigma = ½ (a dx² + c dy²) + b dx dy with dx = mean_x - px: (R17)
    out[kGMx] = a * smx + b * smy;
    out[kGMy] = b * smx + c * smy;
    out[kGConA] = S(0.5) * group_sum(lg + 2 * kGroup);
    out[kGConB] = group_sum(lg + 3 * kGroup);
    out[kGConC] = S(0.5) * group_sum(lg + 4 * kGroup);
    out[kGOpa] = group_sum(lg + 5 * kGroup);
    out[kGDepth] = group_sum(lg + 6 * kGroup);
    for (int k = 0; k < nc; ++k) out[kGradFields + k] = group_sum(lg + (kGradFields + k) * kGroup);
  }
  for (std::int64_t i = std::max(begin, max_last + 1); i < end; ++i) {
    S* out = ws.isect_grad.data() + ws.tile_src[i] * gstride;
    for (int k = 0; k < gstride; ++k) out[k] = S(0);
  }
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace smg::splat::detail
