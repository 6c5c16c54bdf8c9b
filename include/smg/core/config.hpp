// smg/core/config.hpp — language check, compiler macros, debug assertions and the ISA tag.
//
// Every smg header includes this first, so that a C++14 build stops at one clear message
// instead of pages of template errors.
#pragma once

#if !defined(__cplusplus) || \
    (__cplusplus < 201703L && !(defined(_MSVC_LANG) && _MSVC_LANG >= 201703L))
#error "smg needs C++17: compile with -std=c++17 or later (CMake: target_compile_features(... cxx_std_17), which smg::smg sets)"
// #error alone lets the compiler go on into the templates below; a missing include stops it.
#include <smg_needs_cxx17>  // NOLINT
#endif

#include <cstdio>
#include <cstdlib>

// Pointer qualifier for the SIMD loops of the energy kernels (restrict: no aliasing). Guarded,
// so that a project (or a second copy of smg) defining it first wins without a warning.
#ifndef SMG_RESTRICT
#if defined(__GNUC__) || defined(__clang__) || defined(_MSC_VER)
#define SMG_RESTRICT __restrict
#else
#define SMG_RESTRICT
#endif
#endif

// Cache prefetch hint: SMG_PREFETCH(pointer, 0 = read / 1 = write). A no-op where unsupported.
#ifndef SMG_PREFETCH
#if defined(__GNUC__) || defined(__clang__)
#define SMG_PREFETCH(p, rw) __builtin_prefetch((p), (rw))
#else
#define SMG_PREFETCH(p, rw) ((void)(p))
#endif
#endif

// Functions callable from CUDA device code as well as from the host: the per-element maths
// (rotations, dual quaternions, the energy terms, skinning, projection) and the view accessors.
// Empty without a CUDA compiler, so host builds see plain functions. include/smg/cuda/ calls
// them from its kernels; the CPU loops call the very same functions (one source of truth).
#ifndef SMG_HOST_DEVICE
#if defined(__CUDACC__)
#define SMG_HOST_DEVICE __host__ __device__
#else
#define SMG_HOST_DEVICE
#endif
#endif

// Forced inlining of the small per-element functions called inside vectorised loops (the
// vectoriser only sees through a call it has inlined).
#ifndef SMG_FORCE_INLINE
#if defined(__GNUC__) || defined(__clang__)
#define SMG_FORCE_INLINE inline __attribute__((always_inline))
#else
#define SMG_FORCE_INLINE inline
#endif
#endif

// Debug assertions on view shapes and preconditions inside the entry points and view accessors.
// On when NDEBUG is not defined (Debug builds) or when SMG_ENABLE_ASSERTS is defined (the
// sanitizer CI build defines it in RelWithDebInfo); off, and free, otherwise. A failed assertion
// prints one line "smg: assertion failed: <condition> (<message>) at <file>:<line>" and aborts:
// a mis-shaped view in a caller's build fails loudly instead of writing out of bounds.
// SMG_DISABLE_ASSERTS turns them off in a Debug build.
#if !defined(SMG_DISABLE_ASSERTS) && (!defined(NDEBUG) || defined(SMG_ENABLE_ASSERTS))
#define SMG_ASSERTS_ENABLED 1
#else
#define SMG_ASSERTS_ENABLED 0
#endif

namespace smg::detail {
// In device code the message goes to the kernel's printf and the thread traps (the launch then
// fails with cudaErrorLaunchFailure, which the launcher reports).
SMG_HOST_DEVICE inline void assertion_failed(const char* condition, const char* message,
                                             const char* file, int line) {
#if defined(__CUDA_ARCH__)
  printf("smg: assertion failed: %s (%s) at %s:%d\n", condition, message, file, line);
  __trap();
#else
  std::fprintf(stderr, "smg: assertion failed: %s (%s) at %s:%d\n", condition, message, file,
               line);
  std::abort();
#endif
}
}  // namespace smg::detail

#if SMG_ASSERTS_ENABLED
#define SMG_ASSERT(condition, message)                                                 \
  ((condition) ? static_cast<void>(0)                                                  \
               : ::smg::detail::assertion_failed(#condition, message, __FILE__, __LINE__))
#else
#define SMG_ASSERT(condition, message) static_cast<void>(0)
#endif

// The instruction-set tag of the code whose shape depends on the target's vector width: the LRM
// kernel's lane count and the rasteriser's lane groups follow __AVX__. Those functions live in
// the inline namespace smg::SMG_ISA_NAMESPACE (callers still write smg::lrm, smg::splat::...),
// so two translation units built with different -m flags get two different functions instead of
// one inline function with two definitions (an ODR violation: the linker would keep one of
// them for both). docs/conventions.md "Instruction sets".
#if defined(__AVX__)
#define SMG_ISA_NAMESPACE isa_avx
#else
#define SMG_ISA_NAMESPACE isa_base
#endif
