// examples/trainer/random.hpp — seedable, portable random numbers for the example scene.
//
// The scene, its textures and every prior are drawn from these generators, never from <random>:
// std::normal_distribution and friends differ between standard libraries, and a seed must give
// the same scene everywhere. Work that runs in parallel draws from independent streams
// (derive_seed(seed, stream, index)) so that results do not depend on the thread count.
#pragma once

#include <cmath>
#include <cstdint>

#include <Eigen/Core>

namespace trainer {

// SplitMix64's output function: a bijective mix of 64 bits (Steele, Lea & Flood 2014).
inline std::uint64_t mix64(std::uint64_t z) {
  z += 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Seed of item `index` of stream `stream` under `seed`. Streams name independent uses (the
// track sampler, the depth noise of frame t, ...), so adding draws to one never shifts another.
inline std::uint64_t derive_seed(std::uint64_t seed, std::uint64_t stream, std::uint64_t index = 0) {
  return mix64(mix64(mix64(seed) ^ (stream * 0xD1B54A32D192ED03ull)) ^ index);
}

// Uniform in [0, 1) from a 64-bit hash (53 significant bits).
inline double unit_from_bits(std::uint64_t bits) {
  return static_cast<double>(bits >> 11) * (1.0 / 9007199254740992.0);
}

// SplitMix64 generator with uniform and normal draws.
class Random {
 public:
  explicit Random(std::uint64_t seed) : state_(seed) {}

  std::uint64_t next() {
    state_ += 0x9E3779B97F4A7C15ull;
    std::uint64_t z = state_;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1).
  double uniform() { return unit_from_bits(next()); }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Uniform integer in [0, n), n >= 1.
  std::int64_t below(std::int64_t n) {
    const auto k = static_cast<std::int64_t>(uniform() * static_cast<double>(n));
    return k < n ? k : n - 1;
  }
  // Standard normal (Box-Muller; the second value of each pair is kept for the next call).
  double normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double u1 = 1.0 - uniform();  // (0, 1]
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    const double a = 6.283185307179586 * u2;
    spare_ = r * std::sin(a);
    has_spare_ = true;
    return r * std::cos(a);
  }
  // Uniformly distributed unit 3-vector.
  Eigen::Vector3d unit3() {
    for (;;) {
      const Eigen::Vector3d v(normal(), normal(), normal());
      const double n = v.norm();
      if (n > 1e-9) return v / n;
    }
  }

 private:
  std::uint64_t state_;
  bool has_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace trainer
