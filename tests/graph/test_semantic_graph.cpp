// Tests of smg/graph/semantic_graph.hpp: the gate separates objects that pass close to each
// other (and does not without it), isolated-node policies, zero descriptors, the inclusive
// threshold, topology weights, statistics, aliasing, determinism, validation.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "graph/synthetic_scene.hpp"
#include "smg/graph/descriptor.hpp"
#include "smg/graph/neighbors.hpp"
#include "smg/graph/semantic_graph.hpp"
#include "support/random.hpp"

using smg::Index;

namespace {

// Two clusters of 24 nodes that cross: A moves along +x, B along -x, and they overlap in the
// middle frames. Per-frame feature samples: A ~ e0, B ~ e1 (with noise); node `odd` of A has
// samples ~ e2 instead.
struct Crossing {
  Index T = 21, N = 48, C = 4;
  std::vector<double> x, g;
  std::vector<std::uint8_t> v;
  std::vector<double> f;  // descriptors [N][C]
  int object(Index i) const { return i < 24 ? 0 : 1; }
};

Crossing crossing(bool odd_node) {
  Crossing c;
  smg::test::Rng rng(41);
  c.x.resize(static_cast<std::size_t>(c.T * c.N * 3));
  c.g.resize(static_cast<std::size_t>(c.T * c.N * c.C));
  c.v.assign(static_cast<std::size_t>(c.T * c.N), 1);
  std::vector<smg::Vector3<double>> local;
  for (Index i = 0; i < c.N; ++i) local.push_back(rng.unit3() * 0.3);
  for (Index t = 0; t < c.T; ++t) {
    const double s = -2.0 + 4.0 * static_cast<double>(t) / static_cast<double>(c.T - 1);
    for (Index i = 0; i < c.N; ++i) {
      const smg::Vector3<double> centre(c.object(i) == 0 ? s : -s, 0.0, 0.0);
      const smg::Vector3<double> p = centre + local[static_cast<std::size_t>(i)];
      for (int d = 0; d < 3; ++d) c.x[static_cast<std::size_t>((t * c.N + i) * 3 + d)] = p(d);
      const Index hot = (odd_node && i == 5) ? 2 : c.object(i);
      for (Index k = 0; k < c.C; ++k)
        c.g[static_cast<std::size_t>((t * c.N + i) * c.C + k)] = (k == hot ? 1.0 : 0.0) + 0.1 * rng.normal();
    }
  }
  c.f.resize(static_cast<std::size_t>(c.N * c.C));
  smg::DescriptorOptions o;
  smg::semantic_descriptors<double>({c.g.data(), c.T, c.N, c.C}, {c.v.data(), c.T, c.N}, o, {c.f.data(), c.N, c.C});
  return c;
}

struct Graph {
  Index N = 0, k = 0;
  std::vector<std::int32_t> idx;
  std::vector<double> w, d;
  smg::GraphStats stats;
  Index cross_edges(const Crossing& c) const {
    Index n = 0;
    for (Index i = 0; i < N; ++i)
      for (Index q = 0; q < k; ++q) {
        const std::int32_t j = idx[static_cast<std::size_t>(i * k + q)];
        if (j >= 0 && c.object(i) != c.object(j)) ++n;
      }
    return n;
  }
  Index degree(Index i) const {
    Index n = 0;
    while (n < k && idx[static_cast<std::size_t>(i * k + n)] >= 0) ++n;
    return n;
  }
};

Graph build(const Crossing& c, const smg::GraphOptions& o, const std::vector<double>* features = nullptr) {
  Graph g;
  g.N = c.N;
  g.k = o.knn.k;
  g.idx.assign(static_cast<std::size_t>(g.N * g.k), 99);
  g.w.assign(static_cast<std::size_t>(g.N * g.k), 99.0);
  g.d.assign(static_cast<std::size_t>(g.N * g.k), 99.0);
  const auto& f = features ? *features : c.f;
  const smg::FeaturesView<const double> fv = o.gate ? smg::FeaturesView<const double>(f.data(), c.N, c.C)
                                                    : smg::FeaturesView<const double>();
  REQUIRE(smg::validate_semantic_graph<double>({c.x.data(), c.T, c.N}, {c.v.data(), c.T, c.N}, fv, o,
                                               {g.idx.data(), g.N, g.k}, {g.w.data(), g.N, g.k},
                                               {g.d.data(), g.N, g.k})
              .is_ok());
  g.stats = smg::build_semantic_graph<double>({c.x.data(), c.T, c.N}, {c.v.data(), c.T, c.N}, fv, o,
                                              {g.idx.data(), g.N, g.k}, {g.w.data(), g.N, g.k},
                                              {g.d.data(), g.N, g.k});
  REQUIRE(smg::validate_neighbors(smg::NeighborsView<double>(g.idx.data(), g.w.data(), g.N, g.k), g.N).is_ok());
  return g;
}

}  // namespace

TEST_CASE("graph: objects that pass close with different features are separated only by the gate") {
  const auto c = crossing(false);
  smg::GraphOptions o;
  const auto gated = build(c, o);
  CHECK(gated.cross_edges(c) == 0);
  CHECK(gated.stats.gated);
  CHECK(gated.stats.gate_removed_edges > 0);
  CHECK(gated.stats.isolated_nodes == 0);
  o.gate = false;
  const auto plain = build(c, o);
  CHECK(plain.cross_edges(c) > 0);
  CHECK(!plain.stats.gated);
  CHECK(plain.stats.gate_removed_edges == 0);
  CHECK(plain.stats.edges == c.N * 16);
  // The gated graph is the ungated one with the cross edges removed (same order, same
  // distances), then reweighted.
  CHECK(gated.stats.edges + gated.stats.gate_removed_edges == plain.stats.edges);
  for (Index i = 0; i < c.N; ++i) {
    Index q = 0;
    for (Index p = 0; p < 16; ++p) {
      const std::int32_t j = plain.idx[static_cast<std::size_t>(i * 16 + p)];
      if (c.object(i) != c.object(j)) continue;
      CHECK(gated.idx[static_cast<std::size_t>(i * 16 + q)] == j);
      CHECK(gated.d[static_cast<std::size_t>(i * 16 + q)] == plain.d[static_cast<std::size_t>(i * 16 + p)]);
      ++q;
    }
    CHECK(gated.degree(i) == q);
  }
  // A higher threshold only removes more.
  o.gate = true;
  o.tau = 0.99;
  CHECK(build(c, o).stats.edges <= gated.stats.edges);
}

TEST_CASE("graph: isolated-node policies keep_nearest and leave") {
  const auto c = crossing(true);  // node 5 has its own feature direction
  smg::GraphOptions o;
  const auto keep = build(c, o);
  CHECK(keep.degree(5) == 1);
  CHECK(keep.w[5 * 16] == 1.0);
  CHECK(keep.stats.kept_nearest == 1);
  CHECK(keep.stats.isolated_nodes == 0);
  // Its one edge is its nearest KNN candidate.
  o.gate = false;
  const auto plain = build(c, o);
  CHECK(keep.idx[5 * 16] == plain.idx[5 * 16]);
  CHECK(keep.d[5 * 16] == plain.d[5 * 16]);
  // Nobody else keeps an edge to node 5.
  for (Index i = 0; i < c.N; ++i)
    if (i != 5)
      for (Index q = 0; q < 16; ++q) CHECK(keep.idx[static_cast<std::size_t>(i * 16 + q)] != 5);
  o.gate = true;
  o.isolated = smg::IsolatedPolicy::leave;
  const auto leave = build(c, o);
  CHECK(leave.degree(5) == 0);
  CHECK(leave.stats.kept_nearest == 0);
  CHECK(leave.stats.isolated_nodes == 1);
  for (Index q = 0; q < 16; ++q) {
    CHECK(leave.idx[static_cast<std::size_t>(5 * 16 + q)] == -1);
    CHECK(leave.w[static_cast<std::size_t>(5 * 16 + q)] == 0.0);
    CHECK(leave.d[static_cast<std::size_t>(5 * 16 + q)] == 0.0);
  }
  CHECK(leave.stats.edges == keep.stats.edges - 1);
}

TEST_CASE("graph: a zero descriptor loses its gated edges; a node without frames has no candidates") {
  auto c = crossing(false);
  auto f = c.f;
  for (Index k = 0; k < c.C; ++k) f[static_cast<std::size_t>(7 * c.C + k)] = 0.0;
  smg::GraphOptions o;
  o.isolated = smg::IsolatedPolicy::leave;
  auto g = build(c, o, &f);
  CHECK(g.degree(7) == 0);
  CHECK(g.stats.zero_feature_nodes == 1);
  for (std::int32_t j : g.idx) CHECK(j != 7);
  // A node never visible: zero descriptor from semantic_descriptors, and no KNN candidate.
  for (Index t = 0; t < c.T; ++t) c.v[static_cast<std::size_t>(t * c.N + 9)] = 0;
  smg::DescriptorOptions dopt;
  const auto ds = smg::semantic_descriptors<double>({c.g.data(), c.T, c.N, c.C}, {c.v.data(), c.T, c.N}, dopt,
                                                    {c.f.data(), c.N, c.C});
  CHECK(ds.nodes_without_visible_frame == 1);
  o.isolated = smg::IsolatedPolicy::keep_nearest;
  g = build(c, o);
  CHECK(g.degree(9) == 0);
  CHECK(g.stats.nodes_without_candidates == 1);
  CHECK(g.stats.isolated_nodes == 1);
  CHECK(g.stats.kept_nearest == 0);
}

TEST_CASE("graph: the gate is inclusive") {
  // Two nodes with unit features (1, 0, 0, 0) and (1/2, 1/2, 1/2, 1/2): cos = 1/2 exactly.
  std::vector<double> x = {0, 0, 0, 1, 0, 0};
  std::vector<double> f = {1, 0, 0, 0, 0.5, 0.5, 0.5, 0.5};
  std::vector<std::int32_t> idx(2);
  std::vector<double> w(2), d(2);
  smg::GraphOptions o;
  o.knn.k = 1;
  o.isolated = smg::IsolatedPolicy::leave;
  for (double tau : {0.5, std::nextafter(0.5, 1.0)}) {
    o.tau = tau;
    const auto st = smg::build_semantic_graph<double>({x.data(), 1, 2}, {}, {f.data(), 2, 4}, o, {idx.data(), 2, 1},
                                                      {w.data(), 2, 1}, {d.data(), 2, 1});
    CHECK(st.edges == (tau == 0.5 ? 2 : 0));
  }
}

TEST_CASE("graph: topology weights, uniform and distance-aware") {
  const auto c = crossing(false);
  smg::GraphOptions o;
  o.knn.k = 8;
  const auto u = build(c, o);
  o.weighting = smg::TopologyWeighting::distance;
  const auto g = build(c, o);
  CHECK(g.idx == u.idx);
  CHECK(g.d == u.d);
  for (Index i = 0; i < c.N; ++i) {
    const Index n = u.degree(i);
    double su = 0, sg = 0, mean = 0;
    for (Index q = 0; q < n; ++q) {
      const auto at = static_cast<std::size_t>(i * 8 + q);
      CHECK(u.w[at] == doctest::Approx(1.0 / static_cast<double>(n)));
      su += u.w[at];
      sg += g.w[at];
      mean += g.d[at] / static_cast<double>(n);
      if (q > 0) CHECK(g.w[at] <= g.w[at - 1]);  // rows are sorted by distance
    }
    CHECK(su == doctest::Approx(1.0));
    CHECK(sg == doctest::Approx(1.0));
    // (G11): w_q / w_0 = exp(-(d_q^2 - d_0^2) / (2 sigma^2)) with sigma the mean distance.
    for (Index q = 1; q < n; ++q) {
      const auto at = static_cast<std::size_t>(i * 8 + q), a0 = static_cast<std::size_t>(i * 8);
      const double want = std::exp(-(g.d[at] * g.d[at] - g.d[a0] * g.d[a0]) / (2 * mean * mean));
      CHECK(g.w[at] / g.w[a0] == doctest::Approx(want).epsilon(1e-10));
    }
  }
}

TEST_CASE("graph: gate_and_weight in place equals out of place; bit-identical for 1, 2, 7 threads") {
  smg::test::SceneOptions so;
  so.nodes = 800;
  so.frames = 24;
  so.channels = 8;
  so.seed = 3;
  const auto sc = smg::test::make_scene<double>(so);
  std::vector<double> f(static_cast<std::size_t>(sc.N * sc.C));
  smg::DescriptorOptions dopt;
  smg::semantic_descriptors<double>({sc.samples.data(), sc.T, sc.N, sc.C}, {sc.visibility.data(), sc.T, sc.N}, dopt,
                                    {f.data(), sc.N, sc.C});
  smg::GraphOptions o;
  const Index K = o.knn.k;
  auto run = [&](int threads) {
    o.knn.parallel.threads = threads;
    Graph g;
    g.N = sc.N;
    g.k = K;
    g.idx.resize(static_cast<std::size_t>(sc.N * K));
    g.w.resize(g.idx.size());
    g.d.resize(g.idx.size());
    g.stats = smg::build_semantic_graph<double>({sc.positions.data(), sc.T, sc.N}, {sc.visibility.data(), sc.T, sc.N},
                                                {f.data(), sc.N, sc.C}, o, {g.idx.data(), sc.N, K},
                                                {g.w.data(), sc.N, K}, {g.d.data(), sc.N, K});
    return g;
  };
  const Graph one = run(1);
  for (int threads : {2, 7}) {
    const Graph many = run(threads);
    CHECK(many.idx == one.idx);
    CHECK(many.w == one.w);
    CHECK(many.d == one.d);
    CHECK(many.stats.edges == one.stats.edges);
  }
  // Out of place, from the raw KNN rows.
  std::vector<std::int32_t> ki(static_cast<std::size_t>(sc.N * K)), oi(ki.size());
  std::vector<double> kd(ki.size()), ow(ki.size()), od(ki.size());
  smg::trajectory_knn<double>({sc.positions.data(), sc.T, sc.N}, {sc.visibility.data(), sc.T, sc.N}, o.knn,
                              {ki.data(), sc.N, K}, {kd.data(), sc.N, K});
  REQUIRE(smg::validate_gate_and_weight<double>({ki.data(), sc.N, K}, {kd.data(), sc.N, K}, {f.data(), sc.N, sc.C}, o,
                                                {oi.data(), sc.N, K}, {ow.data(), sc.N, K}, {od.data(), sc.N, K})
              .is_ok());
  const auto st = smg::gate_and_weight<double>({ki.data(), sc.N, K}, {kd.data(), sc.N, K}, {f.data(), sc.N, sc.C}, o,
                                               {oi.data(), sc.N, K}, {ow.data(), sc.N, K}, {od.data(), sc.N, K});
  CHECK(oi == one.idx);
  CHECK(ow == one.w);
  CHECK(od == one.d);
  CHECK(st.edges == one.stats.edges);
  CHECK(st.gate_removed_edges == one.stats.gate_removed_edges);
  // Objects with their own features: hardly any edge between objects survives the gate.
  Index cross = 0;
  for (Index i = 0; i < sc.N; ++i)
    for (Index q = 0; q < K; ++q) {
      const std::int32_t j = one.idx[static_cast<std::size_t>(i * K + q)];
      if (j >= 0 && sc.object[static_cast<std::size_t>(i)] != sc.object[static_cast<std::size_t>(j)]) ++cross;
    }
  CHECK(cross <= one.stats.kept_nearest);
}

TEST_CASE("graph: validation") {
  std::vector<double> x(2 * 3 * 3, 0.0), f(3 * 2, 1.0);
  std::vector<std::int32_t> idx(3 * 2);
  std::vector<double> w(6), d(6);
  smg::GraphOptions o;
  o.knn.k = 2;
  auto msg = [&](const smg::GraphOptions& opt, smg::FeaturesView<const double> fv) {
    return smg::validate_semantic_graph<double>({x.data(), 2, 3}, {}, fv, opt, {idx.data(), 3, 2}, {w.data(), 3, 2},
                                                {d.data(), 3, 2})
        .message();
  };
  CHECK(msg(o, {f.data(), 3, 2}).empty());
  CHECK(msg(o, {}) == "features: the semantic gate needs features [N][C] (or disable the gate)");
  auto ungated = o;
  ungated.gate = false;
  CHECK(msg(ungated, {}).empty());
  CHECK(msg(o, {f.data(), 2, 3}) == "features: expected shape [N=3][C=any], got [N=2][C=3]");
  auto bad = o;
  bad.tau = std::numeric_limits<double>::quiet_NaN();
  CHECK(msg(bad, {f.data(), 3, 2}) == "tau: must be finite");
  f[3] = std::numeric_limits<double>::quiet_NaN();
  CHECK(msg(o, {f.data(), 3, 2}) == "features: element [i=1][c=1] is NaN");
  f[3] = 1;
  CHECK(smg::validate_semantic_graph<double>({x.data(), 2, 3}, {}, {f.data(), 3, 2}, o, {idx.data(), 3, 2},
                                             {w.data(), 2, 3}, {d.data(), 3, 2})
            .message() == "weights: expected shape [N=3][K=2], got [2][3]");
  // gate_and_weight checks the KNN rows it is given.
  std::vector<std::int32_t> ki = {1, -1, 1, 0, 0, 1};
  std::vector<double> kd = {1, 0, 1, 1, 1, 1};
  auto gmsg = [&]() {
    return smg::validate_gate_and_weight<double>({ki.data(), 3, 2}, {kd.data(), 3, 2}, {f.data(), 3, 2}, o,
                                                 {idx.data(), 3, 2}, {w.data(), 3, 2}, {d.data(), 3, 2})
        .message();
  };
  CHECK(gmsg() == "knn_indices: entry [i=1][k=0] is a self edge");
  ki[2] = 2;
  ki[3] = 3;
  CHECK(gmsg() == "knn_indices: entry [i=1][k=1] is out of range: 3");
  ki[3] = 0;
  ki[1] = -1;
  ki[0] = -1;
  ki[1] = 2;
  CHECK(gmsg() == "knn_indices: entry [i=0][k=1] is a neighbour after -1 padding");
  ki[0] = 1;
  ki[1] = -1;
  kd[5] = -1;
  CHECK(gmsg() == "knn_distances: entry [i=2][k=1] is negative or not finite");
  kd[5] = 1;
  CHECK(gmsg().empty());
}
