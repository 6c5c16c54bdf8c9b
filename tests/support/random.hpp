// tests/support/random.hpp — seeded random inputs. Every test that draws random numbers builds
// an Rng from a fixed seed and CAPTUREs it, so a failure prints the seed that reproduces it.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>

#include "smg/core/so3.hpp"
#include "smg/core/types.hpp"

namespace smg::test {

struct Rng {
  explicit Rng(std::uint64_t s) : seed(s), engine(s) {}
  std::uint64_t seed;
  std::mt19937_64 engine;

  double uniform(double lo = -1.0, double hi = 1.0) {
    return std::uniform_real_distribution<double>(lo, hi)(engine);
  }
  double normal() { return std::normal_distribution<double>(0.0, 1.0)(engine); }
  int integer(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(engine); }
  Vector3<double> vec3(double scale = 1.0) {
    return Vector3<double>(uniform(), uniform(), uniform()) * scale;
  }
  Vector3<double> unit3() {
    Vector3<double> v(normal(), normal(), normal());
    while (v.norm() < 1e-6) v = Vector3<double>(normal(), normal(), normal());
    return v.normalized();
  }
  // Uniformly distributed rotation (normalised Gaussian 4-vector), sign with w >= 0 not forced.
  Quaternion<double> quaternion() {
    Vector4<double> c(normal(), normal(), normal(), normal());
    while (c.norm() < 1e-6) c = Vector4<double>(normal(), normal(), normal(), normal());
    c.normalize();
    return Quaternion<double>(c(0), c(1), c(2), c(3));
  }
  // A rotation with the given angle about a random axis.
  Quaternion<double> rotation_with_angle(double angle) {
    return so3::exp(Vector3<double>(angle * unit3()));
  }
};

}  // namespace smg::test

// Declares `Rng name(seed)` and CAPTUREs its seed (doctest) for the rest of the scope.
// `name` is a declarator, which cannot be parenthesised like an expression; its second use is.
#define SMG_TEST_RNG(name, seed_value) \
  ::smg::test::Rng name(seed_value);   /* NOLINT(bugprone-macro-parentheses) */ \
  CAPTURE((name).seed)
