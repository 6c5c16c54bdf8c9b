// tests/pipeline/scene_on_disk.hpp — what the tests of scenes on disk share
// (test_data_scene.cpp, test_layout_equivalence.cpp): the small procedural scene with short
// stages, and the check of a refused smg_trainer run.
#pragma once

#include <filesystem>
#include <string>
#include <utility>

#include <doctest/doctest.h>

#include "support/run_program.hpp"
#include "trainer/pipeline.hpp"

namespace smg::test {

// True in the sanitizer build (scripts/test.sh --sanitize; Clang's __has_feature, GCC's macro).
#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kUnderSanitizers = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kUnderSanitizers = true;
#else
inline constexpr bool kUnderSanitizers = false;
#endif
#else
inline constexpr bool kUnderSanitizers = false;
#endif

// 12 frames at 64x48, 400 tracks, 150 stage-1 and 120 stage-2 iterations (pruning from 40, every
// 40, not in the last 20), 2 threads. Under the sanitizers stage 2 runs 40 iterations (pruning
// from 10, every 10, not in the last 10: two prunes, as in 120): stage 2 is three quarters of such
// a run there (106 ms an iteration against 1.5 s for all of stage 1), and what the sanitizers check,
// every code path's memory and arithmetic, the first iterations cover as well as the last; the
// Release build keeps the longer run, whose figures the tests' tolerances were set on.
inline trainer::TrainerConfig tiny_scene_config() {
  trainer::TrainerConfig c = trainer::default_config(true);
  const bool short2 = kUnderSanitizers;
  const std::pair<int*, int> settings[] = {
      {&c.dataset.scene.frames, 12}, {&c.dataset.scene.width, 64},  {&c.dataset.scene.height, 48},
      {&c.dataset.priors.tracks, 400}, {&c.stage1.iterations, 150}, {&c.stage2.iterations, short2 ? 40 : 120},
      {&c.stage2.prune_from, short2 ? 10 : 40}, {&c.stage2.prune_every, short2 ? 10 : 40},
      {&c.stage2.prune_tail, short2 ? 10 : 20}, {&c.threads, 2}};
  for (const auto& [field, value] : settings) *field = value;
  return c;
}

// A refused run: exit 2, one stderr line holding `message`, and no `out` folder created.
inline void check_refused(const ProgramRun& run, const std::string& message, const std::filesystem::path& out) {
  CAPTURE(run.err);
  CHECK(run.code == 2);
  CHECK(count_lines(run.err) == 1);
  CHECK(run.err.find(message) != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(out / "metrics.json"));
  CHECK_FALSE(std::filesystem::exists(out));  // nothing is created for a refused scene or bad flags
}

}  // namespace smg::test
