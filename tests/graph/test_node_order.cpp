// Tests of smg/graph/node_order.hpp: the spatial order is a valid permutation with its inverse,
// it brings graph neighbours closer in memory, arrays and the graph survive a reorder round trip,
// and C-ARAP and LRM (energies and gradients) do not depend on the node order beyond round-off.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <numeric>
#include <vector>

#include "energy/scene.hpp"
#include "smg/energy.hpp"
#include "smg/graph/node_order.hpp"
#include "support/random.hpp"

using smg::Index;

namespace {

// Mean |i - j| over the graph's edges: how far apart neighbours are stored.
double mean_edge_span(const std::vector<std::int32_t>& idx, Index N, Index K) {
  double sum = 0;
  Index edges = 0;
  for (Index i = 0; i < N; ++i)
    for (Index k = 0; k < K; ++k) {
      const std::int32_t j = idx[static_cast<std::size_t>(i * K + k)];
      if (j < 0) continue;
      sum += std::abs(static_cast<double>(j - i));
      ++edges;
    }
  return sum / static_cast<double>(std::max<Index>(1, edges));
}

// The scene moved into `order` (every per-node array and the graph).
smg::test::Scene<double> reordered(const smg::test::Scene<double>& s, const smg::NodeOrder& order) {
  smg::test::Scene<double> r = s;
  REQUIRE(smg::reorder_nodes(order, s.positions(), smg::PositionsView<double>(r.x.data(), s.T, s.N)));
  REQUIRE(smg::reorder_nodes(order, s.rotations(), smg::QuaternionsView<double>(r.q.data(), s.T, s.N)));
  REQUIRE(smg::reorder_nodes(order, s.visibility(), smg::VisibilityView<std::uint8_t>(r.v.data(), s.T, s.N)));
  REQUIRE(smg::reorder_nodes(order, s.confidence(), smg::FrameScalarsView<double>(r.c.data(), s.T, s.N)));
  REQUIRE(smg::reorder_graph(order, s.graph(), {r.idx.data(), s.N, s.K}, {r.w.data(), s.N, s.K}));
  return r;
}

double rel(const std::vector<double>& a, const std::vector<double>& b) {
  double num = 0, den = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    num += (a[k] - b[k]) * (a[k] - b[k]);
    den += b[k] * b[k];
  }
  return std::sqrt(num / std::max(den, 1e-300));
}

}  // namespace

TEST_CASE("spatial_node_order: a permutation with its inverse, neighbours closer in memory") {
  smg::test::Rng rng(3);
  smg::test::Scene<double> s = smg::test::random_scene(6, 400, 8, rng, /*knn=*/true);
  // Shuffle the nodes first, so the input order has no locality at all.
  std::vector<Index> shuffle(static_cast<std::size_t>(s.N));
  std::iota(shuffle.begin(), shuffle.end(), Index(0));
  std::shuffle(shuffle.begin(), shuffle.end(), rng.engine);
  s = reordered(s, smg::NodeOrder::from_new_to_old(shuffle));

  const smg::NodeOrder order = smg::spatial_node_order(s.positions(), s.visibility());
  REQUIRE(smg::validate_node_order(order, s.N));
  for (Index i = 0; i < s.N; ++i) {
    CHECK(order.new_to_old[static_cast<std::size_t>(order.old_to_new[static_cast<std::size_t>(i)])] == i);
  }
  // Deterministic, and a mutable view gives the same order as a const one.
  const smg::NodeOrder again = smg::spatial_node_order(smg::PositionsView<double>(s.x.data(), s.T, s.N));
  CHECK(smg::validate_node_order(again, s.N));
  CHECK(smg::spatial_node_order(s.positions()).new_to_old == again.new_to_old);

  const smg::test::Scene<double> r = reordered(s, order);
  CHECK(smg::validate_neighbors(r.graph(), r.N));
  CHECK(mean_edge_span(r.idx, r.N, r.K) < 0.5 * mean_edge_span(s.idx, s.N, s.K));

  CHECK_FALSE(smg::validate_node_order(smg::NodeOrder::from_new_to_old({0, 0, 1}), 3));
  CHECK_FALSE(smg::validate_node_order(order, s.N + 1));
  CHECK(smg::validate_node_order(smg::NodeOrder::identity(5), 5));
}

TEST_CASE("reorder_nodes and reorder_graph: the round trip restores every array") {
  smg::test::Rng rng(5);
  const smg::test::Scene<double> s = smg::test::random_scene(4, 120, 6, rng);  // padded rows
  const smg::NodeOrder order = smg::spatial_node_order(s.positions());
  const smg::test::Scene<double> back = reordered(reordered(s, order), order.inverse());
  CHECK(back.x == s.x);
  CHECK(back.q == s.q);
  CHECK(back.v == s.v);
  CHECK(back.c == s.c);
  CHECK(back.idx == s.idx);
  CHECK(back.w == s.w);
  // Per-node tables.
  std::vector<float> f(static_cast<std::size_t>(s.N * 2)), g(f.size()), h(f.size());
  std::iota(f.begin(), f.end(), 0.0f);
  REQUIRE(smg::reorder_nodes(order, smg::TableView<const float, 2>(f.data(), s.N),
                             smg::TableView<float, 2>(g.data(), s.N)));
  REQUIRE(smg::reorder_nodes(order.inverse(), smg::TableView<float, 2>(g.data(), s.N),
                             smg::TableView<float, 2>(h.data(), s.N)));
  CHECK(h == f);
  // Wrong shapes and in-place calls are refused.
  std::vector<double> small(static_cast<std::size_t>(s.T * (s.N - 1) * 3));
  CHECK_FALSE(smg::reorder_nodes(order, s.positions(), smg::PositionsView<double>(small.data(), s.T, s.N - 1)));
  std::vector<double> x = s.x;
  CHECK_FALSE(smg::reorder_nodes(order, smg::PositionsView<double>(x.data(), s.T, s.N),
                                 smg::PositionsView<double>(x.data(), s.T, s.N)));
}

TEST_CASE("C-ARAP and LRM do not depend on the node order (energies and restored gradients)") {
  smg::test::Rng rng(9);
  const smg::test::Scene<double> s = smg::test::random_scene(7, 300, 8, rng, /*knn=*/true);
  const smg::NodeOrder order = smg::spatial_node_order(s.positions(), s.visibility());
  const smg::test::Scene<double> r = reordered(s, order);
  const std::size_t n = s.x.size();

  std::vector<double> gx(n, 0.0), gr(n, 0.0), hx(n, 0.0), hr(n, 0.0), bx(n), br(n);
  const double e0 = smg::carap<double>(s.positions(), s.rotations(), s.confidence(), s.graph(), {},
                                       {gx.data(), s.T, s.N}, {gr.data(), s.T, s.N});
  const double e1 = smg::carap<double>(r.positions(), r.rotations(), r.confidence(), r.graph(), {},
                                       {hx.data(), r.T, r.N}, {hr.data(), r.T, r.N});
  CHECK(e1 == doctest::Approx(e0).epsilon(1e-12));
  REQUIRE(smg::reorder_nodes(order.inverse(), smg::PositionsView<const double>(hx.data(), s.T, s.N),
                             smg::PositionsView<double>(bx.data(), s.T, s.N)));
  REQUIRE(smg::reorder_nodes(order.inverse(), smg::TangentsView<const double>(hr.data(), s.T, s.N),
                             smg::TangentsView<double>(br.data(), s.T, s.N)));
  CHECK(rel(bx, gx) < 1e-12);
  CHECK(rel(br, gr) < 1e-12);

  std::fill(gx.begin(), gx.end(), 0.0);
  std::fill(hx.begin(), hx.end(), 0.0);
  const double l0 = smg::lrm<double>(s.positions(), s.confidence(), s.graph(), {}, {gx.data(), s.T, s.N});
  const double l1 = smg::lrm<double>(r.positions(), r.confidence(), r.graph(), {}, {hx.data(), r.T, r.N});
  CHECK(l1 == doctest::Approx(l0).epsilon(1e-12));
  REQUIRE(smg::reorder_nodes(order.inverse(), smg::PositionsView<const double>(hx.data(), s.T, s.N),
                             smg::PositionsView<double>(bx.data(), s.T, s.N)));
  CHECK(rel(bx, gx) < 1e-12);
}
