// smg/core/version.hpp — library version (CMakeLists.txt reads SMG_VERSION_STRING from here).
#pragma once

#include "smg/core/config.hpp"

#define SMG_VERSION_MAJOR 0
#define SMG_VERSION_MINOR 1
#define SMG_VERSION_PATCH 0
#define SMG_VERSION_STRING "0.1.0"

// The instruction set the including translation unit is compiled for, as programs report it
// (smg_cli --help, smg_torch.isa): "avx2+fma", "avx" or "base" (x86-64's SSE2, or another
// architecture's baseline). docs/quickstart.md "Build flags".
#if defined(__AVX2__) && defined(__FMA__)
#define SMG_ISA_NAME "avx2+fma"
#elif defined(__AVX__)
#define SMG_ISA_NAME "avx"
#else
#define SMG_ISA_NAME "base"
#endif
