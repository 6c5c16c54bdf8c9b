// tests/graph/reference.hpp — deliberately plain re-implementations of the graph equations
// (docs/math/graph.md), written independently of the library's kernels: collect all
// co-visible distances, sort, aggregate; all pairs for the KNN; all pairs of samples for the
// descriptor scores. Slow and simple, for small cases only. Plus scene_trajectories, the
// trajectories of a synthetic scene (synthetic_scene.hpp) for the tests that compare against them.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "graph/synthetic_scene.hpp"
#include "smg/graph/trajectory_distance.hpp"

namespace smg::test {

// Raw arrays of a case: positions [T][N][3], visibility [T][N] (empty = all visible).
template <class S>
struct Trajectories {
  Index T = 0, N = 0;
  std::vector<S> x;
  std::vector<std::uint8_t> v;

  PositionsView<const S> positions() const { return {x.data(), T, N}; }
  VisibilityView<const std::uint8_t> visibility() const {
    return v.empty() ? VisibilityView<const std::uint8_t>() : VisibilityView<const std::uint8_t>(v.data(), T, N);
  }
  S& at(Index t, Index i, int c) { return x[static_cast<std::size_t>((t * N + i) * 3 + c)]; }
  bool vis(Index t, Index i) const { return v.empty() || v[static_cast<std::size_t>(t * N + i)] != 0; }
};

// The trajectories of a synthetic scene of moving objects (synthetic_scene.hpp's defaults
// otherwise).
template <class S>
Trajectories<S> scene_trajectories(Index nodes, Index frames, std::uint64_t seed) {
  SceneOptions so;
  so.nodes = nodes;
  so.frames = frames;
  so.seed = seed;
  GraphScene<S> sc = make_scene<S>(so);
  Trajectories<S> tr;
  tr.T = sc.T;
  tr.N = sc.N;
  tr.x = std::move(sc.positions);
  tr.v = std::move(sc.visibility);
  return tr;
}

// (G1)-(G3) the plain way; +inf when the pair is not a candidate.
template <class S>
S reference_distance(const Trajectories<S>& tr, Index i, Index j, const TrajectoryDistanceOptions& o) {
  std::vector<S> d2;
  for (Index t = 0; t < tr.T; ++t) {
    if (!tr.vis(t, i) || !tr.vis(t, j)) continue;
    S s(0);
    for (int c = 0; c < 3; ++c) {
      const S e = tr.x[static_cast<std::size_t>((t * tr.N + i) * 3 + c)] - tr.x[static_cast<std::size_t>((t * tr.N + j) * 3 + c)];
      s += e * e;
    }
    d2.push_back(s);
  }
  const std::size_t need = static_cast<std::size_t>(std::max(1, o.min_covisible));
  if (d2.size() < need) return std::numeric_limits<S>::infinity();
  std::sort(d2.begin(), d2.end());
  const std::size_t c = std::min(d2.size(), static_cast<std::size_t>(o.m));
  if (o.aggregation == Aggregation::robust_max) return std::sqrt(d2[d2.size() - c]);
  S sum(0);
  for (std::size_t q = 0; q < c; ++q) sum += std::sqrt(d2[q]);
  return sum / S(c);
}

// All-pairs KNN from reference_distance: rows of (distance, id), ascending, at most k.
template <class S>
std::vector<std::vector<std::pair<S, std::int32_t>>> reference_knn(const Trajectories<S>& tr, int k,
                                                                   const TrajectoryDistanceOptions& o) {
  std::vector<std::vector<std::pair<S, std::int32_t>>> rows(static_cast<std::size_t>(tr.N));
  for (Index i = 0; i < tr.N; ++i) {
    auto& r = rows[static_cast<std::size_t>(i)];
    for (Index j = 0; j < tr.N; ++j) {
      if (j == i) continue;
      const S d = reference_distance(tr, i, j, o);
      if (d < std::numeric_limits<S>::infinity()) r.emplace_back(d, static_cast<std::int32_t>(j));
    }
    std::sort(r.begin(), r.end());
    if (r.size() > static_cast<std::size_t>(k)) r.resize(static_cast<std::size_t>(k));
  }
  return rows;
}

// Random trajectories: N nodes in a cube of side `extent` doing random walks with steps of
// size `step`, each frame visible with probability `density` (1: visibility left empty).
template <class S, class Rng>
Trajectories<S> random_trajectories(Rng& rng, Index T, Index N, double density, double extent = 1.0,
                                    double step = 0.05) {
  Trajectories<S> tr;
  tr.T = T;
  tr.N = N;
  tr.x.resize(static_cast<std::size_t>(T * N * 3));
  for (Index i = 0; i < N; ++i) {
    double p[3] = {rng.uniform(0, extent), rng.uniform(0, extent), rng.uniform(0, extent)};
    for (Index t = 0; t < T; ++t) {
      for (int c = 0; c < 3; ++c) {
        tr.at(t, i, c) = static_cast<S>(p[c]);
        p[c] += step * rng.uniform(-1, 1);
      }
    }
  }
  if (density < 1.0) {
    tr.v.resize(static_cast<std::size_t>(T * N));
    for (auto& b : tr.v) b = rng.uniform(0, 1) < density ? 1 : 0;
  }
  return tr;
}

}  // namespace smg::test
