// Tests of smg/graph/trajectory_distance.hpp: (G1)-(G3) by hand, against the plain reference,
// symmetry and invariances, candidates (min_covisible, never co-visible), validation.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "graph/reference.hpp"
#include "smg/graph/trajectory_distance.hpp"
#include "support/random.hpp"

using smg::Aggregation;
using smg::Index;
using smg::TrajectoryDistanceOptions;

namespace {

// Two nodes on the x axis: node 0 at the origin, node 1 at x = gap[t] in frame t.
template <class S>
smg::test::Trajectories<S> pair_case(const std::vector<double>& gap, const std::vector<std::uint8_t>& vis1) {
  smg::test::Trajectories<S> tr;
  tr.T = static_cast<Index>(gap.size());
  tr.N = 2;
  tr.x.assign(static_cast<std::size_t>(tr.T * 6), S(0));
  for (Index t = 0; t < tr.T; ++t) tr.at(t, 1, 0) = static_cast<S>(gap[static_cast<std::size_t>(t)]);
  if (!vis1.empty()) {
    tr.v.assign(static_cast<std::size_t>(tr.T * 2), 1);
    for (Index t = 0; t < tr.T; ++t) tr.v[static_cast<std::size_t>(t * 2 + 1)] = vis1[static_cast<std::size_t>(t)];
  }
  return tr;
}

template <class S>
S dist(const smg::test::Trajectories<S>& tr, Aggregation a, int m, int min_cov = 1) {
  TrajectoryDistanceOptions o;
  o.aggregation = a;
  o.m = m;
  o.min_covisible = min_cov;
  REQUIRE(smg::validate_trajectory_distance<S>(tr.positions(), tr.visibility(), 0, 1, o).is_ok());
  return smg::trajectory_distance<S>(tr.positions(), tr.visibility(), 0, 1, o);
}

}  // namespace

TEST_CASE_TEMPLATE("trajectory distance: hand-computed values for both aggregations", S, float, double) {
  // d^t = 5, 1, 4, 2, 3 (not sorted, so the aggregation has to select).
  const auto all = pair_case<S>({5, 1, 4, 2, 3}, {});
  CHECK(dist(all, Aggregation::paper, 3) == doctest::Approx(2.0));       // mean(1, 2, 3)
  CHECK(dist(all, Aggregation::robust_max, 3) == doctest::Approx(3.0));  // 5, 4, [3]
  CHECK(dist(all, Aggregation::paper, 1) == doctest::Approx(1.0));       // min
  CHECK(dist(all, Aggregation::robust_max, 1) == doctest::Approx(5.0));  // max
  CHECK(dist(all, Aggregation::paper, 5) == doctest::Approx(3.0));       // mean of all
  CHECK(dist(all, Aggregation::robust_max, 5) == doctest::Approx(1.0));  // 5th largest = min
  CHECK(dist(all, Aggregation::paper, 9) == doctest::Approx(3.0));       // m > |S|: all of them
  CHECK(dist(all, Aggregation::robust_max, 9) == doctest::Approx(1.0));  // min(m, |S|)-th largest

  // Node 1 invisible in frames 1 and 3: S = {0, 2, 4}, d = 5, 4, 3.
  const auto some = pair_case<S>({5, 1, 4, 2, 3}, {1, 0, 1, 0, 1});
  CHECK(dist(some, Aggregation::paper, 3) == doctest::Approx(4.0));
  CHECK(dist(some, Aggregation::robust_max, 3) == doctest::Approx(3.0));
  CHECK(dist(some, Aggregation::paper, 2) == doctest::Approx(3.5));
  CHECK(dist(some, Aggregation::robust_max, 2) == doctest::Approx(4.0));
  // min_covisible: 3 co-visible frames.
  CHECK(dist(some, Aggregation::paper, 3, 3) == doctest::Approx(4.0));
  CHECK(std::isinf(dist(some, Aggregation::paper, 3, 4)));
  CHECK(std::isinf(dist(some, Aggregation::robust_max, 1, 4)));
  // min_covisible 0 behaves as 1.
  CHECK(dist(some, Aggregation::paper, 3, 0) == doctest::Approx(4.0));

  // Never co-visible: no distance.
  const auto never = pair_case<S>({1, 1, 1}, {0, 0, 0});
  CHECK(std::isinf(dist(never, Aggregation::paper, 3)));
  CHECK(std::isinf(dist(never, Aggregation::robust_max, 3, 0)));

  // 3-D: per-frame distance is the Euclidean norm.
  smg::test::Trajectories<S> tr;
  tr.T = 1;
  tr.N = 2;
  tr.x = {S(1), S(2), S(3), S(4), S(6), S(15)};  // difference (3, 4, 12): 13
  CHECK(dist(tr, Aggregation::paper, 3) == doctest::Approx(13.0));
}

TEST_CASE_TEMPLATE("trajectory distance equals the plain reference, is symmetric, D_ii = 0", S, float, double) {
  SMG_TEST_RNG(rng, 11);
  for (int trial = 0; trial < 20; ++trial) {
    const Index T = rng.integer(1, 70), N = 6;
    auto tr = smg::test::random_trajectories<S>(rng, T, N, trial % 3 == 0 ? 1.0 : 0.6);
    for (Aggregation a : {Aggregation::paper, Aggregation::robust_max})
      for (int m : {1, 3, 4}) {
        TrajectoryDistanceOptions o;
        o.aggregation = a;
        o.m = m;
        o.min_covisible = trial % 4;
        for (Index i = 0; i < N; ++i)
          for (Index j = 0; j < N; ++j) {
            const S d = smg::trajectory_distance<S>(tr.positions(), tr.visibility(), i, j, o);
            const S ref = smg::test::reference_distance(tr, i, j, o);
            CAPTURE(trial);
            CAPTURE(i);
            CAPTURE(j);
            if (std::isinf(ref)) {
              CHECK(std::isinf(d));
              continue;
            }
            CHECK(d == doctest::Approx(ref).epsilon(std::is_same_v<S, float> ? 1e-6 : 1e-14));
            CHECK(d == smg::trajectory_distance<S>(tr.positions(), tr.visibility(), j, i, o));  // bitwise
            if (i == j) CHECK(d == S(0));
          }
      }
  }
}

TEST_CASE("trajectory distance is invariant to a rigid motion per frame") {
  SMG_TEST_RNG(rng, 12);
  auto tr = smg::test::random_trajectories<double>(rng, 30, 5, 0.7);
  auto moved = tr;
  for (Index t = 0; t < tr.T; ++t) {
    const auto R = rng.quaternion().toRotationMatrix();
    const smg::Vector3<double> shift = rng.vec3(10.0);
    for (Index i = 0; i < tr.N; ++i) {
      const smg::Vector3<double> p(tr.at(t, i, 0), tr.at(t, i, 1), tr.at(t, i, 2));
      const smg::Vector3<double> q = R * p + shift;
      for (int c = 0; c < 3; ++c) moved.at(t, i, c) = q(c);
    }
  }
  for (Aggregation a : {Aggregation::paper, Aggregation::robust_max}) {
    TrajectoryDistanceOptions o;
    o.aggregation = a;
    for (Index i = 0; i < tr.N; ++i)
      for (Index j = i + 1; j < tr.N; ++j) {
        const double d = smg::trajectory_distance<double>(tr.positions(), tr.visibility(), i, j, o);
        const double e = smg::trajectory_distance<double>(moved.positions(), moved.visibility(), i, j, o);
        if (std::isinf(d)) {
          CHECK(std::isinf(e));
        } else {
          CHECK(e == doctest::Approx(d).epsilon(1e-12));
        }
      }
  }
}

TEST_CASE("trajectory distance: float agrees with double") {
  SMG_TEST_RNG(rng, 13);
  auto td = smg::test::random_trajectories<double>(rng, 40, 8, 0.8);
  smg::test::Trajectories<float> tf;
  tf.T = td.T;
  tf.N = td.N;
  tf.v = td.v;
  for (double v : td.x) tf.x.push_back(static_cast<float>(v));
  td.x.assign(tf.x.begin(), tf.x.end());  // the same inputs in both precisions
  TrajectoryDistanceOptions o;
  for (Index i = 0; i < td.N; ++i)
    for (Index j = 0; j < td.N; ++j) {
      const double d = smg::trajectory_distance<double>(td.positions(), td.visibility(), i, j, o);
      const float f = smg::trajectory_distance<float>(tf.positions(), tf.visibility(), i, j, o);
      if (std::isinf(d)) {
        CHECK(std::isinf(f));
      } else {
        CHECK(static_cast<double>(f) == doctest::Approx(d).epsilon(1e-6));
      }
    }
}

TEST_CASE("trajectory distance: validation names the argument and the problem") {
  auto tr = pair_case<double>({1, 2, 3}, {1, 1, 0});
  TrajectoryDistanceOptions o;
  auto check = [&](const smg::test::Trajectories<double>& t, Index i, Index j, const TrajectoryDistanceOptions& opt) {
    return smg::validate_trajectory_distance<double>(t.positions(), t.visibility(), i, j, opt).message();
  };
  CHECK(check(tr, 0, 1, o).empty());
  CHECK(check(tr, 0, 2, o) == "node ids: expected 0 <= i, j < N=2, got i=0, j=2");
  CHECK(check(tr, -1, 0, o) == "node ids: expected 0 <= i, j < N=2, got i=-1, j=0");
  TrajectoryDistanceOptions bad = o;
  bad.m = 0;
  CHECK(check(tr, 0, 1, bad) == "m: must be >= 1, got 0");
  bad = o;
  bad.min_covisible = -2;
  CHECK(check(tr, 0, 1, bad) == "min_covisible: must be >= 0, got -2");
  auto nan = tr;
  nan.at(2, 1, 1) = std::numeric_limits<double>::quiet_NaN();
  CHECK(check(nan, 0, 1, o) == "positions: element [t=2][i=1] is NaN");
  auto inf = tr;
  inf.at(0, 0, 2) = -std::numeric_limits<double>::infinity();
  CHECK(check(inf, 0, 1, o) == "positions: element [t=0][i=0] is Inf");
  auto vis = tr;
  vis.v[3] = 2;
  CHECK(check(vis, 0, 1, o) == "visibility: element [t=1][i=1] is 2, expected 0 or 1");
  // Visibility of the wrong shape.
  std::vector<std::uint8_t> v(4, 1);
  CHECK(smg::validate_trajectory_distance<double>(tr.positions(), {v.data(), 2, 2}, 0, 1, o).message() ==
        "visibility: expected shape [T=3][N=2], got [T=2][N=2]");
  // No frames.
  CHECK(smg::validate_trajectory_distance<double>({tr.x.data(), 0, 2}, {}, 0, 1, o).message() ==
        "positions: needs at least one frame (T >= 1)");
}
