// smg/splat/render.hpp — the splatter's entry points: render_forward and render_backward.
//
//   RenderWorkspace<float> ws;                      // reuse across iterations
//   render_forward<3>(params, camera, settings, ws, {image, alpha, depth});
//   render_backward<3>(params, camera, settings, ws, {grad_image, grad_alpha, grad_depth},
//                      grads);
//
// C, the colour channel count, is a template parameter (Eigen::Dynamic = any, read from
// params). gsplat's semantics and constants (docs/math/splat.md): projection (R1)-(R8),
// compositing (R9)-(R13), colour from SH (R14)-(R15), backward (R16)-(R26).
// Multithreaded over Gaussians and over tiles through smg::parallel_for; every output,
// gradients included, is bit-identical for any thread count (per-(Gaussian, tile) partial
// gradients are summed per Gaussian in a fixed order).
// Inputs are checked by validate_render / validate_render_backward, never here.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/splat/camera.hpp"
#include "smg/splat/gaussians.hpp"
#include "smg/splat/projection.hpp"
#include "smg/splat/rasterize.hpp"
#include "smg/splat/settings.hpp"
#include "smg/splat/sh.hpp"
#include "smg/splat/tiling.hpp"
#include "smg/splat/workspace.hpp"

namespace smg::splat {

// Everything render_forward relies on: gaussians (validate_gaussians), camera, settings and
// the output images. channels = C of the instantiation, or -1 for Eigen::Dynamic.
template <class S>
Status validate_render(const GaussianParams<S>& params, const Camera<S>& camera,
                       const SplatSettings<S>& settings, const RenderImages<S>& images,
                       Index channels = -1) {
  if (Status s = validate_gaussians(params, channels); !s) return s;
  if (Status s = validate_camera(camera); !s) return s;
  if (Status s = validate_settings(settings); !s) return s;
  if (params.count() > Index(0x7fffffff))
    return Status::error("means: more than 2^31 - 1 Gaussians");
  if (settings.background)
    for (Index k = 0; k < params.channels(); ++k)
      if (!std::isfinite(settings.background[k]))
        return Status::error("background: non-finite value");
  return validate_render_images(images, camera.height, camera.width, params.channels());
}

// render_backward's preconditions: the workspace holds a forward of this scene (sizes match),
// incoming gradients have the image shapes, outputs have the parameters' shapes.
template <class S>
Status validate_render_backward(const GaussianParams<S>& params, const Camera<S>& camera,
                                const SplatSettings<S>& settings, const RenderWorkspace<S>& ws,
                                const RenderImageGrads<S>& grads_in,
                                const GaussianGrads<S>& grads_out) {
  if (ws.count != params.count() || ws.channels != params.channels() ||
      ws.width != camera.width || ws.height != camera.height ||
      ws.tile_size != settings.tile_size)
    return Status::error(
        "workspace: does not hold a render_forward of these Gaussians, camera and settings");
  if (Status s = validate_render_image_grads(grads_in, camera.height, camera.width,
                                             params.channels());
      !s)
    return s;
  return validate_gaussian_grads(grads_out, params);
}

namespace detail {
// These call the rasteriser, whose lane groups follow __AVX__: an ISA-specific namespace
// (smg/core/config.hpp), as have render_forward and render_backward below.
inline namespace SMG_ISA_NAMESPACE {

template <class S>
inline S sigmoid(S x) {
  return S(1) / (S(1) + std::exp(-x));
}

// Number of tile chunks: at most 128 so that the per-chunk scratch stays small, enough for
// load balance on any realistic core count. Depends on the tile count only.
inline Index tile_grain(Index tiles) { return std::max<Index>(1, (tiles + 127) / 128); }

template <int C, class S>
void project_all(const GaussianParams<S>& params, const Camera<S>& cam,
                 const SplatSettings<S>& set, RenderWorkspace<S>& ws, ParallelOptions par) {
  const Index G = params.count();
  const Index nc = ws.channels;
  const int stride = record_stride<C>(nc);
  const Vector3<S> center = cam.center();
  parallel_for(
      G,
      [&](Index begin, Index end) {
        for (Index g = begin; g < end; ++g) {
          std::int32_t* rect = ws.rect.data() + 4 * g;
          rect[0] = rect[1] = rect[2] = rect[3] = 0;
          ws.radii[g] = S(0);
          const Vector3<S> mean = params.means.row(g);
          ProjectedGaussian<S> pg;
          Cull cull = project_gaussian<S>(cam, mean, params.quats.row(g), params.log_scales.row(g),
                                          set.eps2d, set.radius_sigmas, &pg);
          const S o = sigmoid(params.opacity_logits(g, 0));
          // alpha <= o: below 1/255 no pixel can pass (R10); gsplat >= 1.5 culls these too.
          if (cull == Cull::none && !(o >= kAlphaMin<S>)) cull = Cull::transparent;
          ws.cull[g] = static_cast<std::uint8_t>(cull);
          if (cull != Cull::none) continue;
          S* rec = ws.proj.data() + g * stride;
          rec[kMx] = pg.mean2d.x();
          rec[kMy] = pg.mean2d.y();
          rec[kConA] = pg.conic(0);
          rec[kConB] = pg.conic(1);
          rec[kConC] = pg.conic(2);
          rec[kOpa] = o;
          rec[kDepth] = pg.depth;
          // sigma > cut = ln(255 o) + 1e-3 implies alpha < 1/255 with room for exp's rounding.
          // The ellipse {sigma <= cut}: half height sqrt(2 cut (Q⁻¹)_yy) and, per row, the
          // x-extent of rasterize.hpp's lane_groups; computed from the stored conic in long
          // double so that rounding cannot shrink it (it bounds what compositing evaluates).
          const long double cut = std::log(static_cast<double>(o) / double(kAlphaMin<S>)) + 1e-3;
          const long double qa = pg.conic(0), qb = pg.conic(1), qc = pg.conic(2);
          const long double qdet = qa * qc - qb * qb;
          rec[kExtY] = static_cast<S>(std::sqrt(std::max(0.0L, 2.0L * cut * qa / qdet)) * 1.001L);
          rec[kBoA] = static_cast<S>(qb / qa);
          rec[kInvA] = static_cast<S>(1.0L / qa);
          rec[kTwoACut] = static_cast<S>(2.0L * qa * cut * 1.001L);
          rec[kDetQ] = static_cast<S>(qdet);
          S* col = rec + kRecordFields;
          if (params.sh_degree < 0) {
            for (Index k = 0; k < nc; ++k) col[k] = params.colors(g, k);
          } else {
            sh_to_color<S>(params.sh_degree, static_cast<int>(nc), Vector3<S>(mean - center),
                           params.colors.ptr(g), col);
          }
          ws.radii[g] = pg.radius;
          ws.means2d[2 * g] = pg.mean2d.x();
          ws.means2d[2 * g + 1] = pg.mean2d.y();
          ws.depths[g] = pg.depth;
          tile_rect(pg.mean2d.x(), pg.mean2d.y(), pg.radius, ws.tile_size, ws.tiles_x,
                    ws.tiles_y, rect);
        }
      },
      par);
}

// Runs tile(cx, t, scratch) for every tile t of the image, in parallel chunks of tiles whose
// size depends only on the tile count (deterministic), each chunk with its own scratch.
template <int C, int W, class S, class Tile>
void for_each_tile(const SplatSettings<S>& set, RenderWorkspace<S>& ws, ParallelOptions par,
                   Tile&& tile) {
  const Index tiles = Index(ws.tiles_x) * ws.tiles_y;
  const Index grain = tile_grain(tiles);
  const Index per_chunk = tile_scratch_size<W>(ws.channels);
  ws.scratch.resize(static_cast<std::size_t>(parallel_chunk_count(tiles, grain) * per_chunk));
  const TileContext<S, C, W> cx{&ws, ws.channels, set.alpha_max, set.background};
  ParallelOptions p = par;
  p.grain = grain;
  parallel_for_chunks(
      tiles,
      [&](Index chunk, Index begin, Index end) {
        S* scratch = ws.scratch.data() + chunk * per_chunk;
        for (Index t = begin; t < end; ++t) tile(cx, t, scratch);
      },
      p);
}

template <int C, int W, class S>
void rasterize_forward_all(const SplatSettings<S>& set, RenderWorkspace<S>& ws,
                           const RenderImages<S>& out, ParallelOptions par) {
  for_each_tile<C, W>(set, ws, par, [&](const TileContext<S, C, W>& cx, Index t, S* scratch) {
    forward_tile<S, C, W>(cx, ws, t, scratch, out.image.data(), out.alpha.data(),
                          out.depth.data());
  });
}

template <int C, int W, class S>
void rasterize_backward_all(const SplatSettings<S>& set, RenderWorkspace<S>& ws,
                            const RenderImageGrads<S>& gin, ParallelOptions par) {
  ws.isect_grad.resize(static_cast<std::size_t>(ws.n_isect * grad_stride<C>(ws.channels)));
  for_each_tile<C, W>(set, ws, par, [&](const TileContext<S, C, W>& cx, Index t, S* scratch) {
    backward_tile<S, C, W>(cx, ws, t, scratch, gin.image.data(), gin.alpha.data(),
                           gin.depth.data());
  });
}

}  // inline namespace SMG_ISA_NAMESPACE
}  // namespace detail

inline namespace SMG_ISA_NAMESPACE {

// Renders the Gaussians: image [H][W][C] = Σ w_i c_i + T_N background, alpha = 1 - T_N,
// depth = Σ w_i z_i / max(alpha, 1e-10) (alpha and depth optional), with gsplat's
// projection, tiling and compositing (docs/math/splat.md (R1)-(R15)). ws keeps what
// render_backward needs and exposes per-Gaussian radii, means2d, depths and cull reasons.
// Preconditions: validate_render(params, camera, settings, images, C) is ok.
template <int C, class S>
void render_forward(const GaussianParams<S>& params, const Camera<S>& camera,
                    const SplatSettings<S>& settings, RenderWorkspace<S>& ws,
                    const RenderImages<S>& images, ParallelOptions parallel = {}) {
  static_assert(C > 0 || C == Eigen::Dynamic, "C is a channel count or Eigen::Dynamic");
  const Index G = params.count();
  const Index nc = params.channels();
  ws.count = G;
  ws.channels = nc;
  ws.width = camera.width;
  ws.height = camera.height;
  ws.tile_size = settings.tile_size;
  ws.tiles_x = (camera.width + settings.tile_size - 1) / settings.tile_size;
  ws.tiles_y = (camera.height + settings.tile_size - 1) / settings.tile_size;
  const auto Gs = static_cast<std::size_t>(G);
  ws.cull.resize(Gs);
  ws.radii.resize(Gs);
  ws.means2d.resize(2 * Gs);
  ws.depths.resize(Gs);
  ws.proj.resize(Gs * static_cast<std::size_t>(detail::record_stride<C>(nc)));
  ws.rect.resize(4 * Gs);
  ws.isect_offset.resize(Gs);
  const auto npix = static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height);
  ws.final_T.resize(npix);
  ws.last.resize(npix);
  ws.fg.resize(npix * static_cast<std::size_t>(nc));
  ws.depth_raw.resize(npix);

  detail::project_all<C>(params, camera, settings, ws, parallel);
  ws.order.clear();
  for (Index g = 0; g < G; ++g)
    if (ws.cull[g] == 0) ws.order.push_back(static_cast<std::int32_t>(g));
  ws.n_visible = static_cast<Index>(ws.order.size());
  detail::sort_by_depth(ws);
  detail::build_tile_lists(ws, parallel);
  switch (settings.tile_size) {
    case 8: detail::rasterize_forward_all<C, 8>(settings, ws, images, parallel); break;
    case 32: detail::rasterize_forward_all<C, 32>(settings, ws, images, parallel); break;
    default: detail::rasterize_forward_all<C, 16>(settings, ws, images, parallel); break;
  }
}

// Gradients of a loss L(image, alpha, depth) given dL/dimage, dL/dalpha, dL/ddepth (each
// optional) after render_forward with the same params, camera and settings on ws. Writes
// every non-null view of grads (overwrites): means, raw quaternion and right-tangent rotation
// gradients, log-scales, opacity logits, colours or SH coefficients, 2D means. Culled
// Gaussians get zeros. (R16)-(R26)
// Preconditions: validate_render_backward(params, camera, settings, ws, grads_in, grads).
template <int C, class S>
void render_backward(const GaussianParams<S>& params, const Camera<S>& camera,
                     const SplatSettings<S>& settings, RenderWorkspace<S>& ws,
                     const RenderImageGrads<S>& grads_in, const GaussianGrads<S>& grads,
                     ParallelOptions parallel = {}) {
  static_assert(C > 0 || C == Eigen::Dynamic, "C is a channel count or Eigen::Dynamic");
  switch (settings.tile_size) {
    case 8: detail::rasterize_backward_all<C, 8>(settings, ws, grads_in, parallel); break;
    case 32: detail::rasterize_backward_all<C, 32>(settings, ws, grads_in, parallel); break;
    default: detail::rasterize_backward_all<C, 16>(settings, ws, grads_in, parallel); break;
  }
  const Index G = params.count();
  const Index nc = ws.channels;
  const int stride = detail::record_stride<C>(nc);
  const int gstride = detail::grad_stride<C>(nc);
  const Index ncoef = params.colors.cols();
  const Vector3<S> center = camera.center();
  parallel_for(
      G,
      [&](Index begin, Index end) {
        std::vector<S> coef_scratch;  // SH coefficient gradients nobody asked for
        Eigen::Matrix<S, C, 1> v_col(nc);  // no allocation for a fixed C
        for (Index g = begin; g < end; ++g) {
          // rows are in depth order: fetch a later Gaussian's rows ahead of use
          if (g + 8 < end && ws.cull[g + 8] == 0)
            detail::prefetch(ws.isect_grad.data() + ws.isect_offset[g + 8] * gstride);
          if (ws.cull[g] != 0) {
            if (grads.means.data()) grads.means.row(g).setZero();
            if (grads.quats.data()) grads.quats.row(g).setZero();
            if (grads.quats_tangent.data()) grads.quats_tangent.row(g).setZero();
            if (grads.log_scales.data()) grads.log_scales.row(g).setZero();
            if (grads.opacity_logits.data()) grads.opacity_logits(g, 0) = S(0);
            if (grads.colors.data()) grads.colors.row(g).setZero();
            if (grads.means2d.data()) grads.means2d.row(g).setZero();
            continue;
          }
          // Σ over the Gaussian's tiles, in its row-major tile order.  (R16)
          const std::int32_t* r = ws.rect.data() + 4 * g;
          const Index n = Index(r[2] - r[0]) * (r[3] - r[1]);
          S acc[detail::kGradFields] = {};
          v_col.setZero();
          const S* row = ws.isect_grad.data() + ws.isect_offset[g] * gstride;
          for (Index e = 0; e < n; ++e, row += gstride) {
            for (int f = 0; f < detail::kGradFields; ++f) acc[f] += row[f];
            for (Index k = 0; k < nc; ++k) v_col(k) += row[detail::kGradFields + k];
          }
          const S* rec = ws.proj.data() + g * stride;
          const Vector2<S> v_mean2d(acc[detail::kGMx], acc[detail::kGMy]);
          const Vector3<S> v_conic(acc[detail::kGConA], acc[detail::kGConB], acc[detail::kGConC]);
          if (grads.means2d.data()) grads.means2d.row(g) = v_mean2d;
          const S o = rec[detail::kOpa];
          if (grads.opacity_logits.data())
            grads.opacity_logits(g, 0) = acc[detail::kGOpa] * o * (S(1) - o);
          const Vector3<S> mean = params.means.row(g);
          Vector3<S> v_dir = Vector3<S>::Zero();
          if (params.sh_degree < 0) {
            if (grads.colors.data())
              for (Index k = 0; k < nc; ++k) grads.colors(g, k) = v_col(k);
          } else if (grads.colors.data() || grads.means.data()) {
            S* vc = grads.colors.data() ? grads.colors.ptr(g) : nullptr;
            if (!vc) {
              coef_scratch.resize(static_cast<std::size_t>(ncoef));
              vc = coef_scratch.data();
            }
            v_dir = sh_to_color_vjp<S>(params.sh_degree, static_cast<int>(nc),
                                       Vector3<S>(mean - center), params.colors.ptr(g),
                                       v_col.data(), vc);
          }
          Vector3<S> v_mean;
          Vector4<S> v_quat;
          Vector3<S> v_tan, v_ls;
          project_gaussian_vjp<S>(camera, mean, params.quats.row(g), params.log_scales.row(g),
                                  settings.eps2d,
                                  Vector3<S>(rec[detail::kConA], rec[detail::kConB],
                                             rec[detail::kConC]),
                                  v_mean2d, v_conic, acc[detail::kGDepth], &v_mean,
                                  grads.quats.data() ? &v_quat : nullptr,
                                  grads.quats_tangent.data() ? &v_tan : nullptr,
                                  grads.log_scales.data() ? &v_ls : nullptr);
          if (grads.means.data()) grads.means.row(g) = v_mean + v_dir;
          if (grads.quats.data()) grads.quats.row(g) = v_quat;
          if (grads.quats_tangent.data()) grads.quats_tangent.row(g) = v_tan;
          if (grads.log_scales.data()) grads.log_scales.row(g) = v_ls;
        }
      },
      parallel);
}

}  // inline namespace SMG_ISA_NAMESPACE

}  // namespace smg::splat
