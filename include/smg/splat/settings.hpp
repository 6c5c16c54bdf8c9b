// smg/splat/settings.hpp — the splatter's constants and knobs.
//
// The pinned constants (docs/design.md "Splatter", docs/math/splat.md section 1) are compile-time:
// the alpha skip threshold 1/255, the transmittance rule (a pixel is done when the next
// transmittance would be <= 1e-4, exclusive), the depth normaliser floor 1e-10. The knobs a
// benchmark or a gsplat-version comparison varies are run-time fields of SplatSettings; their
// defaults are the pinned values.
#pragma once

#include "smg/core/config.hpp"

#include <sstream>

#include "smg/core/status.hpp"

namespace smg::splat {

// alpha < kAlphaMin is skipped (gsplat ALPHA_THRESHOLD).  (R10)
template <class S>
constexpr S kAlphaMin = S(1) / S(255);
// A pixel is done when its next transmittance would be <= this (gsplat TRANSMITTANCE_THRESHOLD).
template <class S>
constexpr S kTransmittanceMin = S(1e-4);
// Expected depth = Σ w z / max(alpha, kDepthAlphaFloor).  (R13)
template <class S>
constexpr S kDepthAlphaFloor = S(1e-10);
// Largest supported spherical-harmonics degree (16 coefficients per channel).
constexpr int kMaxShDegree = 3;

template <class S>
struct SplatSettings {
  // Square tile edge in pixels: 8, 16 (default, gsplat's) or 32. Tiles only decide which
  // Gaussians a pixel may see (binning by radius); see radius_sigmas.
  int tile_size = 16;
  // Radius = ceil(radius_sigmas * sqrt(lambda_max)) pixels (R7). 3 is gsplat v1's value. A
  // pixel only sees Gaussians binned to its tile, so a smaller value (2.5) trades exactness
  // for speed; any value >= 3.33 makes the image independent of the tile size
  // (docs/math/splat.md section 2, after (R15)).
  S radius_sigmas = S(3);
  // Dilation added to the 2D covariance, pixels² (gsplat eps2d).  (R5)
  S eps2d = S(0.3);
  // Alpha clamp: alpha = min(alpha_max, o exp(-sigma)). 0.99 as docs/design.md pins and current
  // gsplat uses; gsplat v1.0-1.4 used 0.999.  (R10)
  S alpha_max = S(0.99);
  // Background colour, `channels` values, composited with the final transmittance; null = 0.
  const S* background = nullptr;
};

template <class S>
Status validate_settings(const SplatSettings<S>& s) {
  std::ostringstream m;
  if (s.tile_size != 8 && s.tile_size != 16 && s.tile_size != 32) {
    m << "settings: tile_size must be 8, 16 or 32, got " << s.tile_size;
    return Status::error(m.str());
  }
  if (!(s.radius_sigmas > S(0) && s.radius_sigmas <= S(100)))
    return Status::error("settings: radius_sigmas must be in (0, 100]");
  if (!(s.eps2d >= S(0) && s.eps2d <= S(1e6)))
    return Status::error("settings: eps2d must be finite and >= 0");
  if (!(s.alpha_max >= kAlphaMin<S> && s.alpha_max < S(1)))
    return Status::error("settings: alpha_max must be in [1/255, 1)");
  return Status::ok();
}

}  // namespace smg::splat
