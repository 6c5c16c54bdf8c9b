// The smg_trainer program: bad flags and unwritable output folders are one line on stderr and
// exit code 2; a tiny run writes metrics.json (one line, also the last stdout line) and the
// pictures. Runs when the examples are built (tests/CMakeLists.txt passes SMG_TRAINER_PATH).
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <sys/wait.h>

#include "npy.hpp"
#include "support/run_program.hpp"
#include "trainer/progress.hpp"

namespace fs = std::filesystem;

#ifdef SMG_TRAINER_PATH
namespace {
using Run = smg::test::ProgramRun;
using smg::test::slurp;
Run run(const std::string& args) { return smg::test::run_program(SMG_TRAINER_PATH, args, "smg_test_pipeline_trainer_io"); }
}  // namespace

TEST_CASE("smg_trainer: usage errors are one line on stderr and exit code 2") {
  const fs::path file = fs::temp_directory_path() / "smg_test_pipeline_plain_file";
  smg::test::write_bytes(file, "x");
  smg::test::check_usage_errors(run, "smg_trainer", {
      {"--bogus", "bogus"},
      {"--variant nope", "variant"},
      {"--variant Full", "variant"},
      {"--frames 3", "--frames must be in [4, 1000]"},
      {"--width 8", "--width must be in [32, 4096]"},
      {"--stage1-iters -1", "--stage1-iters"},
      {"--threads abc", "--threads"},
      {"--scene occluded", "scene"},
      {"--alpha 1.5", "--alpha must be in [0.000000, 1.000000], got 1.5"},
      {"--alpha nan", "--alpha"},
      {"--alpha auto", "--alpha"},  // removed by the defaults study (docs/results.md)
      {"--carap-reading both", "carap-reading"},
      {"--confidence-from oracle", "confidence-from"},
      {"--confidence-visibility maybe", "confidence-visibility"},
      {"--stage2-unobserved keep", "stage2-unobserved"},
      {"--data /nonexistent --confidence-from truth", "--confidence-from truth needs"},
      {"--data /nonexistent --scene occluder", "--scene cannot be used with --data"},
      {"stray", "unexpected argument 'stray'"},
      {"--out /proc/forbidden_dir", "/proc/forbidden_dir"},
      {"--out " + (file / "sub").string(), "cannot create output folder"},
  });
  fs::remove(file);
}

TEST_CASE("smg_trainer: a tiny run writes metrics.json and the pictures") {
  const fs::path out = fs::temp_directory_path() / "smg_test_pipeline_trainer_out";
  fs::remove_all(out);
  const Run r = run("--quick --stage1-iters 20 --stage2-iters 10 --frames 6 --width 48 --height 36 --tracks 200 "
                    "--threads 2 --scene occluder --alpha 0.5 --carap-reading directed --confidence-from lifted "
                    "--w-accel 0.1 --w-lrm 0.2 --out " +
                    out.string());
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  REQUIRE(fs::exists(out / "metrics.json"));
  const std::string metrics = slurp(out / "metrics.json");
  CHECK(smg::test::count_lines(metrics) == 1);
  for (const char* key : {"\"scene\":\"occluder\"", "\"alpha\":0.5", "\"carap_reading\":\"directed\"",
                          "\"confidence_from\":\"lifted\"", "\"conf_spearman_error\":", "\"conf_weight_directed_low\":",
                          "\"program\":\"smg_trainer\"", "\"variant\":\"full\"", "\"T\":6", "\"width\":48",
                          "\"height\":36", "\"threads\":2", "\"test_psnr\":", "\"epe\":", "\"epe_stage1\":",
                          "\"epe_lifted\":", "\"stage1_iterations\":20", "\"stage2_iterations\":10",
                          "\"w_accel\":0.1", "\"w_lrm\":0.2"}) {
    const std::string k = key;
    CAPTURE(k);
    CHECK(metrics.find(key) != std::string::npos);
  }
  // A weight at its default is left out (a default run's keys stay as they were).
  for (const char* key : {"\"w_data\":", "\"w_rigidity\":", "\"stage2_unobserved\":"}) {
    const std::string k = key;
    CAPTURE(k);
    CHECK(metrics.find(key) == std::string::npos);
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
TEST_CASE("smg_trainer: --export-case writes the stage-1 problem and exits without training") {
  const fs::path dir = fs::temp_directory_path() / "smg_test_pipeline_trainer_case";
  const fs::path out = fs::temp_directory_path() / "smg_test_pipeline_trainer_case_out";
  fs::remove_all(dir);
  fs::remove_all(out);
  const Run r = run("--quick --stage1-iters 20 --stage2-iters 10 --frames 6 --width 48 --height 36 --tracks 200 "
                    "--threads 2 --out " + out.string() + " --export-case " + dir.string());
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  CHECK_FALSE(fs::exists(out));  // no training, no pictures
  REQUIRE(fs::exists(dir / "case.json"));
  const std::string json = slurp(dir / "case.json");
  CHECK(smg::test::count_lines(json) == 1);
  for (const char* key : {"\"T\":6", "\"N\":", "\"K\":16", "\"variant\":\"full\"", "\"w_rigidity\":",
                          "\"w_lrm\":", "\"lr_position\":", "\"iterations\":20", "\"extent\":"}) {
    const std::string k = key;
    CAPTURE(k);
    CHECK(json.find(key) != std::string::npos);
  }
  CHECK(json.find("nan") == std::string::npos);

  const npy::Array lifted = npy::read((dir / "lifted.npy").string());
  REQUIRE(lifted.shape.size() == 3);
  const std::int64_t T = lifted.shape[0], N = lifted.shape[1];
  CHECK(T == 6);
  CHECK(N > 0);
  CHECK(json.find("\"N\":" + std::to_string(N) + ",") != std::string::npos);
  const struct {
    const char* name;
    npy::DType dtype;
    std::vector<std::int64_t> shape;
  } files[] = {{"lifted.npy", npy::DType::f64, {T, N, 3}},     {"visibility.npy", npy::DType::u8, {T, N}},
               {"gt_positions.npy", npy::DType::f64, {T, N, 3}}, {"quats.npy", npy::DType::f64, {T, N, 4}},
               {"graph_indices.npy", npy::DType::i64, {N, 16}},  {"graph_weights.npy", npy::DType::f64, {N, 16}}};
  for (const auto& f : files) {
    const std::string name = f.name;
    CAPTURE(name);
    const npy::Array a = npy::read((dir / f.name).string());
    CHECK(static_cast<int>(a.dtype) == static_cast<int>(f.dtype));
    CHECK(a.shape == f.shape);
    if (npy::is_float(a.dtype)) {
      const std::vector<double> v = a.as<double>(name);
      CHECK(std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); }));
    }
  }
  const std::vector<double> x = lifted.as<double>("lifted"), gt = npy::read((dir / "gt_positions.npy").string()).as<double>("gt");
  double diff = 0;
  for (std::size_t s = 0; s < x.size(); ++s) diff = std::max(diff, std::abs(x[s] - gt[s]));
  CHECK(diff > 1e-3);  // the lifted tracks are noisy
  const std::vector<std::int64_t> idx = npy::read((dir / "graph_indices.npy").string()).as<std::int64_t>("indices");
  CHECK(std::all_of(idx.begin(), idx.end(), [N](std::int64_t i) { return i >= -1 && i < N; }));
  CHECK(idx[0] >= 0);
  const std::vector<std::uint8_t> vis = npy::read((dir / "visibility.npy").string()).as<std::uint8_t>("visibility");
  CHECK(std::any_of(vis.begin(), vis.end(), [](std::uint8_t v) { return v != 0; }));
  // stdout's last line is case.json's line.
  REQUIRE(!r.out.empty());
  const std::size_t last = r.out.rfind('\n', r.out.size() - 2);
  CHECK(r.out.substr(last == std::string::npos ? 0 : last + 1) == json);
  fs::remove_all(dir);
}

TEST_CASE("smg_trainer: --export-case into a folder that cannot be created is a usage error") {
  const Run r = run("--quick --export-case /proc/forbidden_case_dir");
  CAPTURE(r.err);
  CHECK(r.code == 2);
  CHECK(r.out.empty());
  CHECK(smg::test::count_lines(r.err) == 1);
  CHECK(r.err.find("/proc/forbidden_case_dir") != std::string::npos);
}
#else
TEST_CASE("smg_trainer: skipped (the examples are not built)") {
  MESSAGE("SMG_TRAINER_PATH is not defined: the smg_trainer tests are skipped");
}
#endif

TEST_CASE("progress lines: one line each, control characters escaped") {
  std::FILE* f = std::tmpfile();
  REQUIRE(f != nullptr);
  const trainer::Progress p(f, false);
  p.line("data", "scene /tmp/a\x1b[31m\nb\tc");
  std::rewind(f);
  std::string got;
  for (int ch; (ch = std::fgetc(f)) != EOF;) got += static_cast<char>(ch);
  std::fclose(f);
  CHECK(got.find("scene /tmp/a\\x1b[31m\\nb\\tc\n") != std::string::npos);
  CHECK(std::count(got.begin(), got.end(), '\n') == 1);
  CHECK(got.find('\x1b') == std::string::npos);
}

TEST_CASE("progress lines: hold() keeps them back until release(), in order; dropped if never released") {
  const auto read_all = [](std::FILE* f) {
    std::rewind(f);
    std::string got;
    for (int ch; (ch = std::fgetc(f)) != EOF;) got += static_cast<char>(ch);
    return got;
  };
  std::FILE* f = std::tmpfile();
  REQUIRE(f != nullptr);
  {
    const trainer::Progress p(f, false);
    p.hold();
    p.line("data", "first");
    p.line("stage0", "second");
    CHECK(read_all(f).empty());  // nothing written while held
    p.release();
    const std::string got = read_all(f);
    CHECK(std::count(got.begin(), got.end(), '\n') == 2);
    CHECK(got.find("first") < got.find("second"));
    p.line("stage1", "third");  // after release: straight through
    CHECK(read_all(f).find("third") != std::string::npos);
    std::fseek(f, 0, SEEK_END);
  }
  {
    const trainer::Progress p(f, false);
    p.hold();
    p.line("data", "refused");  // a refused scene: the held lines never reach the stream
  }
  CHECK(read_all(f).find("refused") == std::string::npos);
  std::fclose(f);
}
