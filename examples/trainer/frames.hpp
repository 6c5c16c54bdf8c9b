// examples/trainer/frames.hpp — evenly spread frame indices (pictures, initialisation frames).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace trainer {

// n frame indices spread evenly over [0, T-1], first and last included, increasing, without
// repeats (fewer than n when T < n); {0} when n <= 1.
inline std::vector<int> spread_frames(int T, int n) {
  std::vector<int> f;
  n = std::max(1, std::min(n, T));
  f.reserve(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    const int t = n == 1 ? 0 : static_cast<int>(std::lround(k * (T - 1.0) / (n - 1)));
    if (f.empty() || f.back() != t) f.push_back(t);
  }
  return f;
}

}  // namespace trainer
