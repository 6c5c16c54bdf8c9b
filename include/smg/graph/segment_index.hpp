// smg/graph/segment_index.hpp — the candidate index behind the exact trajectory KNN and node
// selection (docs/math/graph.md "Exact trajectory KNN", (G5)-(G6)).
//
// Frames are cut into segments of L consecutive frames. In segment s a node that is visible in
// at least one of its frames is an axis-aligned box: the bounds of its positions over the
// frames of s where it is visible. If i and j are both visible at t in s, then
//   d_ij^t >= boxdist(B_i^s, B_j^s),                                                   (G6)
// so every pair with D_ij <= U has a segment s in which boxdist(B_i^s, B_j^s) <= U (because
// D_ij >= min_t d_ij^t, (G5)). Each segment holds a balanced bounding-volume tree over its
// boxes; range queries with a shrinking radius U enumerate a superset of the true neighbours,
// whose exact distances are then computed. L = 1 gives per-frame point trees; larger L means
// fewer queries but looser boxes when nodes move fast.
//
// Implementation detail of smg/graph (namespace smg::detail); not a stable API.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/graph/trajectory_distance.hpp"

namespace smg {
namespace detail {

template <class S>
struct Box {
  S lo[3];
  S hi[3];
};

// Squared distance between two boxes (0 when they overlap). Per-axis gaps and their squares
// are summed in x, y, z order, like the pair kernel, so for points it equals d^2 exactly.
template <class S>
inline S box_distance2(const Box<S>& a, const Box<S>& b) {
  S d2(0);
  for (int c = 0; c < 3; ++c) {
    const S g = std::max(std::max(a.lo[c] - b.hi[c], b.lo[c] - a.hi[c]), S(0));
    d2 += g * g;
  }
  return d2;
}

template <class S>
inline void box_extend(Box<S>& a, const Box<S>& b) {
  for (int c = 0; c < 3; ++c) {
    a.lo[c] = std::min(a.lo[c], b.lo[c]);
    a.hi[c] = std::max(a.hi[c], b.hi[c]);
  }
}

template <class S>
inline Box<S> empty_box() {
  Box<S> b;
  for (int c = 0; c < 3; ++c) {
    b.lo[c] = std::numeric_limits<S>::infinity();
    b.hi[c] = -std::numeric_limits<S>::infinity();
  }
  return b;
}

// The box of node i over its visible frames in [f0, f1); false if it has none.
template <class S>
inline bool segment_box(const TrajectoryStore<S>& st, Index i, Index f0, Index f1, Box<S>& out) {
  out = empty_box<S>();
  bool any = false;
  const S* p = st.p(i);
  const std::uint64_t* bits = st.bits(i);
  for (Index w = f0 >> 6; w <= (f1 - 1) >> 6; ++w) {
    std::uint64_t word = bits[w];
    const Index base = w * 64;
    if (base < f0) word &= ~std::uint64_t(0) << (f0 - base);
    if (f1 - base < 64) word &= (std::uint64_t(1) << (f1 - base)) - 1;
    while (word) {
      const Index t = base + count_zeros_low(word);
      word &= word - 1;
      for (int c = 0; c < 3; ++c) {
        out.lo[c] = std::min(out.lo[c], p[3 * t + c]);
        out.hi[c] = std::max(out.hi[c], p[3 * t + c]);
      }
      any = true;
    }
  }
  return any;
}

// Reorders perm[b, e) by recursive median splits along the widest axis of the centres, down
// to ranges of at most `leaf` items: nearby items end up nearby in perm. The split order is
// (coordinate, item), a total order, so the result does not depend on the sort's internals.
template <class S, std::size_t D>
void median_partition(std::int32_t* perm, const std::vector<std::array<S, D>>& centre, Index b,
                      Index e, Index leaf) {
  if (e - b <= leaf) return;
  constexpr int kDim = static_cast<int>(D);
  S lo[kDim], hi[kDim];
  for (int c = 0; c < kDim; ++c) {
    lo[c] = std::numeric_limits<S>::infinity();
    hi[c] = -std::numeric_limits<S>::infinity();
  }
  for (Index q = b; q < e; ++q)
    for (int c = 0; c < kDim; ++c) {
      const S v = centre[static_cast<std::size_t>(perm[q])][static_cast<std::size_t>(c)];
      lo[c] = std::min(lo[c], v);
      hi[c] = std::max(hi[c], v);
    }
  int axis = 0;
  for (int c = 1; c < kDim; ++c)
    if (hi[c] - lo[c] > hi[axis] - lo[axis]) axis = c;
  const Index mid = b + (e - b) / 2;
  const auto a = static_cast<std::size_t>(axis);
  std::nth_element(perm + b, perm + mid, perm + e, [&](std::int32_t u, std::int32_t v) {
    const S cu = centre[static_cast<std::size_t>(u)][a], cv = centre[static_cast<std::size_t>(v)][a];
    return cu < cv || (cu == cv && u < v);
  });
  median_partition(perm, centre, b, mid, leaf);
  median_partition(perm, centre, mid, e, leaf);
}

// A balanced bounding-volume tree over the boxes of one segment. The tree is implicit: node k
// covers items [b, e), its children 2k+1 and 2k+2 cover [b, b + (e-b)/2) and the rest, and a
// node with at most kLeaf items is a leaf. Items are reordered by median splits along the
// widest axis of their box centres, so the shape depends only on the item count.
template <class S>
struct SegmentTree {
  static constexpr Index kLeaf = 16;
  Index f0 = 0, f1 = 0;              // frames [f0, f1)
  std::vector<std::int32_t> ids;     // active node ids, tree order
  std::vector<Box<S>> items;         // their boxes, tree order
  std::vector<Box<S>> bounds;        // node bounds, heap order

  Index size() const { return static_cast<Index>(ids.size()); }
  std::size_t bytes() const {
    return ids.capacity() * sizeof(std::int32_t) + (items.capacity() + bounds.capacity()) * sizeof(Box<S>);
  }

  static Index capacity_for(Index n) {
    Index cap = 1, s = n;
    while (s > kLeaf) {
      s = (s + 1) / 2;
      cap = 2 * cap + 1;
    }
    return cap;
  }

  void build(const TrajectoryStore<S>& st, Index first, Index end) {
    f0 = first;
    f1 = end;
    std::vector<std::int32_t> id;
    std::vector<Box<S>> box;
    Box<S> b;
    for (Index i = 0; i < st.nodes; ++i)
      if (segment_box(st, i, f0, f1, b)) {
        id.push_back(static_cast<std::int32_t>(i));
        box.push_back(b);
      }
    const Index n = static_cast<Index>(id.size());
    std::vector<std::int32_t> perm(static_cast<std::size_t>(n));
    for (Index q = 0; q < n; ++q) perm[static_cast<std::size_t>(q)] = static_cast<std::int32_t>(q);
    std::vector<std::array<S, 3>> centre(static_cast<std::size_t>(n));
    for (Index q = 0; q < n; ++q)
      for (int c = 0; c < 3; ++c)
        centre[static_cast<std::size_t>(q)][static_cast<std::size_t>(c)] =
            box[static_cast<std::size_t>(q)].lo[c] / 2 + box[static_cast<std::size_t>(q)].hi[c] / 2;
    if (n > 0) median_partition(perm.data(), centre, 0, n, kLeaf);
    ids.resize(static_cast<std::size_t>(n));
    items.resize(static_cast<std::size_t>(n));
    for (Index q = 0; q < n; ++q) {
      ids[static_cast<std::size_t>(q)] = id[static_cast<std::size_t>(perm[static_cast<std::size_t>(q)])];
      items[static_cast<std::size_t>(q)] = box[static_cast<std::size_t>(perm[static_cast<std::size_t>(q)])];
    }
    bounds.assign(static_cast<std::size_t>(n > 0 ? capacity_for(n) : 0), empty_box<S>());
    if (n > 0) fill_bounds(0, 0, n);
  }

  // Depth-first over the nodes whose box lies within squared distance bound2() of q (re-read
  // before every test), right child pushed first; calls leaf(b, e) on each leaf's tree positions
  // [b, e) and stops, returning false, as soon as it returns false.
  template <class Bound, class Leaf>
  bool walk(const Box<S>& q, Bound&& bound2, Leaf&& leaf) const {
    if (ids.empty()) return true;
    struct Entry { Index k, b, e; };
    std::array<Entry, 128> stack;
    int top = 0;
    stack[static_cast<std::size_t>(top++)] = {0, 0, size()};
    while (top > 0) {
      const Entry en = stack[static_cast<std::size_t>(--top)];
      if (box_distance2(bounds[static_cast<std::size_t>(en.k)], q) > bound2()) continue;
      if (en.e - en.b <= kLeaf) {
        if (!leaf(en.b, en.e)) return false;
        continue;
      }
      const Index mid = en.b + (en.e - en.b) / 2;
      stack[static_cast<std::size_t>(top++)] = {2 * en.k + 2, mid, en.e};
      stack[static_cast<std::size_t>(top++)] = {2 * en.k + 1, en.b, mid};
    }
    return true;
  }

  // Calls visit(id) for every item whose box lies within squared distance bound2() of q.
  // bound2 is re-read before every test, so a caller may shrink it while visiting.
  template <class Bound, class Visit>
  void range_query(const Box<S>& q, Bound&& bound2, Visit&& visit) const {
    walk(q, bound2, [&](Index b, Index e) {
      for (Index p = b; p < e; ++p)
        if (box_distance2(items[static_cast<std::size_t>(p)], q) <= bound2())
          visit(ids[static_cast<std::size_t>(p)]);
      return true;
    });
  }

  // Appends to `out` the tree positions of the items within squared distance bound2 of q.
  // Stops early and returns false once more than `cap` items were collected.
  bool collect(const Box<S>& q, S bound2, std::size_t cap, std::vector<std::int32_t>& out) const {
    return walk(q, [bound2]() { return bound2; }, [&](Index b, Index e) {
      for (Index p = b; p < e; ++p)
        if (box_distance2(items[static_cast<std::size_t>(p)], q) <= bound2) out.push_back(static_cast<std::int32_t>(p));
      return out.size() <= cap;
    });
  }

  // The (up to) `count` items nearest to q by box distance, excluding node `exclude`, as
  // (squared box distance, id) pairs sorted ascending by (distance, id) into out[0..found).
  // Returns found.
  int nearest(const Box<S>& q, int count, std::int32_t exclude,
              std::pair<S, std::int32_t>* out) const {
    if (ids.empty() || count <= 0) return 0;
    int found = 0;
    auto worst = [&]() {
      return found < count ? std::numeric_limits<S>::infinity() : out[found - 1].first;
    };
    struct Entry { Index k, b, e; S d2; };
    std::array<Entry, 128> stack;
    int top = 0;
    stack[static_cast<std::size_t>(top++)] = {0, 0, size(), box_distance2(bounds[0], q)};
    while (top > 0) {
      const Entry en = stack[static_cast<std::size_t>(--top)];
      if (en.d2 > worst()) continue;
      if (en.e - en.b <= kLeaf) {
        for (Index p = en.b; p < en.e; ++p) {
          const std::int32_t id = ids[static_cast<std::size_t>(p)];
          if (id == exclude) continue;
          const std::pair<S, std::int32_t> c(box_distance2(items[static_cast<std::size_t>(p)], q), id);
          if (found == count && !(c < out[found - 1])) continue;
          int pos = found < count ? found++ : found - 1;
          while (pos > 0 && c < out[pos - 1]) {
            out[pos] = out[pos - 1];
            --pos;
          }
          out[pos] = c;
        }
        continue;
      }
      const Index mid = en.b + (en.e - en.b) / 2;
      const Entry l{2 * en.k + 1, en.b, mid, box_distance2(bounds[static_cast<std::size_t>(2 * en.k + 1)], q)};
      const Entry r{2 * en.k + 2, mid, en.e, box_distance2(bounds[static_cast<std::size_t>(2 * en.k + 2)], q)};
      // Nearer child on top of the stack: visited first, so the bound shrinks sooner.
      if (l.d2 <= r.d2) {
        stack[static_cast<std::size_t>(top++)] = r;
        stack[static_cast<std::size_t>(top++)] = l;
      } else {
        stack[static_cast<std::size_t>(top++)] = l;
        stack[static_cast<std::size_t>(top++)] = r;
      }
    }
    return found;
  }

 private:
  const Box<S>& fill_bounds(Index k, Index b, Index e) {
    Box<S>& out = bounds[static_cast<std::size_t>(k)];
    if (e - b <= kLeaf) {
      for (Index p = b; p < e; ++p) box_extend(out, items[static_cast<std::size_t>(p)]);
    } else {
      const Index mid = b + (e - b) / 2;
      box_extend(out, fill_bounds(2 * k + 1, b, mid));
      box_extend(out, fill_bounds(2 * k + 2, mid, e));
    }
    return out;
  }
};

// Items (boxes and node ids) copied out of a tree into six coordinate arrays, so that box
// distances to many items run as one loop the compiler can vectorise (the same arithmetic as
// box_distance2, term by term).
template <class S>
struct ItemList {
  std::array<std::vector<S>, 6> c;  // lo x, y, z, hi x, y, z
  std::vector<std::int32_t> id;

  std::size_t size() const { return id.size(); }
  std::size_t bytes() const {
    std::size_t b = id.capacity() * sizeof(std::int32_t);
    for (const auto& a : c) b += a.capacity() * sizeof(S);
    return b;
  }
  // The items of `tree` at the given tree positions.
  void assign(const SegmentTree<S>& tree, const std::vector<std::int32_t>& positions) {
    const std::size_t n = positions.size();
    for (auto& a : c) a.resize(n);
    id.resize(n);
    for (std::size_t q = 0; q < n; ++q) {
      const auto p = static_cast<std::size_t>(positions[q]);
      const Box<S>& b = tree.items[p];
      for (int a = 0; a < 3; ++a) {
        c[static_cast<std::size_t>(a)][q] = b.lo[a];
        c[3 + static_cast<std::size_t>(a)][q] = b.hi[a];
      }
      id[q] = tree.ids[p];
    }
  }
  // out[q] = box_distance2(item q, box).
  void distances2(const Box<S>& box, S* out) const {
    const S* lx = c[0].data(); const S* ly = c[1].data(); const S* lz = c[2].data();
    const S* hx = c[3].data(); const S* hy = c[4].data(); const S* hz = c[5].data();
    const std::size_t n = size();
    for (std::size_t q = 0; q < n; ++q) {
      const S gx = std::max(std::max(lx[q] - box.hi[0], box.lo[0] - hx[q]), S(0));
      const S gy = std::max(std::max(ly[q] - box.hi[1], box.lo[1] - hy[q]), S(0));
      const S gz = std::max(std::max(lz[q] - box.hi[2], box.lo[2] - hz[q]), S(0));
      out[q] = gx * gx + gy * gy + gz * gz;
    }
  }
};

// Segment trees for frames cut into segments of `frames_per_segment` (the last one may be
// shorter), built in parallel (one segment per task).
template <class S>
std::vector<SegmentTree<S>> build_segment_trees(const TrajectoryStore<S>& st, Index frames_per_segment,
                                                ParallelOptions parallel) {
  const Index L = std::max<Index>(1, frames_per_segment);
  const Index segments = (st.frames + L - 1) / L;
  std::vector<SegmentTree<S>> trees(static_cast<std::size_t>(segments));
  ParallelOptions one_each = parallel;
  one_each.grain = 1;
  parallel_for(
      segments,
      [&](Index s0, Index s1) {
        for (Index s = s0; s < s1; ++s)
          trees[static_cast<std::size_t>(s)].build(st, s * L, std::min(st.frames, (s + 1) * L));
      },
      one_each);
  return trees;
}

// Nodes in an order where consecutive nodes have nearby trajectories: median splits of their
// positions at four frames spread over the sequence (a 12-dimensional point; nodes without any
// visible frame last, by id). Nodes processed together then query the same parts of each
// segment tree. Only speed depends on this order, never the result.
template <class S>
std::vector<std::int32_t> trajectory_order(const TrajectoryStore<S>& st) {
  std::vector<std::int32_t> seen, unseen;
  constexpr std::size_t kFrames = 4;
  std::vector<std::array<S, 3 * kFrames>> key(static_cast<std::size_t>(st.nodes));
  for (Index i = 0; i < st.nodes; ++i) {
    if (st.visible[static_cast<std::size_t>(i)] == 0) {
      unseen.push_back(static_cast<std::int32_t>(i));
      continue;
    }
    const S* p = st.p(i);
    for (std::size_t f = 0; f < kFrames; ++f) {
      const Index t = static_cast<Index>((2 * f + 1) * static_cast<std::size_t>(st.frames) / (2 * kFrames));
      for (std::size_t c = 0; c < 3; ++c) key[static_cast<std::size_t>(i)][3 * f + c] = p[3 * t + static_cast<Index>(c)];
    }
    seen.push_back(static_cast<std::int32_t>(i));
  }
  if (!seen.empty()) median_partition(seen.data(), key, 0, static_cast<Index>(seen.size()), 1);
  seen.insert(seen.end(), unseen.begin(), unseen.end());
  return seen;
}

// A set of node ids (open addressing, linear probing); reused across nodes so that no
// allocation happens per pair (capacity doubles when half full).
class IdSet {
 public:
  void clear() {
    if (used_ > 0) std::fill(slots_.begin(), slots_.end(), -1);
    used_ = 0;
  }
  // True when id was not in the set (and is now).
  bool insert(std::int32_t id) {
    if (2 * (used_ + 1) > slots_.size()) grow();
    const std::size_t mask = slots_.size() - 1;
    std::size_t h = (static_cast<std::uint32_t>(id) * 2654435761u) & mask;
    while (slots_[h] != -1) {
      if (slots_[h] == id) return false;
      h = (h + 1) & mask;
    }
    slots_[h] = id;
    ++used_;
    return true;
  }
  std::size_t bytes() const { return slots_.capacity() * sizeof(std::int32_t); }

 private:
  void grow() {
    std::vector<std::int32_t> old;
    old.swap(slots_);
    slots_.assign(std::max<std::size_t>(64, 2 * old.size()), -1);
    used_ = 0;
    for (std::int32_t id : old)
      if (id != -1) insert(id);
  }
  std::vector<std::int32_t> slots_;
  std::size_t used_ = 0;
};

// Squared bound with a relative margin of 64 ulp (and the smallest normal added), so that
// rounding in the aggregation (a mean of m values can round a few ulp below its smallest term)
// or a different contraction of the same expression never drops a true candidate. Widening the
// query only adds candidates whose exact distance is then computed.
template <class S>
inline S widen2(S d) {
  if (!(d < std::numeric_limits<S>::infinity())) return std::numeric_limits<S>::infinity();
  return d * d * (S(1) + S(64) * std::numeric_limits<S>::epsilon()) + std::numeric_limits<S>::min();
}

}  // namespace detail
}  // namespace smg
