// tests/fuzz/fuzz_target.hpp — how a harness of tests/fuzz is declared, once for two builds.
//
//   SMG_FUZZ_TARGET(npy)(const std::uint8_t* data, std::size_t size) { ...; return 0; }
//
// With libFuzzer (the fuzz_<reader> programs, SMG_BUILD_FUZZ=ON, scripts/fuzz.sh) it is
// LLVMFuzzerTestOneInput. In the replay program (fuzz_replay, every build with the tests;
// SMG_FUZZ_REPLAY defined) each harness registers itself by name, so that one program runs any
// harness over its corpus with any compiler: `fuzz_replay npy tests/fuzz/corpus/npy`.
//
// A harness calls one reader on the bytes and swallows the reader's own error type only: a
// refusal is the expected outcome of most inputs; any other exception, a crash or a sanitizer
// report is a finding.
#pragma once

#include <cstddef>
#include <cstdint>

#ifdef SMG_FUZZ_REPLAY
namespace smg_fuzz {
using Target = int (*)(const std::uint8_t*, std::size_t);
// Registers `target` under `name` (replay_main.cpp); returns true.
bool register_target(const char* name, Target target);
}  // namespace smg_fuzz
#define SMG_FUZZ_TARGET(name)                                                                    \
  static int smg_fuzz_##name(const std::uint8_t*, std::size_t);                                 \
  [[maybe_unused]] static const bool smg_fuzz_registered_##name =                               \
      smg_fuzz::register_target(#name, smg_fuzz_##name);                                        \
  static int smg_fuzz_##name
#else
#define SMG_FUZZ_TARGET(name) extern "C" int LLVMFuzzerTestOneInput
#endif
