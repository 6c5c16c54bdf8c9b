// examples/trainer/util.hpp — the small helpers the trainer's sources share (one definition each).
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>

#include <smg/core/status.hpp>

namespace trainer {

constexpr double kPi = 3.14159265358979323846;

// An index or count (int, long long) as a std::size_t, for subscripts and sizes.
inline std::size_t sz(long long v) { return static_cast<std::size_t>(v); }

// Throws with the library's message when a precondition fails (a bug in the trainer, not a
// user error: the inputs are all produced here).
inline void check(const smg::Status& s, const char* where) {
  if (!s) throw std::logic_error(std::string(where) + ": " + s.message());
}

}  // namespace trainer
