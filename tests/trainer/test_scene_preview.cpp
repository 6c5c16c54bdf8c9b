// The scene_preview program: one JSON line and its pictures; bad flags or an unwritable output
// folder give one line on stderr and exit code 2. Runs when the examples are built (the CMake
// block in tests/CMakeLists.txt passes SMG_SCENE_PREVIEW_PATH).
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <string>

#include <sys/wait.h>

#include "support/run_program.hpp"
#include <unistd.h>

namespace fs = std::filesystem;

#ifdef SMG_SCENE_PREVIEW_PATH
namespace {
using Run = smg::test::ProgramRun;
Run run(const std::string& args) { return smg::test::run_program(SMG_SCENE_PREVIEW_PATH, args, "smg_test_scene_preview_io"); }
}  // namespace

TEST_CASE("scene_preview writes its pictures and one JSON line") {
  const fs::path out = fs::temp_directory_path() / "smg_test_scene_preview_out";
  fs::remove_all(out);
  const Run r = run("--out " + out.string() + " --frames 4 --width 48 --height 36 --tracks 40 --show 2");
  CHECK(r.code == 0);
  CHECK(r.err.empty());
  CHECK(smg::test::count_lines(r.out) == 1);
  for (const char* key : {"\"program\":\"scene_preview\"", "\"T\":4", "\"width\":48", "\"tracks\":40",
                          "\"visible_fraction\":", "\"outlier_fraction\":", "\"seconds_total\":"})
    CHECK(r.out.find(key) != std::string::npos);
  for (const char* png : {"train.png", "test_right.png", "test_left.png", "depth.png", "features.png", "tracks.png",
                          "covisible.png", "overview.png"}) {
    CAPTURE(png);
    CHECK(fs::exists(out / png));
    CHECK(fs::file_size(out / png) > 100);
  }
  CHECK_FALSE(fs::exists(out / ".scene_preview_probe"));
}

TEST_CASE("scene_preview: bad flags and unwritable folders are one line on stderr and exit code 2") {
  const fs::path file = fs::temp_directory_path() / "smg_test_scene_preview_plain_file";
  smg::test::write_bytes(file, "x");
  smg::test::check_usage_errors(run, "scene_preview", {
      {"--nope 1", "--nope: unknown flag"},
      {"--frames", "--frames: needs a value"},
      {"--frames abc", "--frames: expects an integer"},
      {"--frames 1", "--frames must be in [2, 1000]"},
      {"--jitter-px -1", "jitter_px"},
      {"stray", "unexpected argument 'stray'"},
      {"--out " + (file / "sub").string(), "cannot create output folder"},
  });
  if (::geteuid() != 0) {  // root can write anywhere
    const fs::path ro = fs::temp_directory_path() / "smg_test_scene_preview_readonly";
    fs::create_directories(ro);
    fs::permissions(ro, fs::perms::owner_read | fs::perms::owner_exec);
    const Run r = run("--out " + ro.string() + " --frames 2 --width 16 --height 16 --tracks 4");
    CHECK(r.code == 2);
    CHECK(r.err.find("not writable") != std::string::npos);
    fs::permissions(ro, fs::perms::owner_all);
  }
}
#else
TEST_CASE("scene_preview tests need the examples (configure with SMG_BUILD_EXAMPLES=ON)") {
  MESSAGE("scene_preview not built: its command-line tests are skipped");
}
#endif
