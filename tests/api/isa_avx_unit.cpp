// Compiled with -mavx on x86-64 (tests/CMakeLists.txt): the other half of the "two translation
// units, two instruction sets" test in test_isa_namespace.cpp. Plain pointers only, so that this
// unit instantiates nothing but smg's ISA-tagged functions.
#include <cstdint>

#include "smg/energy/carap.hpp"
#include "smg/energy/lrm.hpp"
#include "smg/energy/regularizers.hpp"

#define SMG_TEST_STR2(x) #x
#define SMG_TEST_STR(x) SMG_TEST_STR2(x)

namespace isa_test {

const char* avx_unit_tag() { return SMG_TEST_STR(SMG_ISA_NAMESPACE); }

int avx_unit_lanes() { return smg::detail::lrm_lanes<float>(); }

double avx_unit_lrm(const float* x, const float* c, const std::int32_t* idx, const float* w,
                    smg::Index T, smg::Index N, smg::Index K, float* grad) {
  return smg::lrm<float>({x, T, N}, {c, T, N}, smg::NeighborsView<float>(idx, w, N, K),
                         smg::LrmOptions{}, {grad, T, N});
}

// C-ARAP and the fused step with `threads` threads (gradients too): with AVX's 32-byte packets
// the energy must not depend on the thread count (the scratch slots' alignment).
double avx_unit_carap(const float* x, const float* q, const float* c, const std::int32_t* idx, const float* w,
                      smg::Index T, smg::Index N, smg::Index K, int threads, float* gx, float* gr) {
  smg::ParallelOptions par;
  par.threads = threads;
  return smg::carap<float>({x, T, N}, {q, T, N}, {c, T, N}, smg::NeighborsView<float>(idx, w, N, K),
                           smg::CarapOptions{}, {gx, T, N}, smg::TangentsView<float>(gr, T, N), nullptr, par);
}

double avx_unit_regularizers(const float* x, const float* q, const std::int32_t* idx, const float* w, smg::Index T,
                             smg::Index N, smg::Index K, int threads, float* gx, float* gr) {
  smg::ParallelOptions par;
  par.threads = threads;
  smg::RegularizerOptions o;
  o.terms = {true, true, true, true};
  return smg::regularizers<float>({x, T, N}, {q, T, N}, {}, smg::NeighborsView<float>(idx, w, N, K), o, {},
                                  {gx, T, N}, smg::TangentsView<float>(gr, T, N), nullptr, par)
      .total();
}

}  // namespace isa_test
