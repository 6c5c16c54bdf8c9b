// smg/graph/point_knn_element.hpp — the per-pair steps of the exact point KNN (docs/math/graph.md
// (G15)), shared by the CPU tree search (graph/point_knn.hpp) and the CUDA kernel
// (cuda/point_knn.cuh), so that both keep the same rows: the squared distance written once, the
// radius test written once, the row order (d², j) written once.
//
// Pool-free and allocation-free: a CUDA translation unit includes it.
#pragma once

#include "smg/core/config.hpp"

#include <cstdint>
#include <limits>
#include <sstream>
#include <string>

#include "smg/core/status.hpp"
#include "smg/core/views.hpp"

namespace smg {

namespace detail {
// a · b and a + b, each rounded once: on the device without nvcc's default contraction into an
// FMA, so that the GPU's d² equals the host's (built without -mfma, smg's default) bit for bit.
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE S mul_rn(S a, S b) {
#ifdef __CUDA_ARCH__
  if constexpr (sizeof(S) == 4) return __fmul_rn(a, b); else return __dmul_rn(a, b);
#else
  return a * b;
#endif
}
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE S add_rn(S a, S b) {
#ifdef __CUDA_ARCH__
  if constexpr (sizeof(S) == 4) return __fadd_rn(a, b); else return __dadd_rn(a, b);
#else
  return a + b;
#endif
}
}  // namespace detail

// d² = (p − q)·(p − q) of two points [3], summed x, y, z in this order (G15). Symmetric bit for
// bit ((a − b)² = (b − a)² in IEEE arithmetic), so d²_ij = d²_ji in every row. A host build with
// -mfma may contract the sum into FMAs (the rows stay exact for that build's d²).
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE S point_distance2(const S* p, const S* q) {
  using detail::add_rn;
  using detail::mul_rn;
  const S dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
  return add_rn(add_rn(mul_rn(dx, dx), mul_rn(dy, dy)), mul_rn(dz, dz));
}

// Whether (d2, j) comes before (e2, l) in a row: by squared distance, ties by index (G15).
template <class S, class I>
SMG_FORCE_INLINE SMG_HOST_DEVICE bool point_knn_before(S d2, I j, S e2, I l) {
  return d2 < e2 || (d2 == e2 && j < l);
}

// Inserts candidate j at squared distance d2 into a row of at most k entries kept sorted by
// (d², j) in dist[0, found) and idx[0, found) (caller storage: registers, a CUDA thread's local
// array or the output row). Candidates beyond the squared radius r2 (d2 > r2, frnn's test) are
// not entered; a full row keeps its k best. `found` is updated.
template <class S, class I>
SMG_FORCE_INLINE SMG_HOST_DEVICE void point_knn_insert(S d2, I j, S r2, int k, int& found, S* dist,
                                                       I* idx) {
  if (!(d2 <= r2)) return;
  if (found == k && !point_knn_before(d2, j, dist[k - 1], idx[k - 1])) return;
  int q = found < k ? found++ : k - 1;
  while (q > 0 && point_knn_before(d2, j, dist[q - 1], idx[q - 1])) {
    dist[q] = dist[q - 1];
    idx[q] = idx[q - 1];
    --q;
  }
  dist[q] = d2;
  idx[q] = j;
}

// The bound a search may prune at: the row's k-th squared distance once it holds k, else r2.
// A subtree whose box is farther than this (strictly) cannot change the row, ties included.
template <class S>
SMG_FORCE_INLINE SMG_HOST_DEVICE S point_knn_bound(S r2, int k, int found, const S* dist) {
  return found < k ? r2 : dist[k - 1];
}

// Pads entries [found, k) of a row: index −1 and squared distance +inf (G15).
template <class S, class I>
SMG_FORCE_INLINE SMG_HOST_DEVICE void point_knn_pad(int k, int found, S* dist, I* idx) {
  for (int q = found; q < k; ++q) {
    dist[q] = std::numeric_limits<S>::infinity();  // constexpr: device code too (relaxed constexpr)
    idx[q] = I(-1);
  }
}

namespace detail {

// The checks of (G15)'s arguments that need no point values (shared by validate_point_knn and
// the CUDA launcher, which cannot read device memory): k >= 1; radius >= 0 or +inf; N within the
// int32 ids of the search and the index type I; indices and squared distances of shape [N][k].
template <class S, class I>
Status check_point_knn_arguments(Index N, int k, double radius, const void* points,
                                 TableView<I, Eigen::Dynamic> indices, TableView<S, Eigen::Dynamic> distances2) {
  if (k < 1) return Status::error("k: must be >= 1, got " + std::to_string(k));
  if (!(radius >= 0)) return Status::error("radius: must be >= 0 or +inf, got " + std::to_string(radius));
  if (N > 0 && points == nullptr) return Status::error("points: null data pointer for a non-empty array");
  if (N > Index(std::numeric_limits<std::int32_t>::max()))  // the search's ids are int32
    return Status::error("points: N = " + std::to_string(N) + " exceeds 2^31 - 1 points");
  if (static_cast<double>(N) > static_cast<double>(std::numeric_limits<I>::max()))
    return Status::error("indices: the index type cannot hold N = " + std::to_string(N));
  auto check = [&](const char* name, Index rows, Index cols, const void* data) {
    if (rows != N || cols != k) {
      std::ostringstream s;
      s << name << ": expected shape [N=" << N << "][k=" << k << "], got [" << rows << "][" << cols << "]";
      return Status::error(s.str());
    }
    if (data == nullptr && rows * cols > 0)
      return Status::error(std::string(name) + ": null data pointer for a non-empty array");
    return Status::ok();
  };
  if (Status s = check("indices", indices.rows(), indices.cols(), indices.data()); !s) return s;
  return check("distances2", distances2.rows(), distances2.cols(), distances2.data());
}

// r² of (G15) in the output's precision (frnn computes float r2 = r * r), +inf for r = +inf.
template <class S>
inline S point_knn_radius2(double radius) {
  const S r = static_cast<S>(radius);
  return r * r;
}

}  // namespace detail

}  // namespace smg
