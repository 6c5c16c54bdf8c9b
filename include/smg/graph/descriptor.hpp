// smg/graph/descriptor.hpp — semantic node descriptors by top-rho cosine-consistent averaging
// of per-frame feature samples (docs/design.md "Descriptor"; docs/math/graph.md (G7)-(G8)).
//
// For node i with visible frames t_1 < ... < t_n and samples g^t (feature_samples [T][N][C]):
//   u^t = g^t / |g^t|  (a zero sample stays zero)
//   s^t = (1 / (n-1)) sum_{t' != t} u^t . u^t'    (0 when n = 1)            score  (G7)
//   keep the max(1, floor(rho n)) samples with the largest score (ties: earlier frame)
//   f_i = normalize(sum of the kept u^t)   (zero when that sum is zero)             (G8)
// A node with no visible frame gets the zero descriptor; cos(0, f) = 0 in the gate, so such a
// node loses its gated edges. Norms are overflow- and underflow-safe (any finite sample). Scores are computed as (u^t . sum_t' u^t' - |u^t|^2) / (n - 1),
// O(n C) per node instead of O(n^2 C); they equal the pairwise mean up to rounding. Ties go to
// the earlier frame when the computed scores are equal: always for two samples (both get
// u^1 . u^2), and for duplicate samples; scores equal only in exact arithmetic (symmetric
// configurations of three or more samples) are ordered by their rounding.
#pragma once

#include "smg/core/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/core/validate.hpp"
#include "smg/core/views.hpp"
#include "smg/graph/trajectory_distance.hpp"

namespace smg {

namespace detail {
// |g| without overflow or underflow for any finite g: the plain sqrt of the squared norm where
// that is exact enough, Eigen's scaled stableNorm where the square would leave the normal range.
template <class Derived>
typename Derived::Scalar safe_norm(const Eigen::MatrixBase<Derived>& g) {
  using S = typename Derived::Scalar;
  const S sq = g.squaredNorm();
  if (sq >= std::numeric_limits<S>::min() && sq <= std::numeric_limits<S>::max()) return std::sqrt(sq);
  return g.stableNorm();
}
}  // namespace detail

struct DescriptorOptions {
  double rho = 0.5;  // fraction of the most consistent samples kept, in (0, 1]
  ParallelOptions parallel{};
};

struct DescriptorStats {
  Index nodes_without_visible_frame = 0;  // zero descriptor because nothing was observed
  Index zero_descriptors = 0;             // all zero descriptors (including the above)
};

// Checks feature samples [T][N][C] (finite, C >= 1), visibility [T][N] of 0/1 or empty (all
// visible), rho in (0, 1], and the output [N][C].
template <class S>
Status validate_semantic_descriptors(detail::NonDeducedT<FeatureSamplesView<const S>> samples,
                                     VisibilityView<const std::uint8_t> v,
                                     const DescriptorOptions& o, FeaturesView<S> out) {
  if (!(o.rho > 0.0 && o.rho <= 1.0)) {
    std::ostringstream s;
    s << "rho: must be in (0, 1], got " << o.rho;
    return Status::error(s.str());
  }
  if (Status s = validate_feature_samples<S>(samples, -1, -1); !s) return s;
  if (!detail::visibility_absent(v))
    if (Status s = validate_visibility<std::uint8_t>(v, samples.frames(), samples.nodes()); !s) return s;
  if (out.rows() != samples.nodes() || out.cols() != samples.dim()) {
    std::ostringstream s;
    s << "descriptors: expected shape [N=" << samples.nodes() << "][C=" << samples.dim() << "], got ["
      << out.rows() << "][" << out.cols() << "]";
    return Status::error(s.str());
  }
  if (out.data() == nullptr && out.size() > 0)
    return Status::error("descriptors: null data pointer for a non-empty array");
  return Status::ok();
}

// Writes the descriptor of every node into out [N][C], (G7)-(G8): unit vectors, or zero.
// Deterministic and bit-identical for any thread count; scratch O(T * C) per task.
template <class S>
DescriptorStats semantic_descriptors(detail::NonDeducedT<FeatureSamplesView<const S>> samples,
                                     VisibilityView<const std::uint8_t> v,
                                     const DescriptorOptions& o, FeaturesView<S> out) {
  const Index T = samples.frames(), N = samples.nodes(), C = samples.dim();
  const Index chunks = parallel_chunk_count(N, o.parallel.grain);
  std::vector<Index> unseen(static_cast<std::size_t>(chunks), 0), zero(static_cast<std::size_t>(chunks), 0);
  parallel_for_chunks(
      N,
      [&](Index chunk, Index begin, Index end) {
        std::vector<Index> frames;
        std::vector<S> score;
        Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> U(C, T);  // unit samples, one per column
        std::vector<Index> rank;
        Eigen::Matrix<S, Eigen::Dynamic, 1> sum(C), avg(C);
        frames.reserve(static_cast<std::size_t>(T));
        for (Index i = begin; i < end; ++i) {
          frames.clear();
          for (Index t = 0; t < T; ++t)
            if (detail::visible(v, t, i)) frames.push_back(t);
          const Index n = static_cast<Index>(frames.size());
          auto f = out.row(i);
          if (n == 0) {
            f.setZero();
            ++unseen[static_cast<std::size_t>(chunk)];
            ++zero[static_cast<std::size_t>(chunk)];
            continue;
          }
          score.resize(static_cast<std::size_t>(n));
          sum.setZero();
          // u = g / |g| (zero stays zero); dividing by a safe norm keeps tiny and huge samples.
          auto unit = [&](Index a) { return U.col(a); };
          for (Index a = 0; a < n; ++a) {
            const auto g = samples(frames[static_cast<std::size_t>(a)], i);
            const S norm = detail::safe_norm(g);
            if (norm > S(0)) {
              U.col(a) = g / norm;
            } else {
              U.col(a).setZero();
            }
            sum += unit(a);
          }
          // (G7): mean cosine to the other samples, through the sum of unit samples. With two
          // samples the scores are equal in exact arithmetic: give both the same value, so
          // that the tie goes to the earlier frame as pinned.
          if (n == 2) {
            score[0] = score[1] = unit(0).dot(unit(1));
          } else {
            for (Index a = 0; a < n; ++a)
              score[static_cast<std::size_t>(a)] = n > 1 ? (unit(a).dot(sum) - unit(a).squaredNorm()) / S(n - 1) : S(0);
          }
          // floor(rho n), with a tolerance so that e.g. rho = 0.29, n = 100 keeps 29.
          const Index keep = std::max<Index>(
              1, std::min<Index>(n, static_cast<Index>(std::floor(o.rho * static_cast<double>(n) + 1e-9))));
          rank.resize(static_cast<std::size_t>(n));
          std::iota(rank.begin(), rank.end(), Index(0));
          std::partial_sort(rank.begin(), rank.begin() + keep, rank.end(), [&](Index a, Index b) {
            const S sa = score[static_cast<std::size_t>(a)], sb = score[static_cast<std::size_t>(b)];
            return sa > sb || (sa == sb && a < b);  // a < b: earlier frame
          });
          // (G8): average of the kept unit samples, summed in frame order, then normalised.
          std::sort(rank.begin(), rank.begin() + keep);
          avg.setZero();
          for (Index q = 0; q < keep; ++q) {
            const Index a = rank[static_cast<std::size_t>(q)];
            avg += unit(a);
          }
          const S norm = detail::safe_norm(avg);
          if (norm > S(0)) {
            f = avg / norm;
          } else {
            f.setZero();
            ++zero[static_cast<std::size_t>(chunk)];
          }
        }
      },
      o.parallel);
  DescriptorStats stats;
  for (Index c = 0; c < chunks; ++c) {
    stats.nodes_without_visible_frame += unseen[static_cast<std::size_t>(c)];
    stats.zero_descriptors += zero[static_cast<std::size_t>(c)];
  }
  return stats;
}

}  // namespace smg
