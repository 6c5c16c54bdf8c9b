// smg::cuda::point_knn (smg/cuda/point_knn.cuh, (G15)): its per-query scan, run on the host over
// the points in tiles of several sizes (as the kernel stages them), gives the CPU tree search's
// rows bit for bit, ties and duplicates by index, radius and self included, float and double,
// int32 and int64 (suite cuda-host: no GPU needed); on a device, the kernel gives them too.
#include <doctest/doctest.h>

#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "smg/cuda/point_knn.cuh"
#include "smg/graph/point_knn.hpp"

#include "cuda/cuda_test_support.cuh"

namespace cuda_point_knn_test {

using smg::Index;

template <class S>
std::vector<S> knn_cloud(Index n, unsigned seed, bool lattice) {
  std::vector<S> p;
  if (lattice) {  // a 5³ lattice three times: exact ties and duplicates everywhere
    for (int c = 0; c < 3; ++c)
      for (int x = 0; x < 5; ++x)
        for (int y = 0; y < 5; ++y)
          for (int z = 0; z < 5; ++z) p.insert(p.end(), {S(x), S(y), S(z)});
    return p;
  }
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  p.resize(std::size_t(3 * n));
  for (auto& v : p) v = S(u(g));
  return p;
}

template <class S, class I>
struct KnnRows {
  std::vector<I> idx;
  std::vector<S> d2;
  bool operator==(const KnnRows& o) const {
    return idx == o.idx && d2.size() == o.d2.size() &&
           (d2.empty() || std::memcmp(d2.data(), o.d2.data(), d2.size() * sizeof(S)) == 0);
  }
};

template <class S, class I>
KnnRows<S, I> cpu_rows(const std::vector<S>& p, const smg::PointKnnOptions& o) {
  const Index N = Index(p.size() / 3);
  KnnRows<S, I> r{std::vector<I>(std::size_t(N * o.k)), std::vector<S>(std::size_t(N * o.k))};
  smg::point_knn<S, I>(smg::TableView<const S, 3>(p.data(), N), o, {r.idx.data(), N, o.k}, {r.d2.data(), N, o.k});
  return r;
}

// The kernel's steps for every query on the host: point_knn_scan over tiles of `tile` points,
// then the padding.
template <class S, class I>
KnnRows<S, I> scan_rows(const std::vector<S>& p, const smg::PointKnnOptions& o, Index tile) {
  const Index N = Index(p.size() / 3);
  KnnRows<S, I> r{std::vector<I>(std::size_t(N * o.k)), std::vector<S>(std::size_t(N * o.k))};
  const S r2 = smg::detail::point_knn_radius2<S>(o.radius);
  for (Index i = 0; i < N; ++i) {
    S* dist = r.d2.data() + i * o.k;
    I* idx = r.idx.data() + i * o.k;
    int found = 0;
    for (Index first = 0; first < N; first += tile)
      smg::cuda::detail::point_knn_scan(p.data() + 3 * first, std::min(tile, N - first), first, p.data() + 3 * i, i,
                                        o.include_self, r2, o.k, found, dist, idx);
    smg::point_knn_pad(o.k, found, dist, idx);
  }
  return r;
}

template <class S, class I>
void check_scan() {
  for (bool lattice : {false, true})
    for (int k : {5, 20, 40})
      for (bool self : {true, false})
        for (double radius : {std::numeric_limits<double>::infinity(), 1.0}) {
          CAPTURE(lattice);
          CAPTURE(k);
          CAPTURE(self);
          CAPTURE(radius);
          smg::PointKnnOptions o;
          o.k = k;
          o.include_self = self;
          o.radius = radius;
          const auto p = knn_cloud<S>(400, unsigned(k), lattice);
          const auto cpu = cpu_rows<S, I>(p, o);
          for (Index tile : {Index(1), Index(7), Index(smg::cuda::detail::kPointKnnTile)})
            CHECK(scan_rows<S, I>(p, o, tile) == cpu);
        }
}

template <class S, class I>
void check_device() {
  smg::test::cuda::Stream stream;
  for (int k : {5, 20, 40}) {
    CAPTURE(k);
    smg::PointKnnOptions o;
    o.k = k;
    o.radius = k == 20 ? 0.3 : std::numeric_limits<double>::infinity();
    const auto p = knn_cloud<S>(3000, unsigned(k), k == 40);
    const Index N = Index(p.size() / 3);
    const auto cpu = cpu_rows<S, I>(p, o);
    smg::test::cuda::DeviceArray<S> dp(p), dd2;
    smg::test::cuda::DeviceArray<I> didx;
    dd2.resize(std::size_t(N * k));
    didx.resize(std::size_t(N * k));
    const smg::Status s = smg::cuda::point_knn<S, I>(smg::TableView<const S, 3>(dp.get(), N), k, o.radius, true,
                                                     {didx.get(), N, k}, {dd2.get(), N, k}, stream.s);
    REQUIRE(s.is_ok());
    stream.sync();
    CHECK(KnnRows<S, I>{didx.download(), dd2.download()} == cpu);
  }
}

}  // namespace cuda_point_knn_test

TEST_SUITE("cuda-host") {
  TEST_CASE("cuda point_knn scan on the host gives the CPU tree's rows bit for bit") {
    using namespace cuda_point_knn_test;
    check_scan<float, std::int64_t>();
    check_scan<double, std::int32_t>();
  }
}

TEST_CASE("cuda point_knn on the device gives the CPU tree's rows bit for bit") {
  using namespace cuda_point_knn_test;
  check_device<float, std::int64_t>();
  check_device<double, std::int32_t>();
}
