// Tests of smg/core/parallel.hpp: coverage, determinism across thread counts, exceptions,
// nesting.
#include <doctest/doctest.h>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

#include "smg/core/parallel.hpp"

using smg::Index;

namespace {
// The exact bit pattern: determinism means equal bits, not merely equal values.
std::uint64_t bits(double x) {
  std::uint64_t b;
  std::memcpy(&b, &x, sizeof b);
  return b;
}
}  // namespace

TEST_CASE("parallel_for visits every index exactly once, for any n and thread count") {
  for (Index n : {0, 1, 2, 255, 256, 257, 10000}) {
    for (int threads : {1, 2, 7}) {
      CAPTURE(n);
      CAPTURE(threads);
      std::vector<int> hits(static_cast<std::size_t>(n), 0);
      smg::parallel_for(
          n, [&](Index b, Index e) { for (Index k = b; k < e; ++k) ++hits[static_cast<std::size_t>(k)]; },
          {threads, 0});
      bool all_once = true;
      for (int h : hits) all_once = all_once && h == 1;
      CHECK(all_once);
    }
  }
}

TEST_CASE("chunking depends on n and grain only") {
  CHECK(smg::parallel_chunk_count(0) == 0);
  CHECK(smg::parallel_chunk_count(1) == 1);
  CHECK(smg::parallel_chunk_count(256) == 256);
  CHECK(smg::parallel_chunk_count(257) == 129);  // grain 2
  CHECK(smg::parallel_chunk_count(100, 30) == 4);
}

TEST_CASE("parallel_reduce is bit-identical for 1, 2 and 7 threads") {
  // Summation order matters in floating point: values spanning many magnitudes make any
  // thread-count-dependent association visible in the last bits.
  std::mt19937_64 engine(31);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> values(100003);
  for (std::size_t k = 0; k < values.size(); ++k)
    values[k] = u(engine) * std::pow(10.0, static_cast<double>(k % 13) - 6);
  auto sum = [&](int threads, Index grain) {
    return smg::parallel_reduce(
        static_cast<Index>(values.size()), 0.0,
        [&](Index b, Index e) {
          double s = 0;
          for (Index k = b; k < e; ++k) s += values[static_cast<std::size_t>(k)];
          return s;
        },
        [](double a, double b) { return a + b; }, {threads, grain});
  };
  for (Index grain : {0, 1000, 7}) {
    const double s1 = sum(1, grain), s2 = sum(2, grain), s7 = sum(7, grain);
    CHECK(bits(s1) == bits(s2));
    CHECK(bits(s1) == bits(s7));
  }
  // A serial left-to-right sum differs from the chunked one in general; the contract is
  // determinism, not equality with the serial order.
  CHECK(std::abs(sum(1, 0) - sum(1, 1)) <= 1e-12 * std::abs(sum(1, 1)));
}

TEST_CASE("the process default thread count is settable") {
  smg::set_num_threads(3);
  CHECK(smg::num_threads() == 3);
  smg::set_num_threads(0);
  CHECK(smg::num_threads() >= 1);
}

TEST_CASE("an exception in a chunk reaches the caller after all threads joined") {
  for (int threads : {1, 2, 7}) {
    std::atomic<int> ran{0};
    CHECK_THROWS_AS(smg::parallel_for(
                        1000,
                        [&](Index b, Index) {
                          ++ran;
                          if (b >= 500) throw std::runtime_error("boom");
                        },
                        {threads, 10}),
                    std::runtime_error);
    CHECK(ran.load() >= 1);
  }
}

TEST_CASE("a nested parallel loop runs serially on its caller's thread") {
  std::atomic<int> total{0};
  smg::parallel_for(
      8,
      [&](Index b, Index e) {
        for (Index k = b; k < e; ++k)
          smg::parallel_for(100, [&](Index bb, Index ee) { total += static_cast<int>(ee - bb); }, {4, 1});
      },
      {2, 1});
  CHECK(total.load() == 800);
}

TEST_CASE("the helper-thread pool: many short loops, changing thread counts, concurrent callers") {
  // Thousands of short loops reuse the pool's threads; every index is still visited once.
  for (int rep = 0; rep < 2000; ++rep) {
    const int threads = 1 + rep % 7;
    std::vector<int> hits(97, 0);
    smg::parallel_for(97, [&](Index b, Index e) { for (Index k = b; k < e; ++k) ++hits[static_cast<std::size_t>(k)]; },
                      {threads, 3});
    bool ok = true;
    for (int h : hits) ok = ok && h == 1;
    REQUIRE(ok);
  }
  // Two user threads running loops at the same time: one gets the pool, the other starts its
  // own threads; both results are complete and deterministic.
  auto sum = [](int threads) {
    return smg::parallel_reduce(
        200000, 0.0,
        [](Index b, Index e) {
          double s = 0;
          for (Index k = b; k < e; ++k) s += 1.0 / static_cast<double>(k + 1);
          return s;
        },
        [](double a, double b) { return a + b; }, {threads, 0});
  };
  const double reference = sum(1);
  std::vector<double> results(4, 0.0);
  std::vector<std::thread> callers;
  callers.reserve(4);
  for (int c = 0; c < 4; ++c)
    callers.emplace_back([&, c] {
      for (int rep = 0; rep < 50; ++rep) results[static_cast<std::size_t>(c)] = sum(2 + c);
    });
  for (auto& t : callers) t.join();
  for (double r : results) CHECK(bits(r) == bits(reference));
}
