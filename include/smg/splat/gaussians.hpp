// smg/splat/gaussians.hpp — views of the Gaussian parameters, their gradients, the rendered
// images, and their validation.
//
// Layouts are those of a gsplat / 3DGS trainer's tensors (row-major, caller memory):
//   means           [G][3]   world units
//   quats           [G][4]   (w, x, y, z), any nonzero norm (normalised on entry, as gsplat)
//   log_scales      [G][3]   scale = exp(log_scale) along the rotated axes
//   opacity_logits  [G]      opacity = sigmoid(logit)
//   colors          [G][C]   when sh_degree < 0 (used as they are, any real values), or
//                   [G][K][C] spherical-harmonics coefficients, K = (sh_degree + 1)², colour =
//                   max(SH + 0.5, 0) (sh.hpp)
// Images: colour [H][W][C], alpha [H][W], expected depth [H][W].
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <sstream>
#include <string>

#include "smg/core/status.hpp"
#include "smg/core/views.hpp"
#include "smg/splat/settings.hpp"
#include "smg/splat/sh.hpp"

namespace smg::splat {

template <class S>
struct GaussianParams {
  TableView<const S, 3> means;
  TableView<const S, 4> quats;
  TableView<const S, 3> log_scales;
  TableView<const S, 1> opacity_logits;
  TableView<const S, Eigen::Dynamic> colors;  // [G][C] or [G][K*C]
  int sh_degree = -1;                         // -1: plain colours; 0..3: SH coefficients

  SMG_HOST_DEVICE Index count() const { return means.rows(); }
  // Colour channels C implied by the colours' width and sh_degree.
  SMG_HOST_DEVICE Index channels() const {
    return sh_degree < 0 ? colors.cols() : colors.cols() / sh_basis_count(sh_degree);
  }
};

// Gradients of a scalar loss with respect to the parameters, same layouts; every view is
// optional (null data = not computed) and is overwritten, not accumulated.
//   quats          raw 4-vector gradient through the normalisation, as gsplat returns it
//   quats_tangent  [G][3] right-tangent gradient: d/dφ L(q̂ ⊗ Exp(φ)) at φ = 0
//   means2d        [G][2] gradient w.r.t. the projected 2D means (pixels), what 3DGS
//                  densification accumulates; 0 for culled Gaussians
template <class S>
struct GaussianGrads {
  TableView<S, 3> means;
  TableView<S, 4> quats;
  TableView<S, 3> quats_tangent;
  TableView<S, 3> log_scales;
  TableView<S, 1> opacity_logits;
  TableView<S, Eigen::Dynamic> colors;
  TableView<S, 2> means2d;
};

// Rendered images. image is required; alpha and depth are optional (null = not written).
template <class S>
struct RenderImages {
  SequenceView<S, Eigen::Dynamic> image;  // [H][W][C]
  SequenceView<S, 1> alpha;               // [H][W], 1 - final transmittance
  SequenceView<S, 1> depth;               // [H][W], expected camera-space z (R13)
};

// Gradients of the loss with respect to the rendered images; each optional (null = zero).
template <class S>
struct RenderImageGrads {
  SequenceView<const S, Eigen::Dynamic> image;  // [H][W][C]
  SequenceView<const S, 1> alpha;               // [H][W]
  SequenceView<const S, 1> depth;               // [H][W]
};

namespace detail {
template <class T, int Cols>
Status check_table(const TableView<T, Cols>& v, Index rows, Index cols, const std::string& name,
                   bool finite) {
  if (v.rows() != rows || v.cols() != cols) {
    std::ostringstream m;
    m << name << ": expected shape [" << rows << "][" << cols << "], got [" << v.rows() << "]["
      << v.cols() << "]";
    return Status::error(m.str());
  }
  if (v.data() == nullptr && rows * cols > 0)
    return Status::error(name + ": null data pointer for a non-empty array");
  if (finite)
    for (Index r = 0; r < rows; ++r)
      for (Index c = 0; c < cols; ++c)
        if (!std::isfinite(v(r, c))) {
          std::ostringstream m;
          m << name << ": element [" << r << "][" << c << "] is "
            << (std::isnan(v(r, c)) ? "NaN" : "Inf");
          return Status::error(m.str());
        }
  return Status::ok();
}
template <class T, int Dim>
Status check_image(const SequenceView<T, Dim>& v, Index h, Index w, Index c,
                   const std::string& name) {
  if (v.frames() != h || v.nodes() != w || (Dim != 1 && v.dim() != c)) {
    std::ostringstream m;
    m << name << ": expected shape [H=" << h << "][W=" << w << "]";
    if (Dim != 1) m << "[C=" << c << "]";
    m << ", got [" << v.frames() << "][" << v.nodes() << "]";
    if (Dim != 1) m << "[" << v.dim() << "]";
    return Status::error(m.str());
  }
  if (v.data() == nullptr) return Status::error(name + ": null data pointer");
  return Status::ok();
}
}  // namespace detail

// Shapes, null pointers, NaN/Inf, zero quaternions, sh_degree in [-1, 3], colour width
// C or K*C with C >= 1 (and C == channels when channels >= 0).
template <class S>
Status validate_gaussians(const GaussianParams<S>& g, Index channels = -1) {
  const Index G = g.count();
  if (g.sh_degree < -1 || g.sh_degree > kMaxShDegree) {
    std::ostringstream m;
    m << "sh_degree: must be -1 (plain colours) or 0.." << kMaxShDegree << ", got " << g.sh_degree;
    return Status::error(m.str());
  }
  if (Status s = detail::check_table(g.means, G, 3, "means", true); !s) return s;
  if (Status s = detail::check_table(g.quats, G, 4, "quats", true); !s) return s;
  if (Status s = detail::check_table(g.log_scales, G, 3, "log_scales", true); !s) return s;
  if (Status s = detail::check_table(g.opacity_logits, G, 1, "opacity_logits", true); !s) return s;
  const Index K = g.sh_degree < 0 ? 1 : sh_basis_count(g.sh_degree);
  const Index C = g.colors.cols() / K;
  if (g.colors.cols() < 1 || g.colors.cols() % K != 0 || (channels >= 0 && C != channels)) {
    std::ostringstream m;
    m << "colors: expected " << (channels >= 0 ? std::to_string(channels) : std::string("C >= 1"))
      << " channels";
    if (K > 1) m << " x " << K << " SH coefficients";
    m << " per Gaussian, got " << g.colors.cols() << " columns";
    return Status::error(m.str());
  }
  if (Status s = detail::check_table(g.colors, G, g.colors.cols(), "colors", true); !s) return s;
  for (Index i = 0; i < G; ++i) {
    const S n = g.quats.row(i).norm();
    if (!(n > S(0))) {
      std::ostringstream m;
      m << "quats: element [" << i << "] is the zero quaternion";
      return Status::error(m.str());
    }
  }
  return Status::ok();
}

// Output images of render_forward: image [H][W][C] required, alpha/depth [H][W] if given.
template <class S>
Status validate_render_images(const RenderImages<S>& out, Index height, Index width, Index channels) {
  if (Status s = detail::check_image(out.image, height, width, channels, "image"); !s) return s;
  if (out.alpha.data())
    if (Status s = detail::check_image(out.alpha, height, width, 1, "alpha"); !s) return s;
  if (out.depth.data())
    if (Status s = detail::check_image(out.depth, height, width, 1, "depth"); !s) return s;
  return Status::ok();
}

// Incoming gradients of render_backward: each given view must have the image's shape and be
// finite.
template <class S>
Status validate_render_image_grads(const RenderImageGrads<S>& g, Index height, Index width,
                                   Index channels) {
  auto finite = [](const auto& v, const std::string& name) {
    for (Index k = 0; k < v.size(); ++k)
      if (!std::isfinite(v.data()[k]))
        return Status::error(name + ": non-finite value at flat index " + std::to_string(k));
    return Status::ok();
  };
  if (g.image.data()) {
    if (Status s = detail::check_image(g.image, height, width, channels, "grad_image"); !s) return s;
    if (Status s = finite(g.image, "grad_image"); !s) return s;
  }
  if (g.alpha.data()) {
    if (Status s = detail::check_image(g.alpha, height, width, 1, "grad_alpha"); !s) return s;
    if (Status s = finite(g.alpha, "grad_alpha"); !s) return s;
  }
  if (g.depth.data()) {
    if (Status s = detail::check_image(g.depth, height, width, 1, "grad_depth"); !s) return s;
    if (Status s = finite(g.depth, "grad_depth"); !s) return s;
  }
  return Status::ok();
}

// Gradient outputs: every given view must be [G][width of its variable].
template <class S>
Status validate_gaussian_grads(const GaussianGrads<S>& g, const GaussianParams<S>& params) {
  const Index G = params.count();
  auto check = [&](const auto& v, Index cols, const char* name) {
    if (!v.data()) return Status::ok();
    return detail::check_table(v, G, cols, std::string("grad ") + name, false);
  };
  if (Status s = check(g.means, 3, "means"); !s) return s;
  if (Status s = check(g.quats, 4, "quats"); !s) return s;
  if (Status s = check(g.quats_tangent, 3, "quats_tangent"); !s) return s;
  if (Status s = check(g.log_scales, 3, "log_scales"); !s) return s;
  if (Status s = check(g.opacity_logits, 1, "opacity_logits"); !s) return s;
  if (Status s = check(g.colors, params.colors.cols(), "colors"); !s) return s;
  if (Status s = check(g.means2d, 2, "means2d"); !s) return s;
  return Status::ok();
}

}  // namespace smg::splat
