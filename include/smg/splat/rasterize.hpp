// smg/splat/rasterize.hpp — per-tile front-to-back compositing and its analytic backward.
//
// One tile of W x W pixels (W = the tile size, a template parameter so every row is a
// fixed-length loop the compiler vectorises) composites its depth-sorted Gaussian list:
//   sigma = ½ (a dx² + c dy²) + b dx dy,  dx = mean_x - px, dy = mean_y - py        (S9)
//   alpha = min(alpha_max, o exp(-sigma)); skip when sigma < 0 or alpha < 1/255        (S10)
//   if T (1 - alpha) <= 1e-4 the pixel is done and this Gaussian is NOT composited     (S11)
//   C += alpha T c,  D += alpha T z,  T *= 1 - alpha                                   (S12)
// The loops run Gaussian-outer, pixel-inner with the pixel state in structure-of-arrays
// form; a Gaussian visits only the rows its alpha >= 1/255 ellipse reaches (a superset,
// so results are those of testing every pixel). The backward walks the same lists front to
// back, recomputing T exactly as the forward did, and obtains the "behind" sums from the
// stored totals (S16)-(S19). Per-(Gaussian, tile) partial gradients are written to their own
// row, so the reduction over tiles (render.hpp) is deterministic. Internal to render.hpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "smg/core/types.hpp"
#include "smg/splat/settings.hpp"
#include "smg/splat/workspace.hpp"

namespace smg::splat::detail {

// Fields of a projected record (RenderWorkspace::proj), followed by the C colour values.
enum RecordField : int { kMx, kMy, kConA, kConB, kConC, kOpa, kDepth, kCut, kExtY, kExtX, kRecordFields };
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

// exp(-x) for the alpha of (S10).
template <class S>
inline S exp_neg(S x) {
  return std::exp(-x);
}

// sigma of (S9) with the per-row terms c dy², b dy hoisted; forward and backward call this one
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

// Scratch sizes of one tile (per parallel chunk).
template <int W>
constexpr Index tile_scratch_size(Index channels) {
  // forward: T, live, accz, C accumulators; backward: T, P, K, gz, C grads + lane accumulators
  return Index(W) * W * (4 + channels) + Index(W) * (kGradFields + channels + 1);
}

template <class S, int C, int W>
struct TileContext {
  const RenderWorkspace<S>* ws;
  Index channels;
  S alpha_max;
  const S* background;  // [C] or null
};

// Forward of one tile: composites its list and writes the pixels of the tile into the
// outputs and the per-pixel state the backward needs.
template <class S, int C, int W>
void forward_tile(const TileContext<S, C, W>& cx, RenderWorkspace<S>& ws, Index tile, S* scratch,
                  S* image, S* alpha_out, S* depth_out) {
  constexpr int WW = W * W;
  const int nc = C > 0 ? C : static_cast<int>(cx.channels);
  const int stride = record_stride<C>(cx.channels);
  const int tx = static_cast<int>(tile % ws.tiles_x), ty = static_cast<int>(tile / ws.tiles_x);
  const int x0 = tx * W, y0 = ty * W;
  const int wx = std::min(W, ws.width - x0), wy = std::min(W, ws.height - y0);
  S* T = scratch;
  S* live = T + WW;
  S* accz = live + WW;
  S* acc = accz + WW;  // [nc][WW]
  std::int32_t last[WW];
  for (int p = 0; p < WW; ++p) {
    const int r = p / W, l = p % W;
    T[p] = S(1);
    live[p] = (r < wy && l < wx) ? S(1) : S(0);
    accz[p] = S(0);
    last[p] = -1;
  }
  for (int k = 0; k < nc * WW; ++k) acc[k] = S(0);
  S px[W];
  for (int l = 0; l < W; ++l) px[l] = S(x0 + l) + S(0.5);

  const S alpha_max = cx.alpha_max;
  const S thr = kAlphaMin<S>;
  const S tmin = kTransmittanceMin<S>;
  int alive = wx * wy;
  const std::int64_t begin = ws.tile_offsets[tile], end = ws.tile_offsets[tile + 1];
  for (std::int64_t i = begin; i < end && alive > 0; ++i) {
    const S* rec = ws.proj.data() + Index(ws.tile_gauss[i]) * stride;
    const S mx = rec[kMx], my = rec[kMy], a = rec[kConA], b = rec[kConB], c = rec[kConC];
    const S o = rec[kOpa], z = rec[kDepth];
    const S* col = rec + kRecordFields;
    int r0, r1;
    row_range(my, rec[kExtY], y0, wy, &r0, &r1);
    const std::int32_t idx = static_cast<std::int32_t>(i);
    for (int r = r0; r <= r1; ++r) {
      const S dy = my - (S(y0 + r) + S(0.5));
      const S cdy2 = c * dy * dy, bdy = b * dy;
      S* Tr = T + r * W;
      S* liver = live + r * W;
      S* acczr = accz + r * W;
      std::int32_t* lastr = last + r * W;
      int stops = 0;
      for (int l = 0; l < W; ++l) {
        const S dx = mx - px[l];
        const S sigma = pixel_sigma(a, cdy2, bdy, dx);
        const S alpha = std::min(alpha_max, o * exp_neg(sigma));
        const S Tl = Tr[l];
        const S next_T = Tl * (S(1) - alpha);
        const bool valid = (liver[l] != S(0)) & (sigma >= S(0)) & (alpha >= thr);
        const bool stop = valid & (next_T <= tmin);
        const bool comp = valid & !stop;
        const S w = comp ? alpha * Tl : S(0);
        for (int k = 0; k < nc; ++k) acc[k * WW + r * W + l] += w * col[k];
        acczr[l] += w * z;
        Tr[l] = comp ? next_T : Tl;
        liver[l] = stop ? S(0) : liver[l];
        lastr[l] = comp ? idx : lastr[l];
        stops += stop ? 1 : 0;
      }
      alive -= stops;
    }
  }

  const S* bg = cx.background;
  for (int r = 0; r < wy; ++r) {
    for (int l = 0; l < wx; ++l) {
      const int p = r * W + l;
      const Index pix = Index(y0 + r) * ws.width + (x0 + l);
      const S Tf = T[p];
      S* img = image + pix * nc;
      S* fg = ws.fg.data() + pix * nc;
      for (int k = 0; k < nc; ++k) {
        fg[k] = acc[k * WW + p];
        img[k] = acc[k * WW + p] + (bg ? Tf * bg[k] : S(0));
      }
      ws.final_T[pix] = Tf;
      ws.last[pix] = last[p];
      ws.depth_raw[pix] = accz[p];
      const S A = S(1) - Tf;
      if (alpha_out) alpha_out[pix] = A;
      if (depth_out) depth_out[pix] = accz[p] / std::max(A, kDepthAlphaFloor<S>);
    }
  }
}

// Pairwise sum of W lanes in a fixed order (vectorisable, deterministic).
template <class S, int W>
inline S lane_sum(S* v) {
  for (int h = W / 2; h >= 1; h /= 2)
    for (int l = 0; l < h; ++l) v[l] += v[l + h];
  return v[0];
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
  S* P = T + WW;       // running Σ_{j <= i} w_j h_j
  S* K = P + WW;       // per-pixel constant of (S18)
  S* gz = K + WW;      // dL/dD_raw
  S* g = gz + WW;      // [nc][WW] dL/dC
  S* lane = g + nc * WW;  // [kGradFields + nc][W] lane accumulators
  std::int32_t last[WW];
  std::int64_t max_last = begin - 1;
  const S* bg = cx.background;
  for (int p = 0; p < WW; ++p) {
    const int r = p / W, l = p % W;
    T[p] = S(1);
    P[p] = S(0);
    if (r >= wy || l >= wx) {
      last[p] = -1;
      K[p] = gz[p] = S(0);
      for (int k = 0; k < nc; ++k) g[k * WW + p] = S(0);
      continue;
    }
    const Index pix = Index(y0 + r) * ws.width + (x0 + l);
    last[p] = ws.last[pix];
    max_last = std::max<std::int64_t>(max_last, last[p]);
    const S Tn = ws.final_T[pix];
    const S A = S(1) - Tn;
    const S Araw = ws.depth_raw[pix];
    const S Afl = std::max(A, kDepthAlphaFloor<S>);
    S gA = grad_alpha ? grad_alpha[pix] : S(0);
    S gzp = S(0);
    if (grad_depth) {  // E = D / max(A, floor): dE/dD = 1/max(A, floor), dE/dA = -E/A (A > floor)
      const S gE = grad_depth[pix];
      gzp = gE / Afl;
      if (A > kDepthAlphaFloor<S>) gA -= gE * (Araw / Afl) / A;
    }
    // K = g·fg + gz D + T_N (g·bg - gA)   (S18)
    S Kp = gzp * Araw;
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

  const S alpha_max = cx.alpha_max;
  const S thr = kAlphaMin<S>;
  S* lg_mx = lane;             // Σ v_sigma dx
  S* lg_my = lane + W;         // Σ v_sigma dy
  S* lg_xx = lane + 2 * W;     // Σ v_sigma dx²
  S* lg_xy = lane + 3 * W;     // Σ v_sigma dx dy
  S* lg_yy = lane + 4 * W;     // Σ v_sigma dy²
  S* lg_o = lane + 5 * W;      // Σ dL/do
  S* lg_z = lane + 6 * W;      // Σ w dL/dD
  S* lg_c = lane + 7 * W;      // [nc][W] Σ w dL/dC
  const int nlanes = kGradFields + nc;

  for (std::int64_t i = begin; i <= max_last; ++i) {
    const S* rec = ws.proj.data() + Index(ws.tile_gauss[i]) * stride;
    const S mx = rec[kMx], my = rec[kMy], a = rec[kConA], b = rec[kConB], c = rec[kConC];
    const S o = rec[kOpa], z = rec[kDepth];
    const S* col = rec + kRecordFields;
    for (int k = 0; k < nlanes * W; ++k) lane[k] = S(0);
    int r0, r1;
    row_range(my, rec[kExtY], y0, wy, &r0, &r1);
    const std::int32_t idx = static_cast<std::int32_t>(i);
    for (int r = r0; r <= r1; ++r) {
      const S dy = my - (S(y0 + r) + S(0.5));
      const S cdy2 = c * dy * dy, bdy = b * dy;
      S* Tr = T + r * W;
      S* Pr = P + r * W;
      const S* Kr = K + r * W;
      const S* gzr = gz + r * W;
      const std::int32_t* lastr = last + r * W;
      for (int l = 0; l < W; ++l) {
        const S dx = mx - px[l];
        const S sigma = pixel_sigma(a, cdy2, bdy, dx);
        const S vis = exp_neg(sigma);
        const S alpha_raw = o * vis;
        const S alpha = std::min(alpha_max, alpha_raw);
        const bool valid = (idx <= lastr[l]) & (sigma >= S(0)) & (alpha >= thr);
        const S Tl = Tr[l];
        const S w = alpha * Tl;
        S h = gzr[l] * z;
        for (int k = 0; k < nc; ++k) h += g[k * WW + r * W + l] * col[k];
        const S Pn = Pr[l] + w * h;
        const S one_minus = S(1) - alpha;
        // dL/dalpha_i = T_i h_i - (K - P_i) / (1 - alpha_i)   (S18)
        const S v_alpha = h * Tl - (Kr[l] - Pn) / one_minus;
        const S wm = valid ? w : S(0);
        for (int k = 0; k < nc; ++k) lg_c[k * W + l] += wm * g[k * WW + r * W + l];
        lg_z[l] += wm * gzr[l];
        // The clamp's flat side passes no gradient to opacity or the footprint.  (S19)
        const bool free = valid & (alpha_raw <= alpha_max);
        const S vs = free ? -alpha_raw * v_alpha : S(0);  // dL/dsigma
        lg_o[l] += free ? vis * v_alpha : S(0);
        lg_mx[l] += vs * dx;
        lg_my[l] += vs * dy;
        lg_xx[l] += vs * dx * dx;
        lg_xy[l] += vs * dx * dy;
        lg_yy[l] += vs * dy * dy;
        Tr[l] = valid ? Tl * one_minus : Tl;
        Pr[l] = valid ? Pn : Pr[l];
      }
    }
    S* row = ws.isect_grad.data() + ws.tile_src[i] * gstride;
    const S smx = lane_sum<S, W>(lg_mx), smy = lane_sum<S, W>(lg_my);
    // sigma = ½ (a dx² + c dy²) + b dx dy with dx = mean_x - px: (S17)
    row[kGMx] = a * smx + b * smy;
    row[kGMy] = b * smx + c * smy;
    row[kGConA] = S(0.5) * lane_sum<S, W>(lg_xx);
    row[kGConB] = lane_sum<S, W>(lg_xy);
    row[kGConC] = S(0.5) * lane_sum<S, W>(lg_yy);
    row[kGOpa] = lane_sum<S, W>(lg_o);
    row[kGDepth] = lane_sum<S, W>(lg_z);
    for (int k = 0; k < nc; ++k) row[kGradFields + k] = lane_sum<S, W>(lg_c + k * W);
  }
  for (std::int64_t i = std::max(begin, max_last + 1); i < end; ++i) {
    S* row = ws.isect_grad.data() + ws.tile_src[i] * gstride;
    for (int k = 0; k < gstride; ++k) row[k] = S(0);
  }
}

}  // namespace smg::splat::detail
