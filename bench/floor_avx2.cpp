// bench/floor_avx2.cpp — the AVX2+FMA multiply-add chains of bench/floor.hpp's machine probe, in
// a translation unit of its own compiled with -mavx2 -mfma (bench/CMakeLists.txt), called only
// when the CPU reports both (__builtin_cpu_supports), so that the binaries it is linked into
// keep running on any x86-64. Elsewhere (not x86, or a compiler without the flags) it returns 0.
// It includes no C++ header: an inline function of a header compiled here with AVX2 could be the
// copy the linker keeps for the whole program (one definition), and then fail on a CPU without it.
// The declaration is bench/floor.hpp's.
namespace smg_bench::roofline {
double avx2_fma_chains(bool fp64, long iters);
}

#if defined(SMG_FLOOR_AVX2) && (defined(__x86_64__) || defined(__i386__))
#include <immintrin.h>

namespace {


// 12 independent chains of vfmadd (acc = acc·m + a) in ymm registers: 2 flops per lane per step;
// returns the flops done (the caller times all threads together).
template <bool kDouble>
struct Vec {
  using type = __m256;
};
template <>
struct Vec<true> {
  using type = __m256d;
};
template <bool kDouble>
double chains(long iters) {
  using V = typename Vec<kDouble>::type;
  constexpr int kChains = 12, kLanes = kDouble ? 4 : 8;
  volatile double seed_m = 0.999999, seed_a = 1e-6;
  V m, a, acc[kChains];
  if constexpr (kDouble) {
    m = _mm256_set1_pd(seed_m);
    a = _mm256_set1_pd(seed_a);
    for (int c = 0; c < kChains; ++c) acc[c] = _mm256_set1_pd(static_cast<double>(c));
  } else {
    m = _mm256_set1_ps(static_cast<float>(seed_m));
    a = _mm256_set1_ps(static_cast<float>(seed_a));
    for (int c = 0; c < kChains; ++c) acc[c] = _mm256_set1_ps(static_cast<float>(c));
  }
  for (long i = 0; i < iters; ++i)
    for (int c = 0; c < kChains; ++c) {
      if constexpr (kDouble)
        acc[c] = _mm256_fmadd_pd(acc[c], m, a);
      else
        acc[c] = _mm256_fmadd_ps(acc[c], m, a);
    }
  double sum = 0;
  for (int c = 0; c < kChains; ++c) {
    alignas(32) double d[4];
    alignas(32) float f[8];
    if constexpr (kDouble) {
      _mm256_store_pd(d, acc[c]);
      for (double x : d) sum += x;
    } else {
      _mm256_store_ps(f, acc[c]);
      for (float x : f) sum += static_cast<double>(x);
    }
  }
  volatile double sink = sum;
  (void)sink;
  return 2.0 * kLanes * kChains * static_cast<double>(iters);
}

}  // namespace

double smg_bench::roofline::avx2_fma_chains(bool fp64, long iters) {
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) return 0;
  return fp64 ? chains<true>(iters) : chains<false>(iters);
}
#else
double smg_bench::roofline::avx2_fma_chains(bool, long) { return 0; }
#endif
