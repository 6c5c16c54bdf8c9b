// smg/splat/sh.hpp — real spherical harmonics of degree 0..3 for view-dependent colour.
//
// The basis is the one of 3D Gaussian splatting and gsplat (coefficient index b = l² + l + m,
// the constants of the original 3DGS code). Colour = max(Σ_b Y_b(d) coeff_b + 0.5, 0) with d
// the normalised direction from the camera centre to the Gaussian mean, as gsplat's
// rasterization() does.  Equations (R14)-(R15) in docs/math/splat.md.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>

#include "smg/core/types.hpp"

namespace smg::splat {

// Number of coefficients per channel for a degree: (degree + 1)².
constexpr int sh_basis_count(int degree) { return (degree + 1) * (degree + 1); }

namespace sh_detail {
// Scalars at namespace scope (device code may read a namespace-scope constexpr scalar, not an
// array); the degree-2 and degree-3 constants are local arrays of sh_basis.
constexpr double C0 = 0.28209479177387814;
constexpr double C1 = 0.4886025119029199;
}  // namespace sh_detail

// Y_b(d) for b < (degree+1)², d a unit vector; optionally the 3 partial derivatives of each
// basis function with respect to (x, y, z) (dY[3 b + i]), as polynomials in d (the caller
// chains through the normalisation). (R14)
template <class S>
SMG_HOST_DEVICE inline void sh_basis(int degree, const Vector3<S>& d, S* Y, S* dY = nullptr) {
  using namespace sh_detail;
  constexpr double C2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                            -1.0925484305920792, 0.5462742152960396};
  constexpr double C3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                            0.3731763325901154, -0.4570457994644658, 1.445305721320277,
                            -0.5900435899266435};
  const S x = d.x(), y = d.y(), z = d.z();
  Y[0] = S(C0);
  if (dY) dY[0] = dY[1] = dY[2] = S(0);
  if (degree < 1) return;
  const S c1 = S(C1);
  Y[1] = -c1 * y;
  Y[2] = c1 * z;
  Y[3] = -c1 * x;
  if (dY) {
    dY[3] = 0;   dY[4] = -c1; dY[5] = 0;
    dY[6] = 0;   dY[7] = 0;   dY[8] = c1;
    dY[9] = -c1; dY[10] = 0;  dY[11] = 0;
  }
  if (degree < 2) return;
  const S xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
  Y[4] = S(C2[0]) * xy;
  Y[5] = S(C2[1]) * yz;
  Y[6] = S(C2[2]) * (S(2) * zz - xx - yy);
  Y[7] = S(C2[3]) * xz;
  Y[8] = S(C2[4]) * (xx - yy);
  if (dY) {
    S* g = dY + 12;
    g[0] = S(C2[0]) * y;          g[1] = S(C2[0]) * x;          g[2] = 0;
    g[3] = 0;                     g[4] = S(C2[1]) * z;          g[5] = S(C2[1]) * y;
    g[6] = S(-2 * C2[2]) * x;     g[7] = S(-2 * C2[2]) * y;     g[8] = S(4 * C2[2]) * z;
    g[9] = S(C2[3]) * z;          g[10] = 0;                    g[11] = S(C2[3]) * x;
    g[12] = S(2 * C2[4]) * x;     g[13] = S(-2 * C2[4]) * y;    g[14] = 0;
  }
  if (degree < 3) return;
  Y[9] = S(C3[0]) * y * (S(3) * xx - yy);
  Y[10] = S(C3[1]) * xy * z;
  Y[11] = S(C3[2]) * y * (S(4) * zz - xx - yy);
  Y[12] = S(C3[3]) * z * (S(2) * zz - S(3) * xx - S(3) * yy);
  Y[13] = S(C3[4]) * x * (S(4) * zz - xx - yy);
  Y[14] = S(C3[5]) * z * (xx - yy);
  Y[15] = S(C3[6]) * x * (xx - S(3) * yy);
  if (dY) {
    S* g = dY + 27;
    g[0] = S(C3[0]) * S(6) * xy;            g[1] = S(C3[0]) * S(3) * (xx - yy);  g[2] = 0;
    g[3] = S(C3[1]) * yz;                   g[4] = S(C3[1]) * xz;                g[5] = S(C3[1]) * xy;
    g[6] = S(C3[2]) * S(-2) * xy;           g[7] = S(C3[2]) * (S(4) * zz - xx - S(3) * yy);
    g[8] = S(C3[2]) * S(8) * yz;
    g[9] = S(C3[3]) * S(-6) * xz;           g[10] = S(C3[3]) * S(-6) * yz;
    g[11] = S(C3[3]) * (S(6) * zz - S(3) * xx - S(3) * yy);
    g[12] = S(C3[4]) * (S(4) * zz - S(3) * xx - yy);  g[13] = S(C3[4]) * S(-2) * xy;
    g[14] = S(C3[4]) * S(8) * xz;
    g[15] = S(C3[5]) * S(2) * xz;           g[16] = S(C3[5]) * S(-2) * yz;       g[17] = S(C3[5]) * (xx - yy);
    g[18] = S(C3[6]) * S(3) * (xx - yy);    g[19] = S(C3[6]) * S(-6) * xy;       g[20] = 0;
  }
}

// View-dependent colour of one Gaussian: out[k] = max(Σ_b Y_b(d̂) coeffs[b*channels + k] + 0.5, 0)
// with d̂ = dir / |dir| (dir = mean - camera centre, any nonzero length; a zero direction
// evaluates the degree-0 term only). coeffs is [K][channels], K = (degree+1)². (R15)
template <class S>
SMG_HOST_DEVICE
inline void sh_to_color(int degree, int channels, const Vector3<S>& dir, const S* coeffs, S* out) {
  S Y[16];
  const S n = dir.norm();
  const Vector3<S> d = n > S(0) ? Vector3<S>(dir / n) : Vector3<S>::Zero();
  sh_basis<S>(n > S(0) ? degree : 0, d, Y);
  const int K = n > S(0) ? sh_basis_count(degree) : 1;
  for (int k = 0; k < channels; ++k) {
    S v = S(0.5);
    for (int b = 0; b < K; ++b) v += Y[b] * coeffs[b * channels + k];
    out[k] = v > S(0) ? v : S(0);
  }
}

// Backward of sh_to_color: given v_color (dL/d out, `channels` values) writes dL/d coeffs
// ([K][channels], overwritten) and returns dL/d dir (through the normalisation). The clamp at
// 0 passes the gradient where the unclamped value is >= 0 (as torch.clamp_min does).
template <class S>
SMG_HOST_DEVICE
inline Vector3<S> sh_to_color_vjp(int degree, int channels, const Vector3<S>& dir,
                                  const S* coeffs, const S* v_color, S* v_coeffs) {
  S Y[16], dY[48];
  const S n = dir.norm();
  const bool has_dir = n > S(0);
  const Vector3<S> d = has_dir ? Vector3<S>(dir / n) : Vector3<S>::Zero();
  const int deg = has_dir ? degree : 0;
  sh_basis<S>(deg, d, Y, dY);
  const int K = sh_basis_count(deg);
  for (int b = 0; b < sh_basis_count(degree) * channels; ++b) v_coeffs[b] = S(0);
  Vector3<S> v_d = Vector3<S>::Zero();
  for (int k = 0; k < channels; ++k) {
    S v = S(0.5);
    for (int b = 0; b < K; ++b) v += Y[b] * coeffs[b * channels + k];
    if (!(v >= S(0))) continue;  // clamped: no gradient
    const S g = v_color[k];
    for (int b = 0; b < K; ++b) {
      v_coeffs[b * channels + k] = Y[b] * g;
      const S gc = g * coeffs[b * channels + k];
      v_d += gc * Vector3<S>(dY[3 * b], dY[3 * b + 1], dY[3 * b + 2]);
    }
  }
  if (!has_dir) return Vector3<S>::Zero();
  // d̂ = dir/|dir|: dL/ddir = (I - d̂ d̂ᵀ) dL/dd̂ / |dir|.
  return (v_d - d * d.dot(v_d)) / n;
}

}  // namespace smg::splat
