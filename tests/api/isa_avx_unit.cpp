// Compiled with -mavx on x86-64 (tests/CMakeLists.txt): the other half of the "two translation
// units, two instruction sets" test in test_isa_namespace.cpp. Plain pointers only, so that this
// unit instantiates nothing but smg's ISA-tagged functions.
#include <cstdint>

#include "smg/energy/lrm.hpp"

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

}  // namespace isa_test
