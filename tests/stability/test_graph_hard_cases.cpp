// Hard cases of smg/graph with a defined behaviour (docs/math/graph.md "Hard cases"): huge and
// tiny coordinates, identical trajectories (all distances 0), extremely sparse visibility,
// min_covisible above T, fast movers under every segment length, huge and tiny feature norms.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "graph/reference.hpp"
#include "smg/graph.hpp"
#include "support/random.hpp"

using smg::Index;

namespace {

template <class S>
struct Knn {
  std::vector<std::int32_t> idx;
  std::vector<S> dist;
  bool operator==(const Knn& o) const { return idx == o.idx && dist == o.dist; }
};

template <class S>
Knn<S> knn(const smg::test::Trajectories<S>& tr, const smg::KnnOptions& o, bool brute = false) {
  Knn<S> r;
  r.idx.resize(static_cast<std::size_t>(tr.N * o.k));
  r.dist.resize(r.idx.size());
  REQUIRE(smg::validate_trajectory_knn<S>(tr.positions(), tr.visibility(), o, {r.idx.data(), tr.N, o.k},
                                          {r.dist.data(), tr.N, o.k})
              .is_ok());
  if (brute)
    smg::trajectory_knn_brute_force<S>(tr.positions(), tr.visibility(), o, {r.idx.data(), tr.N, o.k},
                                       {r.dist.data(), tr.N, o.k});
  else
    smg::trajectory_knn<S>(tr.positions(), tr.visibility(), o, {r.idx.data(), tr.N, o.k}, {r.dist.data(), tr.N, o.k});
  return r;
}

template <class S>
smg::test::Trajectories<S> scaled(const smg::test::Trajectories<double>& tr, double scale, double offset) {
  smg::test::Trajectories<S> out;
  out.T = tr.T;
  out.N = tr.N;
  out.v = tr.v;
  for (double x : tr.x) out.x.push_back(static_cast<S>(x * scale + offset));
  return out;
}

}  // namespace

TEST_CASE("graph hard cases: huge and tiny coordinates") {
  SMG_TEST_RNG(rng, 61);
  const auto base = smg::test::random_trajectories<double>(rng, 20, 80, 0.7, 1.0, 0.05);
  smg::KnnOptions o;
  o.k = 6;
  const auto ref = knn(base, o);
  // Scale invariance of the neighbour sets: exact in double for powers of two far from the
  // limits, and the fast search still equals brute force.
  for (double scale : {0x1p-400, 0x1p-100, 0x1p100, 0x1p400}) {
    CAPTURE(scale);
    const auto tr = scaled<double>(base, scale, 0.0);
    const auto r = knn(tr, o);
    CHECK(r == knn(tr, o, true));
    CHECK(r.idx == ref.idx);
  }
  // A large offset with a small spacing: rounding of the coordinates changes distances, but
  // the search stays exact with respect to them.
  const auto far = scaled<double>(base, 1e-3, 1e7);
  CHECK(knn(far, o) == knn(far, o, true));
  const auto far_f = scaled<float>(base, 1e-2, 1e3);
  CHECK(knn(far_f, o) == knn(far_f, o, true));
  // Beyond the range where the squared distance fits the type, distances overflow to +inf and
  // the pairs are not neighbours (documented); tiny ones underflow to 0 (all ties: by index).
  const auto huge = scaled<float>(base, 1e25, 0.0);
  const auto rh = knn(huge, o);
  CHECK(rh == knn(huge, o, true));
  for (std::size_t q = 0; q < rh.idx.size(); ++q)
    if (rh.idx[q] >= 0) CHECK(std::isfinite(rh.dist[q]));
  const auto tiny = scaled<double>(base, 1e-170, 0.0);
  const auto rt = knn(tiny, o);
  CHECK(rt == knn(tiny, o, true));
  for (double d : rt.dist) CHECK(d == 0.0);
}

TEST_CASE("graph hard cases: identical trajectories, sparse visibility, min_covisible above T") {
  SMG_TEST_RNG(rng, 62);
  // 40 copies of one trajectory: every distance is 0, rows are the smallest other indices.
  auto one = smg::test::random_trajectories<double>(rng, 10, 1, 1.0);
  smg::test::Trajectories<double> same;
  same.T = 10;
  same.N = 40;
  for (Index t = 0; t < 10; ++t)
    for (Index i = 0; i < 40; ++i)
      for (int c = 0; c < 3; ++c) same.x.push_back(one.at(t, 0, c));
  smg::KnnOptions o;
  o.k = 5;
  auto r = knn(same, o);
  CHECK(r == knn(same, o, true));
  for (Index i = 0; i < 40; ++i) {
    Index want = 0;
    for (Index q = 0; q < 5; ++q, ++want) {
      if (want == i) ++want;
      CHECK(r.idx[static_cast<std::size_t>(i * 5 + q)] == want);
    }
  }
  // Node selection on them: one node covers all.
  std::vector<std::int32_t> sel(40), asg(40);
  std::vector<double> err(40);
  smg::NodeSelectionOptions so;
  so.unit = 1e-12;
  const auto st = smg::select_nodes<double>(same.positions(), same.visibility(), so, {sel.data(), 40}, {asg.data(), 40},
                                            {err.data(), 40});
  CHECK(st.selected == 1);
  CHECK(st.max_error == 0.0);

  // Each node visible in exactly one random frame of 50.
  auto sparse = smg::test::random_trajectories<double>(rng, 50, 200, 1.0, 1.0, 0.1);
  sparse.v.assign(static_cast<std::size_t>(50 * 200), 0);
  for (Index i = 0; i < 200; ++i) sparse.v[static_cast<std::size_t>(rng.integer(0, 49) * 200 + i)] = 1;
  o.k = 16;
  for (int L : {0, 1, 7}) {
    o.segment_frames = L;
    CHECK(knn(sparse, o) == knn(sparse, o, true));
  }
  // min_covisible larger than T: nobody is a candidate.
  o.distance.min_covisible = 60;
  r = knn(sparse, o);
  for (std::int32_t j : r.idx) CHECK(j == -1);
}

TEST_CASE("graph hard cases: fast movers under every segment length") {
  SMG_TEST_RNG(rng, 63);
  // Steps as large as the scene: boxes of long segments cover everything; still exact.
  const auto tr = smg::test::random_trajectories<double>(rng, 33, 120, 0.8, 1.0, 1.0);
  for (smg::Aggregation a : {smg::Aggregation::paper, smg::Aggregation::robust_max})
    for (int L : {0, 1, 4, 33}) {
      smg::KnnOptions o;
      o.distance.aggregation = a;
      o.segment_frames = L;
      CAPTURE(L);
      CHECK(knn(tr, o) == knn(tr, o, true));
    }
}

TEST_CASE("graph hard cases: huge and tiny feature norms") {
  // Descriptors and the gate are invariant to the scale of the features, down to subnormal and
  // up to near-overflow magnitudes.
  const Index T = 3, N = 2, C = 3;
  const std::vector<double> base = {1, 2, 2, 1, 2, 2.1, 0.9, 2, 2, 2, -1, 0, 2, -1.1, 0, 2, -1, 0.1};
  std::vector<double> ref(static_cast<std::size_t>(N * C));
  smg::semantic_descriptors<double>({base.data(), T, N, C}, {}, {}, {ref.data(), N, C});
  for (double scale : {1e-310, 1e-200, 1e200, 1e307}) {
    CAPTURE(scale);
    std::vector<double> g;
    g.reserve(base.size());
    for (double x : base) g.push_back(x * scale);
    std::vector<double> f(static_cast<std::size_t>(N * C));
    smg::semantic_descriptors<double>({g.data(), T, N, C}, {}, {}, {f.data(), N, C});
    for (std::size_t q = 0; q < f.size(); ++q) CHECK(f[q] == doctest::Approx(ref[q]).epsilon(1e-9));
    // The gate on huge / tiny given features: cos is computed on unit vectors.
    std::vector<double> x = {0, 0, 0, 1, 0, 0};
    std::vector<double> feat = {scale, 0, 0, scale, scale * 1e-3, 0};
    std::vector<std::int32_t> idx(2);
    std::vector<double> w(2), d(2);
    smg::GraphOptions o;
    o.knn.k = 1;
    o.isolated = smg::IsolatedPolicy::leave;
    const auto st = smg::build_semantic_graph<double>({x.data(), 1, 2}, {}, {feat.data(), 2, 3}, o, {idx.data(), 2, 1},
                                                      {w.data(), 2, 1}, {d.data(), 2, 1});
    CHECK(st.edges == 2);
    CHECK(st.zero_feature_nodes == 0);
  }
}
