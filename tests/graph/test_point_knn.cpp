// Tests of smg/graph/point_knn.hpp (G15): the tree search equals the all-pairs search bit for bit
// and an independent sort of every pair; ties and exact duplicates by index; radius, self,
// padding; k past N; empty and one-point clouds; huge and tiny coordinates; thread counts;
// int32 and int64 indices; each bad argument refused naming it.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "smg/graph/point_knn.hpp"

using smg::Index;
using smg::PointKnnOptions;

namespace point_knn_test {

template <class S, class I = std::int64_t>
struct Table {
  Index N = 0;
  int k = 0;
  std::vector<I> idx;
  std::vector<S> d2;
  smg::TableView<I, Eigen::Dynamic> indices() { return {idx.data(), N, k}; }
  smg::TableView<S, Eigen::Dynamic> distances2() { return {d2.data(), N, k}; }
  bool same(const Table& o) const {
    if (idx != o.idx || d2.size() != o.d2.size()) return false;
    for (std::size_t q = 0; q < d2.size(); ++q)  // bitwise, inf == inf
      if (!(d2[q] == o.d2[q])) return false;
    return true;
  }
};

template <class S, class I = std::int64_t>
Table<S, I> search(const std::vector<S>& p, const PointKnnOptions& o, bool brute = false) {
  Table<S, I> t;
  t.N = Index(p.size() / 3);
  t.k = o.k;
  t.idx.assign(std::size_t(t.N * o.k), I(7));  // garbage the call must overwrite
  t.d2.assign(std::size_t(t.N * o.k), S(7));
  const smg::TableView<const S, 3> pts(p.data(), t.N);
  REQUIRE(smg::validate_point_knn<S, I>(pts, o, t.indices(), t.distances2()).is_ok());
  if (brute)
    smg::point_knn_brute_force<S, I>(pts, o, t.indices(), t.distances2());
  else
    smg::point_knn<S, I>(pts, o, t.indices(), t.distances2());
  return t;
}

// Independent reading of (G15): every pair's d² (x, y, z summed in order, as the library
// states), all pairs sorted by (d², j), the first k within r² kept.
template <class S>
Table<S> reference(const std::vector<S>& p, const PointKnnOptions& o) {
  Table<S> t;
  t.N = Index(p.size() / 3);
  t.k = o.k;
  const S r = S(o.radius), r2 = r * r;
  for (Index i = 0; i < t.N; ++i) {
    std::vector<std::pair<S, std::int64_t>> all;
    for (Index j = 0; j < t.N; ++j) {
      if (!o.include_self && j == i) continue;
      const S dx = p[3 * j] - p[3 * i], dy = p[3 * j + 1] - p[3 * i + 1], dz = p[3 * j + 2] - p[3 * i + 2];
      const S d2 = dx * dx + dy * dy + dz * dz;
      if (d2 <= r2) all.emplace_back(d2, j);
    }
    std::sort(all.begin(), all.end());
    for (int q = 0; q < o.k; ++q) {
      const bool on = std::size_t(q) < all.size();
      t.idx.push_back(on ? all[std::size_t(q)].second : -1);
      t.d2.push_back(on ? all[std::size_t(q)].first : std::numeric_limits<S>::infinity());
    }
  }
  return t;
}

template <class S>
std::vector<S> cloud(Index n, unsigned seed, double scale = 1.0) {
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<S> p(std::size_t(3 * n));
  for (auto& v : p) v = S(scale * u(g));
  return p;
}

// Integer lattice points with many exact duplicates: every distance tie there is.
template <class S>
std::vector<S> lattice_with_duplicates(int side, int copies) {
  std::vector<S> p;
  for (int c = 0; c < copies; ++c)
    for (int x = 0; x < side; ++x)
      for (int y = 0; y < side; ++y)
        for (int z = 0; z < side; ++z) p.insert(p.end(), {S(x), S(y), S(z)});
  return p;
}

// The tree against the all-pairs search, and (with_reference) against the sort of every pair:
// the sort is the costly reading (N² log N), so the callers run it at their largest k, where
// the rows of every smaller k are prefixes of its rows.
template <class S>
void check_all_readings(const std::vector<S>& p, const PointKnnOptions& o, bool with_reference = true) {
  const auto fast = search<S>(p, o), brute = search<S>(p, o, true);
  CHECK(fast.same(brute));
  if (with_reference) CHECK(fast.same(reference<S>(p, o)));
}

}  // namespace point_knn_test

using namespace point_knn_test;

TEST_CASE_TEMPLATE("point_knn: tree = all pairs = a sort of every pair, bit for bit", S, float, double) {
  for (Index n : {Index(1), Index(2), Index(17), Index(400)})
    for (int k : {1, 5, 20})
      for (bool self : {true, false})
        for (double r : {std::numeric_limits<double>::infinity(), 0.15}) {
          CAPTURE(n);
          CAPTURE(k);
          CAPTURE(self);
          CAPTURE(r);
          PointKnnOptions o;
          o.k = k;
          o.include_self = self;
          o.radius = r;
          check_all_readings(cloud<S>(n, unsigned(n + k)), o, k == 20);
        }
}

TEST_CASE_TEMPLATE("point_knn: ties and exact duplicates go by index", S, float, double) {
  const auto p = lattice_with_duplicates<S>(6, 3);  // 648 points, each three times
  const Index n = Index(p.size() / 3);
  for (int k : {1, 6, 27, 40}) {
    PointKnnOptions o;
    o.k = k;
    check_all_readings(p, o, k == 40);
    o.include_self = false;
    check_all_readings(p, o, k == 40);
    o.radius = 1.0;  // the six lattice neighbours at d² = 1 exactly, and the copies at 0
    check_all_readings(p, o, k == 40);
  }
  PointKnnOptions o;
  o.k = 3;
  const auto t = search<S>(p, o);
  for (Index i = 0; i < n; ++i) {
    // Row i opens with the three copies of its point, lowest index first, at d² = 0.
    const Index base = i % 216;
    for (int q = 0; q < 3; ++q) {
      CHECK(t.idx[std::size_t(3 * i + q)] == base + 216 * q);
      CHECK(t.d2[std::size_t(3 * i + q)] == S(0));
    }
  }
}

TEST_CASE_TEMPLATE("point_knn: radius, self, padding and k past N", S, float, double) {
  const std::vector<S> p = {0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 4};  // d² 1, 4, 16 from the origin
  PointKnnOptions o;
  o.k = 6;
  o.radius = 2.0;  // d² <= 4: the bound itself is kept (frnn's <=)
  auto t = search<S>(p, o);
  const S inf = std::numeric_limits<S>::infinity();
  const std::vector<std::int64_t> row0 = {0, 1, 2, -1, -1, -1};
  const std::vector<S> d0 = {0, 1, 4, inf, inf, inf};
  for (int q = 0; q < 6; ++q) {
    CHECK(t.idx[std::size_t(q)] == row0[std::size_t(q)]);
    CHECK(t.d2[std::size_t(q)] == d0[std::size_t(q)]);
  }
  o.include_self = false;
  t = search<S>(p, o);
  CHECK(t.idx[0] == 1);
  CHECK(t.idx[1] == 2);
  CHECK(t.idx[2] == -1);
  // Row 3 (the point at z = 4): nothing else within 2.
  CHECK(t.idx[18] == -1);
  CHECK(t.d2[18] == inf);
  o.radius = 0.0;  // only exact duplicates (and self) qualify
  o.include_self = true;
  t = search<S>(p, o);
  for (Index i = 0; i < 4; ++i) {
    CHECK(t.idx[std::size_t(6 * i)] == i);
    CHECK(t.idx[std::size_t(6 * i + 1)] == -1);
  }
  check_all_readings(p, o);
}

TEST_CASE("point_knn: no points, one point") {
  PointKnnOptions o;
  o.k = 3;
  const auto empty = search<double>({}, o);
  CHECK(empty.idx.empty());
  const auto one = search<double>({1, 2, 3}, o);
  CHECK(one.idx == std::vector<std::int64_t>{0, -1, -1});
  o.include_self = false;
  CHECK(search<double>({1, 2, 3}, o).idx == std::vector<std::int64_t>{-1, -1, -1});
}

TEST_CASE_TEMPLATE("point_knn: huge and tiny coordinates", S, float, double) {
  PointKnnOptions o;
  o.k = 8;
  // Huge: d² overflows to +inf for float (rows then order by index among the infinite
  // distances); tiny: d² underflows to subnormals and zeros (ties by index).
  for (double scale : {1e25, 1e18, 1e-18, 1e-25}) {
    CAPTURE(scale);
    check_all_readings(cloud<S>(200, 3, scale), o);
  }
}

TEST_CASE("point_knn: the same rows for 1, 2 and 4 threads; int32 = int64") {
  const auto p = cloud<float>(5000, 11);
  PointKnnOptions o;
  o.k = 12;
  o.parallel.threads = 1;
  const auto one = search<float>(p, o);
  for (int threads : {2, 4}) {
    o.parallel.threads = threads;
    CHECK(search<float>(p, o).same(one));
  }
  const auto narrow = search<float, std::int32_t>(p, o);
  CHECK(std::equal(narrow.idx.begin(), narrow.idx.end(), one.idx.begin()));
  CHECK(narrow.d2 == one.d2);
}

TEST_CASE("point_knn: rows are symmetric in d²") {
  const auto p = cloud<float>(800, 5);
  PointKnnOptions o;
  o.k = 10;
  const auto t = search<float>(p, o);
  for (Index i = 0; i < t.N; ++i)
    for (int q = 0; q < o.k; ++q) {
      const auto j = t.idx[std::size_t(i * o.k + q)];
      // d²_ij read from row i equals d²_ji computed the other way round.
      const float dx = p[std::size_t(3 * i)] - p[std::size_t(3 * j)], dy = p[std::size_t(3 * i + 1)] - p[std::size_t(3 * j + 1)],
                  dz = p[std::size_t(3 * i + 2)] - p[std::size_t(3 * j + 2)];
      CHECK(t.d2[std::size_t(i * o.k + q)] == dx * dx + dy * dy + dz * dz);
    }
}

TEST_CASE("point_knn: bad arguments are refused, naming them") {
  std::vector<double> p = cloud<double>(5, 1);
  std::vector<std::int64_t> idx(10);
  std::vector<double> d2(10);
  PointKnnOptions o;
  o.k = 2;
  auto status = [&](Index rows, int cols) {
    return smg::validate_point_knn<double, std::int64_t>(smg::TableView<const double, 3>(p.data(), 5), o,
                                                         {idx.data(), rows, cols}, {d2.data(), rows, cols});
  };
  CHECK(status(5, 2).is_ok());
  p[7] = std::numeric_limits<double>::quiet_NaN();
  CHECK(status(5, 2).message().find("points: point 2 has a NaN or infinite coordinate") == 0);
  p[7] = std::numeric_limits<double>::infinity();
  CHECK(status(5, 2).message().find("points: point 2") == 0);
  p[7] = 0;
  o.k = 0;
  CHECK(status(5, 0).message().find("k: must be >= 1") == 0);
  o.k = 2;
  o.radius = -1;
  CHECK(status(5, 2).message().find("radius: must be >= 0") == 0);
  o.radius = std::numeric_limits<double>::quiet_NaN();
  CHECK(status(5, 2).message().find("radius") == 0);
  o.radius = 1;
  CHECK(status(4, 2).message().find("indices: expected shape [N=5][k=2], got [4][2]") == 0);
}
