// smg/energy/lanes.hpp — a small "lane" type for SIMD across independent problems.
//
// The LRM neighbourhood maths is written once, templated on its lane type V: a plain scalar
// (float, double, Eigen::AutoDiffScalar — residual form, autodiff checks) or Lanes<S, W>, W
// independent neighbourhoods at once (the fast kernel). Lanes' operators are fixed-length
// element loops forced inline, which GCC and Clang turn into SIMD instructions; the square
// root goes through Eigen's packet sqrt, which vectorises whatever -fmath-errno says. Control
// flow becomes masks (lane_greater / lane_select) so every lane runs the same instructions.
// Also here: moving lanes to and from memory (lane_load / lane_store / lane_ref), and the
// vectorised sqrt and sum over plain arrays that the C-ARAP kernel's loops use.
#pragma once

#include "smg/core/config.hpp"

#include <cmath>
#include <cstring>
#include <type_traits>
#include <utility>

#include <Eigen/Core>

#include "smg/core/scalar.hpp"
#include "smg/core/types.hpp"

#ifndef SMG_LANE_INLINE
#define SMG_LANE_INLINE SMG_FORCE_INLINE
#endif

namespace smg::detail {

// GCC/Clang vector extensions on the host. nvcc's device pass has none: there Lanes falls back
// to the plain array below (its instantiations from the host-device functions are compiled for
// the device too, though only scalar lanes ever run there); the host pass, and so the CPU
// kernels' instructions, are unchanged.
#ifndef SMG_HAVE_VECTOR_EXTENSIONS
#if (defined(__GNUC__) || defined(__clang__)) && !defined(__CUDA_ARCH__)
#define SMG_HAVE_VECTOR_EXTENSIONS 1
#else
#define SMG_HAVE_VECTOR_EXTENSIONS 0
#endif
#endif

template <class S, int W>
struct Lanes {
#if SMG_HAVE_VECTOR_EXTENSIONS
  // A native SIMD value (GCC/Clang vector extension): operators are single instructions.
  typedef S Vec __attribute__((vector_size(W * sizeof(S))));
  using Int = typename FloatBits<S>::Signed;
  typedef Int IVec __attribute__((vector_size(W * sizeof(S))));
#else
  struct Vec {
    S e[W];
    SMG_HOST_DEVICE S& operator[](int l) { return e[l]; }
    SMG_HOST_DEVICE const S& operator[](int l) const { return e[l]; }
  };
#endif
  Vec v;

  Lanes() = default;
  SMG_HOST_DEVICE static SMG_LANE_INLINE Lanes constant(S s) {
    Lanes r;
    for (int l = 0; l < W; ++l) r.v[l] = s;
    return r;
  }
  SMG_HOST_DEVICE SMG_LANE_INLINE S& operator[](int l) { return reinterpret_cast<S*>(&v)[l]; }
  SMG_HOST_DEVICE SMG_LANE_INLINE const S& operator[](int l) const { return reinterpret_cast<const S*>(&v)[l]; }

#if SMG_HAVE_VECTOR_EXTENSIONS
#define SMG_LANES_BINARY(op)                                                    \
  friend SMG_HOST_DEVICE SMG_LANE_INLINE Lanes operator op(const Lanes& a, const Lanes& b) {    \
    Lanes r;                                                                    \
    r.v = a.v op b.v;                                                           \
    return r;                                                                   \
  }                                                                             \
  friend SMG_HOST_DEVICE SMG_LANE_INLINE Lanes operator op(const Lanes& a, S b) {               \
    Lanes r;                                                                    \
    r.v = a.v op b;                                                             \
    return r;                                                                   \
  }                                                                             \
  friend SMG_HOST_DEVICE SMG_LANE_INLINE Lanes operator op(S a, const Lanes& b) {               \
    Lanes r;                                                                    \
    r.v = a op b.v;                                                             \
    return r;                                                                   \
  }                                                                             \
  SMG_HOST_DEVICE SMG_LANE_INLINE Lanes& operator op##=(const Lanes& b) {                       \
    v = v op b.v;                                                               \
    return *this;                                                               \
  }
#else
#define SMG_LANES_BINARY(op)                                                    \
  friend SMG_HOST_DEVICE SMG_LANE_INLINE Lanes operator op(const Lanes& a, const Lanes& b) {    \
    Lanes r;                                                                    \
    for (int l = 0; l < W; ++l) r.v[l] = a.v[l] op b.v[l];                      \
    return r;                                                                   \
  }                                                                             \
  friend SMG_HOST_DEVICE SMG_LANE_INLINE Lanes operator op(const Lanes& a, S b) {               \
    Lanes r;                                                                    \
    for (int l = 0; l < W; ++l) r.v[l] = a.v[l] op b;                           \
    return r;                                                                   \
  }                                                                             \
  friend SMG_HOST_DEVICE SMG_LANE_INLINE Lanes operator op(S a, const Lanes& b) {               \
    Lanes r;                                                                    \
    for (int l = 0; l < W; ++l) r.v[l] = a op b.v[l];                           \
    return r;                                                                   \
  }                                                                             \
  SMG_HOST_DEVICE SMG_LANE_INLINE Lanes& operator op##=(const Lanes& b) {                       \
    for (int l = 0; l < W; ++l) v[l] = v[l] op b.v[l];                          \
    return *this;                                                               \
  }
#endif
  SMG_LANES_BINARY(+)
  SMG_LANES_BINARY(-)
  SMG_LANES_BINARY(*)
  SMG_LANES_BINARY(/)
#undef SMG_LANES_BINARY

  friend SMG_HOST_DEVICE SMG_LANE_INLINE Lanes operator-(const Lanes& a) {
    Lanes r;
    for (int l = 0; l < W; ++l) r.v[l] = -a.v[l];
    return r;
  }
};

template <class V>
struct LaneTraits {
  static constexpr bool is_lanes = false;
  using Mask = bool;
};
template <class S, int W>
struct LaneTraits<Lanes<S, W>> {
  static constexpr bool is_lanes = true;
#if SMG_HAVE_VECTOR_EXTENSIONS
  using Mask = typename Lanes<S, W>::IVec;  // all ones / all zeros per lane
#else
  struct Mask {
    bool m[W];
  };
#endif
};

template <class V, class L>
SMG_HOST_DEVICE SMG_LANE_INLINE V lane_constant(L value) {
  if constexpr (LaneTraits<V>::is_lanes) {
    return V::constant(value);
  } else {
    return V(value);
  }
}

template <class V>
SMG_HOST_DEVICE SMG_LANE_INLINE typename LaneTraits<V>::Mask lane_greater(const V& a, const V& b) {
  if constexpr (LaneTraits<V>::is_lanes) {
#if SMG_HAVE_VECTOR_EXTENSIONS
    return a.v > b.v;
#else
    typename LaneTraits<V>::Mask r{};
    for (int l = 0; l < int(sizeof(r.m)); ++l) r.m[l] = a.v[l] > b.v[l];
    return r;
#endif
  } else {
    return bool(a > b);
  }
}

// mask ? a : b, lane-wise (bitwise blend, no branch).
template <class M, class V>
SMG_HOST_DEVICE SMG_LANE_INLINE V lane_select(const M& mask, const V& a, const V& b) {
  if constexpr (LaneTraits<V>::is_lanes) {
    V r;
#if SMG_HAVE_VECTOR_EXTENSIONS
    using IVec = M;
    using Vec = decltype(r.v);
    r.v = (Vec)(((IVec)a.v & mask) | ((IVec)b.v & ~mask));
#else
    for (int l = 0; l < int(sizeof(mask.m)); ++l) r.v[l] = mask.m[l] ? a.v[l] : b.v[l];
#endif
    return r;
  } else {
    return mask ? a : b;
  }
}

template <class V>
SMG_HOST_DEVICE SMG_LANE_INLINE V lane_sqrt(const V& a) {
  if constexpr (LaneTraits<V>::is_lanes) {
    using SS = std::remove_const_t<std::remove_reference_t<decltype(a[0])>>;
    constexpr int W = int(sizeof(a.v) / sizeof(SS));
    V r;
    Eigen::Map<Eigen::Array<SS, W, 1>, Eigen::Unaligned> out(&r[0]);
    out = Eigen::Map<const Eigen::Array<SS, W, 1>, Eigen::Unaligned>(&a[0]).sqrt();
    return r;
  } else {
    using std::sqrt;
    return sqrt(a);
  }
}

// (fill, a_0, …, a_{W−2}): the lanes moved up by one, `fill` into lane 0, in registers (one
// shuffle) where a store and an overlapping load would stall on store forwarding (LRM's
// velocity part, terms/lrm.hpp).
// (Not under nvcc, whose front end does not expand a pack inside the builtin's arguments; the
// CPU terms' lanes do not run in CUDA translation units.)
#if SMG_HAVE_VECTOR_EXTENSIONS && defined(__has_builtin) && !defined(__CUDACC__)
#if __has_builtin(__builtin_shufflevector)
#define SMG_HAVE_SHUFFLEVECTOR 1
#endif
#endif
template <class S, int W, std::size_t... L>
SMG_LANE_INLINE Lanes<S, W> lanes_shift_up(const Lanes<S, W>& a, S fill,
                                           std::index_sequence<L...>) {
  Lanes<S, W> r;
#ifdef SMG_HAVE_SHUFFLEVECTOR
  const Lanes<S, W> f = Lanes<S, W>::constant(fill);
  r.v = __builtin_shufflevector(a.v, f.v, W, static_cast<int>(L)...);
#else
  r[0] = fill;
  ((r[static_cast<int>(L) + 1] = a[static_cast<int>(L)]), ...);
#endif
  return r;
}
template <class S, int W>
SMG_LANE_INLINE Lanes<S, W> lanes_shift_up(const Lanes<S, W>& a, S fill) {
  return lanes_shift_up(a, fill, std::make_index_sequence<W - 1>());
}

// Lane v (W scalars) from / to memory; W = 1 for scalar lanes.
template <class V, class S>
SMG_LANE_INLINE void lane_load(V& v, const S* p) {
  if constexpr (LaneTraits<V>::is_lanes) {
    std::memcpy(&v, p, sizeof(V));
  } else {
    v = *p;
  }
}
template <class V, class S>
SMG_LANE_INLINE void lane_store(const V& v, S* p) {
  if constexpr (LaneTraits<V>::is_lanes) {
    std::memcpy(p, &v, sizeof(V));
  } else {
    *p = v;
  }
}
template <class V, class S>
SMG_LANE_INLINE S& lane_ref(V& v, Index l) {
  if constexpr (LaneTraits<V>::is_lanes) {
    return v[static_cast<int>(l)];
  } else {
    (void)l;
    return v;
  }
}

// Plain arrays (the C-ARAP kernel's loops over [edge][frame]).

// out[k] = sqrt(in[k]); through Eigen's packet sqrt for float/double so that it vectorises
// whatever -fmath-errno says (a plain loop over std::sqrt does not).
template <class S>
inline void sqrt_array(const S* in, S* out, Index n) {
  if constexpr (std::is_floating_point_v<S>) {
    Eigen::Map<Eigen::Array<S, Eigen::Dynamic, 1>>(out, n) =
        Eigen::Map<const Eigen::Array<S, Eigen::Dynamic, 1>>(in, n).sqrt();
  } else {
    using std::sqrt;
    for (Index k = 0; k < n; ++k) out[k] = sqrt(in[k]);
  }
}

// Σ_k in[k] through Eigen's packet sum for float/double (its fixed association order, so the
// result does not depend on the caller), a plain loop for other scalars.
template <class S>
inline S sum_array(const S* in, Index n) {
  if constexpr (std::is_floating_point_v<S>) {
    return n > 0 ? Eigen::Map<const Eigen::Array<S, Eigen::Dynamic, 1>>(in, n).sum() : S(0);
  } else {
    S s(0);
    for (Index k = 0; k < n; ++k) s += in[k];
    return s;
  }
}

}  // namespace smg::detail
