// tests/energy/fused_options.hpp — the options the fused-step tests (CPU: test_regularizers.cpp,
// CUDA: tests/cuda/test_cuda_regularizers.cu) run: a subset of the terms by bit mask
// (1 confidence, 2 C-ARAP, 4 ARAP, 8 LRM, 16 smoothness) and non-default values where a default would hide a
// mix-up between terms (ARAP's gaps share δ = 1 with C-ARAP's and add δ = 3 of their own).
#pragma once

#include "smg/energy/options.hpp"

namespace smg::test {

inline RegularizerOptions fused_options(unsigned mask) {
  RegularizerOptions o;
  o.terms.confidence = (mask & 1u) != 0;
  o.terms.carap = (mask & 2u) != 0;
  o.terms.arap = (mask & 4u) != 0;
  o.terms.lrm = (mask & 8u) != 0;
  o.terms.accel = (mask & 16u) != 0;
  o.accel.confidence_weighted = true;
  o.accel.weight = 0.5;
  o.arap.gaps = {{1, 1.0}, {3, 0.5}};
  o.arap.lambda_l = 0.7;
  o.lrm.huber_delta = 0.03;
  o.lrm.weight = 2.0;
  return o;
}

}  // namespace smg::test
