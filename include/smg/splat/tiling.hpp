// smg/splat/tiling.hpp — tile rectangles, the global depth sort, and per-tile lists.
//
// gsplat's isect_tiles semantics: a visible Gaussian with radius r covers the tiles
// [floor(mx/ts - r/ts), ceil(mx/ts + r/ts)) x [same in y], clamped to the grid.  (R8)
// Lists are ordered by (depth, Gaussian index) — what gsplat's (tile, depth) radix sort of
// index-ordered intersections yields. Here the visible Gaussians are sorted once (stable LSD
// radix sort of the depth's bit pattern; depths are > 0 so the bits order as the values),
// and a stable counting sort by tile then leaves every tile's list in depth order.
// Intersection rows are numbered in depth-sorted generation order; isect_offset[g] is the
// first row of Gaussian g, whose rows cover its tiles in row-major order. Internal.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/splat/workspace.hpp"

namespace smg::splat::detail {

// Tile rectangle of a Gaussian (R8). Writes [x0, x1) x [y0, y1), possibly empty.
template <class S>
inline void tile_rect(S mx, S my, S radius, int tile_size, int tiles_x, int tiles_y,
                      std::int32_t* rect) {
  const S ts = S(tile_size);
  const S tr = radius / ts, cx = mx / ts, cy = my / ts;
  auto clampi = [](S v, int hi) {
    if (!(v > S(0))) return 0;  // also NaN
    if (v >= S(hi)) return hi;
    return static_cast<int>(v);
  };
  rect[0] = clampi(std::floor(cx - tr), tiles_x);
  rect[1] = clampi(std::floor(cy - tr), tiles_y);
  rect[2] = clampi(std::ceil(cx + tr), tiles_x);
  rect[3] = clampi(std::ceil(cy + tr), tiles_y);
}

template <class S>
inline std::uint64_t depth_key(S depth) {
  if constexpr (sizeof(S) == 4) {
    std::uint32_t u;
    std::memcpy(&u, &depth, 4);
    return u;
  } else {
    std::uint64_t u;
    std::memcpy(&u, &depth, 8);
    return u;
  }
}

// Sorts ws.order (visible Gaussians in index order) by ws.depths, stably. LSD radix sort on
// 8-bit digits; digits shared by every key are skipped.
template <class S>
void sort_by_depth(RenderWorkspace<S>& ws) {
  const std::size_t n = ws.order.size();
  ws.keys.resize(n);
  ws.keys_tmp.resize(n);
  ws.order_tmp.resize(n);
  std::uint64_t all_or = 0, all_and = ~std::uint64_t(0);
  for (std::size_t k = 0; k < n; ++k) {
    ws.keys[k] = depth_key(ws.depths[static_cast<std::size_t>(ws.order[k])]);
    all_or |= ws.keys[k];
    all_and &= ws.keys[k];
  }
  const std::uint64_t varying = all_or ^ all_and;
  for (int shift = 0; shift < int(8 * sizeof(S)); shift += 8) {
    if (((varying >> shift) & 0xff) == 0) continue;
    std::size_t count[257] = {};
    for (std::size_t k = 0; k < n; ++k) ++count[((ws.keys[k] >> shift) & 0xff) + 1];
    for (int d = 0; d < 256; ++d) count[d + 1] += count[d];
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t pos = count[(ws.keys[k] >> shift) & 0xff]++;
      ws.keys_tmp[pos] = ws.keys[k];
      ws.order_tmp[pos] = ws.order[k];
    }
    ws.keys.swap(ws.keys_tmp);
    ws.order.swap(ws.order_tmp);
  }
}

// Builds tile_offsets, tile_gauss, tile_src and isect_offset from rect and the sorted order.
// Parallel over fixed chunks of the sorted order (per-chunk tile counts, then each chunk
// writes at its own cursors), so the lists are the same for any thread count.
template <class S>
void build_tile_lists(RenderWorkspace<S>& ws, ParallelOptions par) {
  const Index tiles = Index(ws.tiles_x) * ws.tiles_y;
  const Index n = static_cast<Index>(ws.order.size());
  const Index grain = std::max<Index>(4096, (n + 63) / 64);
  const Index chunks = parallel_chunk_count(n, grain);
  const auto T = static_cast<std::size_t>(tiles);
  ws.tile_offsets.assign(T + 1, 0);
  ws.tile_cursor.assign(static_cast<std::size_t>(chunks) * T, 0);  // per-chunk counts, then cursors
  std::int64_t total = 0;
  for (Index k = 0; k < n; ++k) {  // rows of each Gaussian, in depth order
    const std::int32_t g = ws.order[static_cast<std::size_t>(k)];
    const std::int32_t* r = ws.rect.data() + 4 * Index(g);
    ws.isect_offset[static_cast<std::size_t>(g)] = total;
    total += std::int64_t(r[2] - r[0]) * (r[3] - r[1]);
  }
  ws.n_isect = total;
  ParallelOptions p = par;
  p.grain = grain;
  parallel_for_chunks(
      n,
      [&](Index chunk, Index begin, Index end) {
        std::int64_t* count = ws.tile_cursor.data() + chunk * tiles;
        for (Index k = begin; k < end; ++k) {
          const std::int32_t* r = ws.rect.data() + 4 * Index(ws.order[static_cast<std::size_t>(k)]);
          for (int ty = r[1]; ty < r[3]; ++ty)
            for (int tx = r[0]; tx < r[2]; ++tx) ++count[ty * ws.tiles_x + tx];
        }
      },
      p);
  // Tile t's list: chunk 0's entries, then chunk 1's, ... (depth order).
  std::int64_t start = 0;
  for (std::size_t t = 0; t < T; ++t) {
    ws.tile_offsets[t] = start;
    for (Index c = 0; c < chunks; ++c) {
      std::int64_t& cnt = ws.tile_cursor[static_cast<std::size_t>(c) * T + t];
      const std::int64_t here = cnt;
      cnt = start;
      start += here;
    }
  }
  ws.tile_offsets[T] = start;
  ws.tile_gauss.resize(static_cast<std::size_t>(total));
  ws.tile_src.resize(static_cast<std::size_t>(total));
  parallel_for_chunks(
      n,
      [&](Index chunk, Index begin, Index end) {
        std::int64_t* cursor = ws.tile_cursor.data() + chunk * tiles;
        for (Index k = begin; k < end; ++k) {
          const std::int32_t g = ws.order[static_cast<std::size_t>(k)];
          const std::int32_t* r = ws.rect.data() + 4 * Index(g);
          std::int64_t e = ws.isect_offset[static_cast<std::size_t>(g)];
          for (int ty = r[1]; ty < r[3]; ++ty)
            for (int tx = r[0]; tx < r[2]; ++tx) {
              const auto pos = static_cast<std::size_t>(cursor[ty * ws.tiles_x + tx]++);
              ws.tile_gauss[pos] = g;
              ws.tile_src[pos] = e++;
            }
        }
      },
      p);
}

}  // namespace smg::splat::detail
