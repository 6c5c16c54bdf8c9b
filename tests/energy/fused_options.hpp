// tests/energy/fused_options.hpp — the options the fused-step tests (CPU: test_regularizers.cpp,
// CUDA: tests/cuda/test_cuda_regularizers.cu) run: a subset of the terms by bit mask, bit k for
// the k-th term of the library's list (smg::for_each_term: 1 confidence, 2 C-ARAP, 4 ARAP, 8 LRM,
// 16 smoothness, and so on for a term added to the list), and non-default values where a default
// would hide a mix-up between terms (ARAP's gaps share δ = 1 with C-ARAP's and add δ = 3 of their
// own).
#pragma once

#include <string>

#include "smg/energy/options.hpp"

namespace smg::test {

// The number of terms on the list (the masks run over 0 … 2^count − 1).
inline unsigned fused_term_count() {
  unsigned n = 0;
  RegularizerOptions o;
  for_each_term(o, [&](const char*, bool, const auto&) { ++n; });
  return n;
}

// The list index of the term named `term` (its mask bit is 1 << index); count if not listed.
inline unsigned fused_term_index(const char* term) {
  unsigned k = 0, found = fused_term_count();
  RegularizerOptions o;
  for_each_term(o, [&](const char* name, bool, const auto&) {
    if (std::string(name) == term) found = k;
    ++k;
  });
  return found;
}

// The mask with every term on.
inline unsigned fused_all_terms() { return (1u << fused_term_count()) - 1u; }

inline RegularizerOptions fused_options(unsigned mask) {
  RegularizerOptions o;
  unsigned k = 0;
  for_each_term(o, [&](const char*, bool& on, const auto&) { on = ((mask >> k++) & 1u) != 0; });
  o.accel.confidence_weighted = true;
  o.accel.weight = 0.5;
  o.arap.gaps = {{1, 1.0}, {3, 0.5}};
  o.arap.lambda_l = 0.7;
  o.lrm.huber_delta = 0.03;
  o.lrm.weight = 2.0;
  return o;
}

}  // namespace smg::test
