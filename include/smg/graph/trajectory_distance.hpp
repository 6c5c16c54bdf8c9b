// smg/graph/trajectory_distance.hpp — the distance between two node trajectories, aggregated
// over the frames where both are visible (docs/design.md "Trajectory distance"; docs/math/graph.md
// (G1)-(G3)).
//
//   S_ij   = { t : v_{t,i} = v_{t,j} = 1 }                       co-visible frames   (G1)
//   d_ij^t = |x_i^t - x_j^t|                                      per-frame distance  (G1)
//   paper      D_ij = mean of the min(m, |S_ij|) smallest d_ij^t                      (G2)
//   robust_max D_ij = the min(m, |S_ij|)-th largest d_ij^t (MoSca's code)             (G3)
//
// A pair with |S_ij| < max(1, min_covisible) has no distance (D = +inf: never neighbours).
// Both aggregations satisfy D_ij >= min_{t in S_ij} d_ij^t, the bound the exact KNN relies on
// (G5). Distances are computed as sqrt of the squared coordinate differences; a pair whose
// squared distance overflows gets D = +inf (coordinates beyond ~1e154 in double, ~1e19 in float).
//
// Visibility is a [T][N] uint8 view of 0/1; an empty view (default-constructed) means every
// node is visible in every frame.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"

namespace smg {

// How per-frame distances over the co-visible frames are combined into one trajectory distance.
enum class Aggregation {
  paper,       // mean of the m smallest (the paper: "three co-visible frames with the smallest distances")
  robust_max,  // the m-th largest (MoSca's code)
};

struct TrajectoryDistanceOptions {
  Aggregation aggregation = Aggregation::paper;
  int m = 3;              // co-visible distances aggregated per pair (>= 1)
  int min_covisible = 1;  // a pair needs |S_ij| >= max(1, min_covisible) frames (>= 0)
};

inline const char* to_string(Aggregation a) {
  return a == Aggregation::paper ? "paper" : "robust_max";
}

namespace detail {

inline int count_zeros_low(std::uint64_t x) {
#if defined(__GNUC__) || defined(__clang__)
  return __builtin_ctzll(x);
#else
  int n = 0;
  while (!(x & 1u)) { x >>= 1; ++n; }
  return n;
#endif
}
inline int popcount64(std::uint64_t x) {
#if defined(__GNUC__) || defined(__clang__)
  return __builtin_popcountll(x);
#else
  int n = 0;
  while (x) { x &= x - 1; ++n; }
  return n;
#endif
}

// A default-constructed visibility view (null data, no frames, no nodes) means "all visible".
inline bool visibility_absent(const VisibilityView<const std::uint8_t>& v) {
  return v.data() == nullptr && v.frames() == 0 && v.nodes() == 0;
}
inline bool visible(const VisibilityView<const std::uint8_t>& v, Index t, Index i) {
  return v.data() == nullptr || v(t, i) != 0;
}

// Checks positions [T][N][3] (T >= 1) and an optional visibility [T][N]; also that N fits the
// int32 node ids of graph outputs.
template <class S>
Status validate_trajectories(PositionsView<const S> x, VisibilityView<const std::uint8_t> v) {
  if (x.frames() < 1) return Status::error("positions: needs at least one frame (T >= 1)");
  if (x.nodes() >= static_cast<Index>(std::numeric_limits<std::int32_t>::max()))
    return Status::error("positions: too many nodes for int32 node ids");
  if (Status s = validate_positions<S>(x, -1, -1); !s) return s;
  if (!visibility_absent(v)) {
    if (Status s = validate_visibility<std::uint8_t>(v, x.frames(), x.nodes()); !s) return s;
  }
  return Status::ok();
}

inline Status validate_distance_options(const TrajectoryDistanceOptions& o) {
  if (o.m < 1) return Status::error("m: must be >= 1, got " + std::to_string(o.m));
  if (o.min_covisible < 0)
    return Status::error("min_covisible: must be >= 0, got " + std::to_string(o.min_covisible));
  if (o.aggregation != Aggregation::paper && o.aggregation != Aggregation::robust_max)
    return Status::error("aggregation: unknown value");
  return Status::ok();
}

// Node-major copy of the trajectories: pos [N][T][3] and visibility bitsets [N][W], W =
// ceil(T / 64). Pair distances then stream two contiguous arrays instead of striding through
// the frame-major input (N*3 scalars apart per frame). Memory: N*T*3 scalars + N*W words.
template <class S>
struct TrajectoryStore {
  Index frames = 0, nodes = 0, words = 0;
  std::vector<S> pos;                 // [N][T][3]
  std::vector<std::uint64_t> vis;     // [N][W], bit t%64 of word t/64
  std::vector<std::int32_t> visible;  // [N] number of visible frames

  const S* p(Index i) const { return pos.data() + i * frames * 3; }
  const std::uint64_t* bits(Index i) const { return vis.data() + i * words; }
  bool is_visible(Index i, Index t) const { return (bits(i)[t >> 6] >> (t & 63)) & 1u; }
  std::size_t bytes() const {
    return pos.capacity() * sizeof(S) + vis.capacity() * sizeof(std::uint64_t) +
           visible.capacity() * sizeof(std::int32_t);
  }

  void build(PositionsView<const S> x, VisibilityView<const std::uint8_t> v,
             ParallelOptions parallel) {
    frames = x.frames();
    nodes = x.nodes();
    words = (frames + 63) / 64;
    pos.assign(static_cast<std::size_t>(nodes * frames * 3), S(0));
    vis.assign(static_cast<std::size_t>(nodes * words), 0u);
    visible.assign(static_cast<std::size_t>(nodes), 0);
    // Blocks of 64 nodes: each frame's rows of the block are read contiguously.
    constexpr Index kBlock = 64;
    const Index blocks = (nodes + kBlock - 1) / kBlock;
    parallel_for(
        blocks,
        [&](Index b0, Index b1) {
          for (Index b = b0; b < b1; ++b) {
            const Index i0 = b * kBlock, i1 = std::min(nodes, i0 + kBlock);
            for (Index t = 0; t < frames; ++t)
              for (Index i = i0; i < i1; ++i) {
                const S* src = x.ptr(t, i);
                S* dst = pos.data() + (i * frames + t) * 3;
                dst[0] = src[0];
                dst[1] = src[1];
                dst[2] = src[2];
                if (detail::visible(v, t, i)) vis[static_cast<std::size_t>(i * words + (t >> 6))] |=
                    std::uint64_t(1) << (t & 63);
              }
            for (Index i = i0; i < i1; ++i) {
              int c = 0;
              for (Index w = 0; w < words; ++w) c += popcount64(bits(i)[w]);
              visible[static_cast<std::size_t>(i)] = c;
            }
          }
        },
        parallel);
  }
};

// Accumulates squared per-frame distances and keeps the m that the aggregation needs, in a
// caller-provided buffer of m scalars (no allocation per pair):
//   paper:      the m smallest, ascending;   robust_max: the m largest, descending.
template <class S>
class PairAccumulator {
 public:
  PairAccumulator(Aggregation a, int m, S* buffer) : agg_(a), m_(m), buf_(buffer) {}

  void push(S d2) {
    const bool paper = agg_ == Aggregation::paper;
    if (n_ < m_) {
      int q = n_++;
      while (q > 0 && (paper ? d2 < buf_[q - 1] : d2 > buf_[q - 1])) {
        buf_[q] = buf_[q - 1];
        --q;
      }
      buf_[q] = d2;
      return;
    }
    ++n_;
    if (paper ? !(d2 < buf_[m_ - 1]) : !(d2 > buf_[m_ - 1])) return;
    int q = m_ - 1;
    while (q > 0 && (paper ? d2 < buf_[q - 1] : d2 > buf_[q - 1])) {
      buf_[q] = buf_[q - 1];
      --q;
    }
    buf_[q] = d2;
  }

  // robust_max only: true when the result is already known to exceed sqrt(bound2) (the m-th
  // largest of a subset can only grow as frames are added).
  bool exceeds(S bound2) const {
    return agg_ == Aggregation::robust_max && n_ >= m_ && buf_[m_ - 1] > bound2;
  }

  int count() const { return n_; }

  // (G2) / (G3); +inf when nothing was pushed.
  S finish() const {
    const int c = std::min(n_, m_);
    if (c == 0) return std::numeric_limits<S>::infinity();
    if (agg_ == Aggregation::robust_max) return std::sqrt(buf_[c - 1]);
    S sum(0);
    for (int q = 0; q < c; ++q) sum += std::sqrt(buf_[q]);
    return sum / S(c);
  }

 private:
  Aggregation agg_;
  int m_;
  S* buf_;
  int n_ = 0;
};

// Number of co-visible frames |S_ij| (G1).
template <class S>
int covisible_count(const TrajectoryStore<S>& st, Index i, Index j) {
  const std::uint64_t* a = st.bits(i);
  const std::uint64_t* b = st.bits(j);
  int c = 0;
  for (Index w = 0; w < st.words; ++w) c += popcount64(a[w] & b[w]);
  return c;
}

// The trajectory distance D_ij of (G2)/(G3) from the store; +inf when the pair is not a
// candidate (|S_ij| < max(1, min_covisible)), and also when `bound2` is finite and the
// robust_max result is known to exceed sqrt(bound2) early (the caller only needs to know that
// it exceeds the bound). `buffer` holds m scalars. Frames are visited in increasing t, so every
// caller (KNN, brute force, single pair) gets bit-identical values.
template <class S>
S pair_distance(const TrajectoryStore<S>& st, Index i, Index j,
                const TrajectoryDistanceOptions& o, S* buffer,
                S bound2 = std::numeric_limits<S>::infinity()) {
  const std::uint64_t* a = st.bits(i);
  const std::uint64_t* b = st.bits(j);
  const int need = std::max(1, o.min_covisible);
  if (need > 1 && covisible_count(st, i, j) < need) return std::numeric_limits<S>::infinity();
  const S* pi = st.p(i);
  const S* pj = st.p(j);
  PairAccumulator<S> acc(o.aggregation, o.m, buffer);
  const bool can_stop = o.aggregation == Aggregation::robust_max && bound2 < std::numeric_limits<S>::infinity();
  for (Index w = 0; w < st.words; ++w) {
    std::uint64_t bits = a[w] & b[w];
    while (bits) {
      const Index t = w * 64 + count_zeros_low(bits);
      bits &= bits - 1;
      const S* u = pi + 3 * t;
      const S* q = pj + 3 * t;
      const S dx = u[0] - q[0], dy = u[1] - q[1], dz = u[2] - q[2];
      acc.push(dx * dx + dy * dy + dz * dz);
    }
    // An early exit returns +inf, which callers read as "farther than the bound".
    if (can_stop && acc.exceeds(bound2)) return std::numeric_limits<S>::infinity();
  }
  if (acc.count() < need) return std::numeric_limits<S>::infinity();
  return acc.finish();
}

}  // namespace detail

// Checks the inputs of trajectory_distance: positions [T][N][3] finite with T >= 1, optional
// visibility [T][N] of 0/1, node ids in range, m >= 1, min_covisible >= 0.
template <class S>
Status validate_trajectory_distance(PositionsView<const S> x, VisibilityView<const std::uint8_t> v,
                                    Index i, Index j, const TrajectoryDistanceOptions& o) {
  if (Status s = detail::validate_trajectories<S>(x, v); !s) return s;
  if (Status s = detail::validate_distance_options(o); !s) return s;
  if (i < 0 || i >= x.nodes() || j < 0 || j >= x.nodes()) {
    std::ostringstream s;
    s << "node ids: expected 0 <= i, j < N=" << x.nodes() << ", got i=" << i << ", j=" << j;
    return Status::error(s.str());
  }
  return Status::ok();
}

// The trajectory distance D_ij between nodes i and j, (G2) or (G3); +inf when the pair has
// fewer than max(1, min_covisible) co-visible frames. D_ii = 0 when i has enough visible
// frames. O(T) time; allocates O(T) scratch (a reference for single pairs — trajectory_knn
// evaluates many pairs without allocating per pair, with bit-identical values).
template <class S>
S trajectory_distance(PositionsView<const S> x, VisibilityView<const std::uint8_t> v, Index i,
                      Index j, const TrajectoryDistanceOptions& o = {}) {
  // A two-node store, so that the value is computed by exactly the code the KNN uses.
  const Index T = x.frames();
  std::vector<S> pos(static_cast<std::size_t>(T * 2 * 3));
  std::vector<std::uint8_t> vis(static_cast<std::size_t>(T * 2));
  for (Index t = 0; t < T; ++t) {
    for (int c = 0; c < 3; ++c) {
      pos[static_cast<std::size_t>((t * 2 + 0) * 3 + c)] = x.ptr(t, i)[c];
      pos[static_cast<std::size_t>((t * 2 + 1) * 3 + c)] = x.ptr(t, j)[c];
    }
    vis[static_cast<std::size_t>(t * 2 + 0)] = detail::visible(v, t, i) ? 1 : 0;
    vis[static_cast<std::size_t>(t * 2 + 1)] = detail::visible(v, t, j) ? 1 : 0;
  }
  detail::TrajectoryStore<S> st;
  st.build(PositionsView<const S>(pos.data(), T, 2), VisibilityView<const std::uint8_t>(vis.data(), T, 2),
           ParallelOptions{1, 0});
  std::vector<S> buffer(static_cast<std::size_t>(o.m));
  return detail::pair_distance(st, 0, 1, o, buffer.data());
}

// The same two functions for a mutable positions view (no template argument needed).
template <class View, detail::EnableMutableSequence<View, 3> = 0>
Status validate_trajectory_distance(const View& x, VisibilityView<const std::uint8_t> v, Index i,
                                    Index j, const TrajectoryDistanceOptions& o) {
  return validate_trajectory_distance<typename View::Value>(x, v, i, j, o);
}
template <class View, detail::EnableMutableSequence<View, 3> = 0>
typename View::Value trajectory_distance(const View& x, VisibilityView<const std::uint8_t> v,
                                         Index i, Index j, const TrajectoryDistanceOptions& o = {}) {
  return trajectory_distance<typename View::Value>(x, v, i, j, o);
}

}  // namespace smg
