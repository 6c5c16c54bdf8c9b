// smg/core/rotation_gradient.hpp — rotation gradients in the right tangent and for raw,
// unnormalised quaternion coordinates, and the view through which an entry point returns
// either (docs/math/core.md (Q3), (Q5); docs/conventions.md "Rotation gradients").
//
// smg's kernels differentiate with respect to the right tangent φ of the normalised rotation
// (R(q̂) ← R(q̂) Exp(φ)). A PyTorch trainer that holds raw quaternions q (w, x, y, z) and steps
// them with Adam wants ∂L/∂q instead. With C(q) = L(q)[:, 1:4], the vector columns of the left
// product matrix of the raw q (docs/math/core.md (Q1)):
//
//   raw from tangent:  g_q = (2 / |q|²) C(q) g_φ                                       (Q5)
//   tangent from raw:  g_φ = ½ C(q)ᵀ g_q                                               (Q3)
//
// g_q is orthogonal to q (a function of q̂ does not change along q); the second map ignores any
// radial component of g_q, so it is the inverse of the first on that orthogonal complement.
// Per-element functions only (CUDA kernels include this header): the batched loops over
// [T][N] arrays are in rotation_gradient_batch.hpp.
#pragma once

#include "smg/core/config.hpp"

#include <type_traits>

#include "smg/core/scalar.hpp"
#include "smg/core/views.hpp"

namespace smg {

// Adds the raw-coordinate gradient of one quaternion to g_q[4], given its right-tangent gradient
// g_phi[3]; q[4] (w, x, y, z) need not be unit (nonzero).  (Q5)
template <class S>
SMG_HOST_DEVICE
inline void add_quaternion_gradient_from_tangent(const S* q, const S* g_phi, S* g_q) {
  using L = Literal<S>;
  const S w = q[0], x = q[1], y = q[2], z = q[3];
  const S f = L(2) / (w * w + x * x + y * y + z * z);
  const S a = g_phi[0], b = g_phi[1], c = g_phi[2];
  g_q[0] += f * (-x * a - y * b - z * c);
  g_q[1] += f * (w * a - z * b + y * c);
  g_q[2] += f * (z * a + w * b - x * c);
  g_q[3] += f * (-y * a + x * b + w * c);
}

// Adds the right-tangent gradient g_phi[3] of rotation `item` (a flat index into [..][3] tangent
// and [..][4] quaternion arrays; q[4] is that rotation) to whichever output the caller asked for:
// the tangent gradient grad_tangent and/or, by (Q5), the raw-quaternion gradient grad_raw (each
// may be null). The one place a term's element hands its rotation gradient to a caller's array.
template <class S>
SMG_HOST_DEVICE
inline void add_rotation_gradient(const S* q, Index item, const S* g_phi, S* grad_tangent, S* grad_raw) {
  if (grad_tangent != nullptr)
    for (int c = 0; c < 3; ++c) grad_tangent[item * 3 + c] += g_phi[c];
  if (grad_raw != nullptr) add_quaternion_gradient_from_tangent(q, g_phi, grad_raw + item * 4);  // (Q5)
}

// Adds the right-tangent gradient of one rotation to g_phi[3], given the raw-coordinate gradient
// g_q[4] of the (possibly unnormalised) quaternion q[4]; the component of g_q along q is
// ignored.  (Q3)
template <class S>
SMG_HOST_DEVICE
inline void add_tangent_gradient_from_quaternion(const S* q, const S* g_q, S* g_phi) {
  using L = Literal<S>;
  const S w = q[0], x = q[1], y = q[2], z = q[3];
  const S gw = g_q[0], gx = g_q[1], gy = g_q[2], gz = g_q[3];
  g_phi[0] += L(0.5) * (-x * gw + w * gx + z * gy - y * gz);
  g_phi[1] += L(0.5) * (-y * gw - z * gx + w * gy + x * gz);
  g_phi[2] += L(0.5) * (-z * gw + y * gx - x * gy + w * gz);
}

// Where an entry point adds a rotation gradient [T][N][...]: either the right tangent
// (TangentsView, [T][N][3]) or raw quaternion coordinates (QuaternionsView, [T][N][4]); both
// convert implicitly, and {} means "not computed". Pass raw when the caller optimises the
// quaternions it gave smg as free 4-vectors (PyTorch + Adam).
template <class S>
class RotationGradientView {
 public:
  RotationGradientView() = default;
  RotationGradientView(TangentsView<S> tangent) : tangent_(tangent) {}  // NOLINT(google-explicit-constructor)
  RotationGradientView(QuaternionsView<S> raw) : raw_(raw) {}          // NOLINT(google-explicit-constructor)
  // {data, T, N}: the right tangent [T][N][3], as before raw gradients existed.
  RotationGradientView(S* tangent, Index frames, Index nodes) : tangent_(tangent, frames, nodes) {}

  bool empty() const { return tangent_.data() == nullptr && raw_.data() == nullptr; }
  bool is_raw() const { return raw_.data() != nullptr; }
  TangentsView<S> tangent() const { return tangent_; }
  QuaternionsView<S> raw() const { return raw_; }
  Index frames() const { return is_raw() ? raw_.frames() : tangent_.frames(); }
  Index nodes() const { return is_raw() ? raw_.nodes() : tangent_.nodes(); }

 private:
  TangentsView<S> tangent_;
  QuaternionsView<S> raw_;
};

}  // namespace smg
