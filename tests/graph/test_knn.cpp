// Tests of smg/graph/knn.hpp: the fast exact KNN equals brute force (bit for bit) and the plain
// reference on random scenes, with ties broken by (distance, index); small cases; padding;
// determinism across thread counts; validation.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "graph/reference.hpp"
#include "smg/graph/knn.hpp"
#include "support/random.hpp"

using smg::Aggregation;
using smg::Index;
using smg::KnnOptions;

namespace {

template <class S>
struct Rows {
  Index N = 0, k = 0;
  std::vector<std::int32_t> idx;
  std::vector<S> dist;
  smg::KnnStats stats;
  smg::TableView<std::int32_t, Eigen::Dynamic> indices() { return {idx.data(), N, k}; }
  smg::TableView<S, Eigen::Dynamic> distances() { return {dist.data(), N, k}; }
  bool operator==(const Rows& o) const { return idx == o.idx && dist == o.dist; }
};

template <class S>
Rows<S> run(const smg::test::Trajectories<S>& tr, const KnnOptions& o, bool brute = false) {
  Rows<S> r;
  r.N = tr.N;
  r.k = o.k;
  r.idx.assign(static_cast<std::size_t>(tr.N * o.k), 7);
  r.dist.assign(static_cast<std::size_t>(tr.N * o.k), S(7));
  REQUIRE(smg::validate_trajectory_knn<S>(tr.positions(), tr.visibility(), o, r.indices(), r.distances()).is_ok());
  r.stats = brute ? smg::trajectory_knn_brute_force<S>(tr.positions(), tr.visibility(), o, r.indices(), r.distances())
                  : smg::trajectory_knn<S>(tr.positions(), tr.visibility(), o, r.indices(), r.distances());
  return r;
}

// The rows agree with the independent reference (same ids; distances to rounding).
template <class S>
void check_against_reference(const smg::test::Trajectories<S>& tr, const Rows<S>& r, const KnnOptions& o) {
  const auto ref = smg::test::reference_knn(tr, o.k, o.distance);
  for (Index i = 0; i < tr.N; ++i) {
    const auto& row = ref[static_cast<std::size_t>(i)];
    for (Index q = 0; q < o.k; ++q) {
      CAPTURE(i);
      CAPTURE(q);
      const auto at = static_cast<std::size_t>(i * o.k + q);
      if (q < static_cast<Index>(row.size())) {
        CHECK(r.idx[at] == row[static_cast<std::size_t>(q)].second);
        CHECK(r.dist[at] == doctest::Approx(row[static_cast<std::size_t>(q)].first).epsilon(1e-12));
      } else {
        CHECK(r.idx[at] == -1);
        CHECK(r.dist[at] == S(0));
      }
    }
  }
}

}  // namespace

TEST_CASE("knn: a hand-checked line of nodes") {
  // Static nodes at x = 0, 1, 3, 6, 10 over 2 frames: neighbours by |x_i - x_j|, ties by index.
  smg::test::Trajectories<double> tr;
  tr.T = 2;
  tr.N = 5;
  const double xs[] = {0, 1, 3, 6, 10};
  tr.x.assign(30, 0.0);
  for (Index t = 0; t < 2; ++t)
    for (Index i = 0; i < 5; ++i) tr.at(t, i, 0) = xs[i];
  KnnOptions o;
  o.k = 2;
  const auto r = run(tr, o);
  // Node 2 (x = 3) has node 1 at 2, then nodes 0 and 3 both at 3: the tie goes to index 0.
  CHECK(r.idx == std::vector<std::int32_t>{1, 2, 0, 2, 1, 0, 2, 4, 3, 2});
  CHECK(r.dist == std::vector<double>{1, 3, 1, 2, 2, 3, 3, 4, 4, 7});
  CHECK(r.stats.neighbors == 10);
  CHECK(r.stats.nodes_without_candidates == 0);
}

TEST_CASE_TEMPLATE("knn: fast search equals brute force and the plain reference on random scenes", S, float, double) {
  SMG_TEST_RNG(rng, 21);
  for (int trial = 0; trial < 24; ++trial) {
    CAPTURE(trial);
    const Index T = std::vector<Index>{1, 2, 7, 63, 64, 65, 130}[static_cast<std::size_t>(rng.integer(0, 6))];
    const Index N = rng.integer(1, 160);
    const double density = std::vector<double>{1.0, 0.7, 0.2, 0.05}[static_cast<std::size_t>(trial % 4)];
    const double step = trial % 3 == 0 ? 0.0 : (trial % 3 == 1 ? 0.02 : 0.3);
    auto tr = smg::test::random_trajectories<S>(rng, T, N, density, 1.0, step);
    KnnOptions o;
    o.k = std::vector<int>{1, 4, 16}[static_cast<std::size_t>(trial % 3)];
    o.distance.aggregation = trial % 2 ? Aggregation::robust_max : Aggregation::paper;
    o.distance.m = std::vector<int>{3, 1, 5}[static_cast<std::size_t>((trial / 2) % 3)];
    o.distance.min_covisible = std::vector<int>{1, 0, 3}[static_cast<std::size_t>((trial / 3) % 3)];
    o.segment_frames = std::vector<int>{0, 1, 3, 1000}[static_cast<std::size_t>((trial / 4) % 4)];
    o.seed_segments = 1 + trial % 3;
    CAPTURE(T);
    CAPTURE(N);
    CAPTURE(o.k);
    const auto fast = run(tr, o);
    const auto brute = run(tr, o, true);
    CHECK(fast == brute);
    CHECK(fast.stats.neighbors == brute.stats.neighbors);
    CHECK(fast.stats.nodes_without_candidates == brute.stats.nodes_without_candidates);
    if (N <= 60) check_against_reference(tr, fast, o);
  }
}

TEST_CASE("knn: exact on a synthetic scene of moving objects, every segment length") {
  const auto tr = smg::test::scene_trajectories<double>(600, 40, 5);
  for (Aggregation a : {Aggregation::paper, Aggregation::robust_max}) {
    KnnOptions o;
    o.distance.aggregation = a;
    const auto brute = run(tr, o, true);
    for (int L : {0, 1, 2, 5, 40}) {
      o.segment_frames = L;
      CAPTURE(L);
      const auto fast = run(tr, o);
      CHECK(fast == brute);
      // Far fewer exact evaluations than all pairs, except with one segment spanning the whole
      // sequence (L = T), where every box covers a whole trajectory: exact, but no pruning.
      if (L != 40) CHECK(fast.stats.pairs_evaluated < brute.stats.pairs_evaluated / 2);
    }
  }
}

TEST_CASE("knn: exact ties are broken by index, like brute force") {
  // A static 4x4x4 lattice with unit spacing, duplicated: every node has an identical twin
  // (distance 0) and many neighbours at exactly equal distances.
  smg::test::Trajectories<double> tr;
  tr.T = 3;
  tr.N = 128;
  tr.x.assign(static_cast<std::size_t>(tr.T * tr.N * 3), 0.0);
  for (Index t = 0; t < tr.T; ++t)
    for (Index i = 0; i < tr.N; ++i) {
      const Index c = i % 64;
      tr.at(t, i, 0) = static_cast<double>(c % 4);
      tr.at(t, i, 1) = static_cast<double>((c / 4) % 4);
      const Index layer = c / 16;  // integer division intended: 4x4x4 lattice coordinates
      tr.at(t, i, 2) = static_cast<double>(layer);
    }
  for (int k : {1, 7, 16}) {
    KnnOptions o;
    o.k = k;
    const auto fast = run(tr, o);
    CHECK(fast == run(tr, o, true));
    check_against_reference(tr, fast, o);
    // The twin comes first, at distance 0.
    for (Index i = 0; i < tr.N; ++i) {
      CHECK(fast.idx[static_cast<std::size_t>(i * k)] == (i + 64) % 128);
      CHECK(fast.dist[static_cast<std::size_t>(i * k)] == 0.0);
    }
  }
}

TEST_CASE_TEMPLATE("knn: small cases (T = 1, N <= k, N = 1, N = 0) pad with -1", S, float, double) {
  SMG_TEST_RNG(rng, 22);
  for (Index N : {0, 1, 2, 5, 16, 17}) {
    auto tr = smg::test::random_trajectories<S>(rng, 1, N, 1.0);
    KnnOptions o;  // k = 16
    const auto r = run(tr, o);
    CHECK(r == run(tr, o, true));
    for (Index i = 0; i < N; ++i) {
      const Index have = std::min<Index>(N - 1, 16);
      for (Index q = 0; q < 16; ++q) {
        const auto at = static_cast<std::size_t>(i * 16 + q);
        CHECK((r.idx[at] >= 0) == (q < have));
        if (q >= have) CHECK(r.dist[at] == S(0));
      }
    }
    CHECK(r.stats.neighbors == N * std::min<Index>(N > 0 ? N - 1 : 0, 16));
    CHECK(r.stats.nodes_without_candidates == (N == 1 ? 1 : 0));
  }
}

TEST_CASE("knn: nodes without a visible frame or without co-visible partners get empty rows") {
  SMG_TEST_RNG(rng, 23);
  auto tr = smg::test::random_trajectories<double>(rng, 6, 20, 1.0);
  tr.v.assign(static_cast<std::size_t>(tr.T * tr.N), 1);
  for (Index t = 0; t < tr.T; ++t) {
    tr.v[static_cast<std::size_t>(t * tr.N + 3)] = 0;                  // node 3: never visible
    tr.v[static_cast<std::size_t>(t * tr.N + 4)] = t == 5 ? 1 : 0;     // node 4: only frame 5
    for (Index i = 0; i < tr.N; ++i)
      if (i != 4 && t == 5) tr.v[static_cast<std::size_t>(t * tr.N + i)] = 0;  // alone in frame 5
  }
  KnnOptions o;
  o.k = 4;
  const auto r = run(tr, o);
  CHECK(r == run(tr, o, true));
  for (Index q = 0; q < 4; ++q) {
    CHECK(r.idx[static_cast<std::size_t>(3 * 4 + q)] == -1);
    CHECK(r.idx[static_cast<std::size_t>(4 * 4 + q)] == -1);
  }
  CHECK(r.stats.nodes_without_candidates == 2);
  // Nobody lists 3 or 4.
  for (std::int32_t j : r.idx) CHECK((j != 3 && j != 4));
}

TEST_CASE("knn: bit-identical for 1, 2 and 7 threads") {
  const auto tr = smg::test::scene_trajectories<float>(900, 30, 9);
  KnnOptions o;
  o.parallel.threads = 1;
  const auto one = run(tr, o);
  for (int threads : {2, 7}) {
    o.parallel.threads = threads;
    const auto many = run(tr, o);
    CHECK(many == one);
    CHECK(many.stats.pairs_evaluated == one.stats.pairs_evaluated);
  }
}

TEST_CASE("knn: validation") {
  smg::test::Rng rng(24);
  auto tr = smg::test::random_trajectories<double>(rng, 4, 10, 1.0);
  KnnOptions o;
  std::vector<std::int32_t> idx(10 * 16);
  std::vector<double> dist(10 * 16);
  auto msg = [&](const KnnOptions& opt, Index rows, Index cols) {
    return smg::validate_trajectory_knn<double>(tr.positions(), tr.visibility(), opt, {idx.data(), rows, cols},
                                                {dist.data(), rows, cols})
        .message();
  };
  CHECK(msg(o, 10, 16).empty());
  KnnOptions bad = o;
  bad.k = 0;
  CHECK(msg(bad, 10, 0) == "k: must be >= 1, got 0");
  bad.k = -3;
  CHECK(msg(bad, 10, 16) == "k: must be >= 1, got -3");
  bad = o;
  bad.segment_frames = -1;
  CHECK(msg(bad, 10, 16) == "segment_frames: must be >= 0, got -1");
  bad = o;
  bad.seed_segments = 0;
  CHECK(msg(bad, 10, 16) == "seed_segments: must be >= 1, got 0");
  bad = o;
  bad.distance.m = 0;
  CHECK(msg(bad, 10, 16) == "m: must be >= 1, got 0");
  CHECK(msg(o, 10, 8) == "indices: expected shape [N=10][k=16], got [10][8]");
  CHECK(msg(o, 9, 16) == "indices: expected shape [N=10][k=16], got [9][16]");
  CHECK(smg::validate_trajectory_knn<double>(tr.positions(), tr.visibility(), o, {idx.data(), 10, 16},
                                             {dist.data(), 10, 15})
            .message() == "distances: expected shape [N=10][k=16], got [10][15]");
  tr.at(1, 2, 0) = std::numeric_limits<double>::quiet_NaN();
  CHECK(msg(o, 10, 16) == "positions: element [t=1][i=2] is NaN");
}
