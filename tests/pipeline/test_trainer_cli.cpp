// The smg_trainer program: bad flags and unwritable output folders are one line on stderr and
// exit code 2; a tiny run writes metrics.json (one line, also the last stdout line) and the
// pictures. Runs when the examples are built (tests/CMakeLists.txt passes SMG_TRAINER_PATH).
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <sys/wait.h>

#include "support/run_program.hpp"

namespace fs = std::filesystem;

#ifdef SMG_TRAINER_PATH
namespace {
using Run = smg::test::ProgramRun;
using smg::test::slurp;
Run run(const std::string& args) {
  return smg::test::run_program(SMG_TRAINER_PATH, args, "smg_test_pipeline_trainer_io");
}
int lines(const std::string& s) { return smg::test::count_lines(s); }
}  // namespace

TEST_CASE("smg_trainer: usage errors are one line on stderr and exit code 2") {
  const fs::path file = fs::temp_directory_path() / "smg_test_pipeline_plain_file";
  std::ofstream(file) << "x";
  const struct {
    std::string args, message;
  } cases[] = {
      {"--bogus", "bogus"},
      {"--variant nope", "variant"},
      {"--variant Full", "variant"},
      {"--frames 3", "--frames must be in [4, 1000]"},
      {"--width 8", "--width must be in [32, 4096]"},
      {"--stage1-iters -1", "--stage1-iters"},
      {"--threads abc", "--threads"},
      {"stray", "unexpected argument 'stray'"},
      {"--out /proc/forbidden_dir", "/proc/forbidden_dir"},
      {"--out " + (file / "sub").string(), "cannot create output folder"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.args);
    const Run r = run(c.args);
    CAPTURE(r.err);
    CHECK(r.code == 2);
    CHECK(r.out.empty());
    CHECK(lines(r.err) == 1);
    CHECK(r.err.rfind("smg_trainer: error: ", 0) == 0);
    CHECK(r.err.find(c.message) != std::string::npos);
  }
  fs::remove(file);
}

TEST_CASE("smg_trainer: a tiny run writes metrics.json and the pictures") {
  const fs::path out = fs::temp_directory_path() / "smg_test_pipeline_trainer_out";
  fs::remove_all(out);
  const Run r = run("--quick --stage1-iters 20 --stage2-iters 10 --frames 6 --width 48 --height 36 --tracks 200 "
                    "--threads 2 --out " + out.string());
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  REQUIRE(fs::exists(out / "metrics.json"));
  const std::string metrics = slurp(out / "metrics.json");
  CHECK(lines(metrics) == 1);
  for (const char* key : {"\"program\":\"smg_trainer\"", "\"variant\":\"full\"", "\"T\":6", "\"width\":48",
                          "\"height\":36", "\"threads\":2", "\"test_psnr\":", "\"epe\":", "\"epe_stage1\":",
                          "\"epe_lifted\":", "\"stage1_iterations\":20", "\"stage2_iterations\":10"}) {
    const std::string k = key;
    CAPTURE(k);
    CHECK(metrics.find(key) != std::string::npos);
  }
  CHECK(metrics.find("nan") == std::string::npos);
  // stdout's last line is the same JSON line.
  REQUIRE(!r.out.empty());
  const std::size_t last = r.out.rfind('\n', r.out.size() - 2);
  CHECK(r.out.substr(last == std::string::npos ? 0 : last + 1) == metrics);
  for (const char* png : {"test_left.png", "test_right.png", "contact_sheet.png", "nodes.png"}) {
    const std::string p = png;
    CAPTURE(p);
    REQUIRE(fs::exists(out / png));
    CHECK(fs::file_size(out / png) > 100);
    std::ifstream f(out / png, std::ios::binary);
    char sig[8] = {};
    f.read(sig, 8);
    CHECK(std::string(sig + 1, 3) == "PNG");
  }
  CHECK_FALSE(fs::exists(out / ".smg_trainer_probe"));
  fs::remove_all(out);
}
#else
TEST_CASE("smg_trainer: skipped (the examples are not built)") {
  MESSAGE("SMG_TRAINER_PATH is not defined: the smg_trainer tests are skipped");
}
#endif
