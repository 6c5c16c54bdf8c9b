// Two translation units built for different instruction sets (this one for the baseline, and
// isa_avx_unit.cpp with -mavx) each get their own LRM kernel: the lane width differs, so the
// kernels live in an ISA-tagged inline namespace (smg/core/config.hpp) instead of being one
// inline function with two definitions, of which the linker would keep one for both.
#include <doctest/doctest.h>

#include <cstdint>
#include <cstring>
#include <vector>

#include "energy/scene.hpp"
#include "smg/energy/lrm.hpp"

#define SMG_TEST_STR2(x) #x
#define SMG_TEST_STR(x) SMG_TEST_STR2(x)

namespace isa_test {
const char* avx_unit_tag();
int avx_unit_lanes();
double avx_unit_lrm(const float* x, const float* c, const std::int32_t* idx, const float* w,
                    smg::Index T, smg::Index N, smg::Index K, float* grad);
double avx_unit_carap(const float* x, const float* q, const float* c, const std::int32_t* idx, const float* w,
                      smg::Index T, smg::Index N, smg::Index K, int threads, float* gx, float* gr);
double avx_unit_regularizers(const float* x, const float* q, const std::int32_t* idx, const float* w, smg::Index T,
                             smg::Index N, smg::Index K, int threads, float* gx, float* gr);
}  // namespace isa_test

TEST_CASE("translation units built for different instruction sets keep their own LRM kernel") {
  const std::string here = SMG_TEST_STR(SMG_ISA_NAMESPACE), there = isa_test::avx_unit_tag();
  if (here == there) {
    MESSAGE("skipped: both units were compiled for the same instruction set (" << here << ")");
    return;
  }
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  if (!__builtin_cpu_supports("avx")) {
    MESSAGE("skipped: this CPU has no AVX, the -mavx unit cannot run");
    return;
  }
#endif
  CHECK(there == "isa_avx");
  CHECK(smg::detail::lrm_lanes<float>() == 4);
  CHECK(isa_test::avx_unit_lanes() == 8);
  // Both kernels compute the same energy and gradient (the lanes only change the grouping of
  // frames, and so the order of a few additions).
  smg::test::Rng rng(11);
  const smg::test::Scene<float> s = smg::test::random_scene(13, 30, 5, rng).cast<float>();
  std::vector<float> c(13 * 30, 0.7f), g1(13 * 30 * 3, 0.f), g2(13 * 30 * 3, 0.f);
  const double e1 =
      smg::lrm<float>(s.positions(), {c.data(), 13, 30}, s.graph(), smg::LrmOptions{},
                      {g1.data(), 13, 30});
  const double e2 = isa_test::avx_unit_lrm(s.x.data(), c.data(), s.idx.data(), s.w.data(), 13, 30,
                                           5, g2.data());
  CHECK(e1 == doctest::Approx(e2).epsilon(1e-6));
  double diff = 0, norm = 0;
  for (std::size_t k = 0; k < g1.size(); ++k) {
    diff = std::max(diff, double(std::abs(g1[k] - g2[k])));
    norm = std::max(norm, double(std::abs(g1[k])));
  }
  CHECK(diff <= 1e-5 * norm);
}

// With AVX's 32-byte packets Eigen's sums depend on their array's alignment: C-ARAP's scratch
// slots were not aligned, so the energy changed with the thread count (1-3 threads
// 29680.031348705292, 4 threads 29680.031400203705 on this scene before the fix); both C-ARAP and
// the fused step now give the same bits for 1 to 4 threads.
TEST_CASE("with AVX, C-ARAP and the fused step are bit-identical for 1 to 4 threads") {
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  if (!__builtin_cpu_supports("avx")) {
    MESSAGE("skipped: this CPU has no AVX, the -mavx unit cannot run");
    return;
  }
#endif
  smg::test::Rng rng(2402);
  const smg::test::Scene<float> s = smg::test::random_scene(41, 36, 7, rng).cast<float>();
  const std::vector<float> c(41 * 36, 0.6f);
  const auto run = [&](bool fused, int threads, std::vector<float>& gx, std::vector<float>& gr) {
    gx.assign(s.x.size(), 0.f);
    gr.assign(s.x.size(), 0.f);
    return fused ? isa_test::avx_unit_regularizers(s.x.data(), s.q.data(), s.idx.data(), s.w.data(), 41, 36, 7, threads,
                                                   gx.data(), gr.data())
                 : isa_test::avx_unit_carap(s.x.data(), s.q.data(), c.data(), s.idx.data(), s.w.data(), 41, 36, 7,
                                            threads, gx.data(), gr.data());
  };
  for (bool fused : {false, true}) {
    CAPTURE(fused);
    std::vector<float> gx1, gr1, gx, gr;
    const double e1 = run(fused, 1, gx1, gr1);
    for (int threads = 2; threads <= 4; ++threads) {
      CAPTURE(threads);
      CHECK(run(fused, threads, gx, gr) == e1);
      CHECK(gx == gx1);
      CHECK(gr == gr1);
    }
  }
}
