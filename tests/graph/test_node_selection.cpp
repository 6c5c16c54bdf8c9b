// Tests of smg/graph/node_selection.hpp: coverage within the unit, separation of the chosen
// nodes, nearest assignment, preference for long-visible trajectories, node count against the
// unit, eligibility, determinism, validation. Checked against all-pairs trajectory distances.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "graph/reference.hpp"
#include "smg/graph/node_selection.hpp"
#include "support/random.hpp"

using smg::Index;

namespace {

template <class S>
struct Selection {
  std::vector<std::int32_t> selected, assignment;
  std::vector<S> error;
  smg::NodeSelectionStats<S> stats;
};

template <class S>
Selection<S> select(const smg::test::Trajectories<S>& tr, const smg::NodeSelectionOptions& o) {
  Selection<S> r;
  r.selected.assign(static_cast<std::size_t>(tr.N), 5);
  r.assignment.assign(static_cast<std::size_t>(tr.N), 5);
  r.error.assign(static_cast<std::size_t>(tr.N), S(5));
  REQUIRE(smg::validate_node_selection<S>(tr.positions(), tr.visibility(), o, {r.selected.data(), tr.N},
                                          {r.assignment.data(), tr.N}, {r.error.data(), tr.N})
              .is_ok());
  r.stats = smg::select_nodes<S>(tr.positions(), tr.visibility(), o, {r.selected.data(), tr.N},
                                 {r.assignment.data(), tr.N}, {r.error.data(), tr.N});
  return r;
}

template <class S>
Index visible_count(const smg::test::Trajectories<S>& tr, Index i) {
  Index n = 0;
  for (Index t = 0; t < tr.T; ++t) n += tr.vis(t, i) ? 1 : 0;
  return n;
}

}  // namespace

TEST_CASE_TEMPLATE("node selection: coverage, separation, nearest assignment, preference", S, float, double) {
  SMG_TEST_RNG(rng, 51);
  for (int trial = 0; trial < 6; ++trial) {
    CAPTURE(trial);
    auto tr = smg::test::random_trajectories<S>(rng, rng.integer(1, 40), 150, trial % 2 ? 0.5 : 1.0, 1.0, 0.02);
    smg::NodeSelectionOptions o;
    o.unit = std::vector<double>{0.05, 0.15, 0.4}[static_cast<std::size_t>(trial % 3)];
    o.distance.aggregation = trial % 2 ? smg::Aggregation::robust_max : smg::Aggregation::paper;
    o.segment_frames = trial % 3;
    const auto r = select(tr, o);
    const Index count = r.stats.selected;
    CHECK(count >= 1);
    std::vector<char> chosen(static_cast<std::size_t>(tr.N), 0);
    for (Index q = 0; q < tr.N; ++q) {
      const std::int32_t c = r.selected[static_cast<std::size_t>(q)];
      CHECK((c >= 0) == (q < count));
      if (c >= 0) chosen[static_cast<std::size_t>(c)] = 1;
    }
    // Preference: visible counts never increase along the selection order.
    for (Index q = 1; q < count; ++q)
      CHECK(visible_count(tr, r.selected[static_cast<std::size_t>(q)]) <=
            visible_count(tr, r.selected[static_cast<std::size_t>(q - 1)]));
    double max_err = 0, sum_err = 0;
    Index eligible = 0;
    for (Index j = 0; j < tr.N; ++j) {
      CAPTURE(j);
      const std::int32_t a = r.assignment[static_cast<std::size_t>(j)];
      if (visible_count(tr, j) == 0) {
        CHECK(a == -1);
        CHECK(r.error[static_cast<std::size_t>(j)] == S(0));
        continue;
      }
      ++eligible;
      REQUIRE(a >= 0);
      CHECK(chosen[static_cast<std::size_t>(a)]);
      const S d = smg::test::reference_distance(tr, a, j, o.distance);
      CHECK(d <= static_cast<S>(o.unit) * S(1 + 1e-5));  // coverage
      CHECK(r.error[static_cast<std::size_t>(j)] == doctest::Approx(d).epsilon(1e-5));
      if (chosen[static_cast<std::size_t>(j)]) CHECK(a == j);
      // Nearest: no chosen node is (clearly) closer.
      for (Index c = 0; c < tr.N; ++c)
        if (chosen[static_cast<std::size_t>(c)] && c != a && !chosen[static_cast<std::size_t>(j)])
          CHECK(!(smg::test::reference_distance(tr, c, j, o.distance) < d * (1 - 1e-5)));
      max_err = std::max(max_err, static_cast<double>(r.error[static_cast<std::size_t>(j)]));
      sum_err += static_cast<double>(r.error[static_cast<std::size_t>(j)]);
    }
    // Separation: chosen nodes are pairwise farther apart than the unit.
    for (Index p = 0; p < count; ++p)
      for (Index q = p + 1; q < count; ++q)
        CHECK(smg::test::reference_distance(tr, r.selected[static_cast<std::size_t>(p)],
                                            r.selected[static_cast<std::size_t>(q)], o.distance) >
              static_cast<S>(o.unit) * S(1 - 1e-5));
    CHECK(r.stats.eligible == eligible);
    CHECK(static_cast<double>(r.stats.max_error) == doctest::Approx(max_err));
    CHECK(static_cast<double>(r.stats.mean_error) == doctest::Approx(sum_err / static_cast<double>(eligible)).epsilon(1e-5));
  }
}

TEST_CASE("node selection: the node count adapts to the unit") {
  const auto tr = smg::test::scene_trajectories<double>(1500, 30, 7);
  Index previous = tr.N + 1;
  for (double unit : {0.01, 0.05, 0.1, 0.2, 0.4, 100.0}) {
    smg::NodeSelectionOptions o;
    o.unit = unit;
    const auto r = select(tr, o);
    CAPTURE(unit);
    CHECK(r.stats.selected < previous);
    CHECK(r.stats.max_error <= unit);
    previous = r.stats.selected;
  }
  // A unit larger than the scene: one node per group of mutually co-visible trajectories,
  // here a handful (visibility windows overlap).
  CHECK(previous <= 3);
}

TEST_CASE("node selection: identical trajectories, eligibility, tiny unit") {
  smg::test::Trajectories<double> tr;
  tr.T = 4;
  tr.N = 6;
  tr.x.assign(static_cast<std::size_t>(4 * 6 * 3), 0.0);
  for (Index t = 0; t < 4; ++t)
    for (Index i = 0; i < 6; ++i) tr.at(t, i, 0) = i < 3 ? 0.0 : 10.0 + static_cast<double>(i);
  tr.v.assign(24, 1);
  for (Index t = 0; t < 4; ++t) tr.v[static_cast<std::size_t>(t * 6 + 5)] = 0;  // node 5: never visible
  tr.v[0 * 6 + 0] = 0;  // node 0: 3 visible frames; nodes 1, 2: 4 (preferred)
  smg::NodeSelectionOptions o;
  o.unit = 1e-9;
  auto r = select(tr, o);
  // Nodes 0, 1, 2 coincide: node 1 (longest visible, smallest index) covers 0 and 2 at
  // distance 0; nodes 3 and 4 are 1 apart: both chosen; node 5 is not eligible.
  CHECK(r.stats.selected == 3);
  CHECK(r.selected == std::vector<std::int32_t>{1, 3, 4, -1, -1, -1});
  CHECK(r.assignment == std::vector<std::int32_t>{1, 1, 1, 3, 4, -1});
  CHECK(r.stats.eligible == 5);
  CHECK(r.stats.max_error == 0.0);
  // min_visible = 4 excludes node 0 as well.
  o.min_visible = 4;
  r = select(tr, o);
  CHECK(r.assignment == std::vector<std::int32_t>{-1, 1, 1, 3, 4, -1});
  CHECK(r.stats.eligible == 4);
}

TEST_CASE("node selection: bit-identical for 1, 2 and 7 threads") {
  const auto tr = smg::test::scene_trajectories<float>(1200, 25, 8);
  smg::NodeSelectionOptions o;
  o.unit = 0.1;
  o.parallel.threads = 1;
  const auto one = select(tr, o);
  for (int threads : {2, 7}) {
    o.parallel.threads = threads;
    const auto many = select(tr, o);
    CHECK(many.selected == one.selected);
    CHECK(many.assignment == one.assignment);
    CHECK(many.error == one.error);
  }
}

TEST_CASE("node selection: validation") {
  smg::test::Rng rng(52);
  auto tr = smg::test::random_trajectories<double>(rng, 3, 5, 1.0);
  std::vector<std::int32_t> sel(5), asg(5);
  std::vector<double> err(5);
  auto msg = [&](const smg::NodeSelectionOptions& o, Index n) {
    return smg::validate_node_selection<double>(tr.positions(), tr.visibility(), o, {sel.data(), n}, {asg.data(), 5},
                                                {err.data(), 5})
        .message();
  };
  smg::NodeSelectionOptions o;
  o.unit = 0.1;
  CHECK(msg(o, 5).empty());
  CHECK(msg(o, 4) == "selected: expected 5 entries (N), got 4");
  auto bad = o;
  bad.unit = 0;
  CHECK(msg(bad, 5) == "unit: must be finite and > 0, got 0");
  bad.unit = std::numeric_limits<double>::infinity();
  CHECK(msg(bad, 5) == "unit: must be finite and > 0, got inf");
  bad = o;
  bad.min_visible = -1;
  CHECK(msg(bad, 5) == "min_visible: must be >= 0, got -1");
  bad = o;
  bad.distance.m = 0;
  CHECK(msg(bad, 5) == "m: must be >= 1, got 0");
}
