// smg/splat/workspace.hpp — the state one render keeps for its backward, reused across calls.
//
// A RenderWorkspace is owned by the caller and passed to render_forward and then (optionally)
// render_backward with the same inputs. Its buffers only grow: after the first call with a
// given scene size, later calls allocate nothing (std::vector::resize within capacity). One
// workspace serves one render at a time; use one per thread or camera for concurrent renders.
//
// Everything here is written by render_forward/render_backward; callers read the documented
// per-Gaussian results (radii, means2d, depths, cull) and never need to write anything.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <vector>

#include "smg/core/types.hpp"

namespace smg::splat {

template <class S>
struct RenderWorkspace {
  // ---- geometry of the last render_forward ----
  Index count = 0;     // G
  Index channels = 0;  // C
  int width = 0, height = 0, tile_size = 16, tiles_x = 0, tiles_y = 0;
  Index n_isect = 0;   // (Gaussian, tile) pairs
  Index n_visible = 0; // Gaussians with radius > 0

  // ---- per Gaussian (readable by callers after render_forward) ----
  std::vector<std::uint8_t> cull;  // [G] a smg::splat::Cull value (0 = visible)
  std::vector<S> radii;            // [G] pixels, 0 when culled (gsplat's radii)
  std::vector<S> means2d;          // [G][2] projected means, pixels (valid where radius > 0)
  std::vector<S> depths;           // [G] camera-space z (valid where radius > 0)

  // ---- internal: projected records, binning, per-pixel state, gradient buffers ----
  // proj: [G][kRecordFields + C] (mean2d, conic, opacity, z, cutoff, extents, colour)
  std::vector<S> proj;
  std::vector<std::int32_t> rect;          // [G][4] tile rectangle [x0, x1) x [y0, y1)
  std::vector<std::int64_t> isect_offset;  // [G] first (Gaussian, tile) row, depth order
  std::vector<std::int32_t> order;         // visible Gaussians sorted by (depth, index)
  std::vector<std::int32_t> order_tmp;
  std::vector<std::uint64_t> keys, keys_tmp;
  std::vector<std::int64_t> tile_offsets;  // [tiles + 1]
  std::vector<std::int64_t> tile_cursor;   // [chunks][tiles] counts, then write cursors
  std::vector<std::int32_t> tile_gauss;    // [n_isect] Gaussian of each tile-list entry
  std::vector<std::int64_t> tile_src;      // [n_isect] its row in depth-order generation
  std::vector<S> final_T;                  // [H][W] transmittance after the last Gaussian
  std::vector<std::int32_t> last;          // [H][W] tile-list index of the last composited
  std::vector<S> fg;                       // [H][W][C] colour before the background
  std::vector<S> depth_raw;                // [H][W] Σ w z
  std::vector<S> isect_grad;               // [n_isect][kGradFields + C] per-tile partials
  std::vector<S> scratch;                  // per-chunk tile scratch
};

}  // namespace smg::splat
