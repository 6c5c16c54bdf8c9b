// Tests of the smg_cli driver (docs/interop.md): JSON summary on stdout, one-line errors on stderr,
// exit code 2, and flag parsing.
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "cli_args.hpp"
#include "json_line.hpp"
#include "npy.hpp"
#include "smg/core/version.hpp"
#include "support/run_program.hpp"

namespace fs = std::filesystem;

namespace {
#ifdef SMG_CLI_PATH
using Run = smg::test::ProgramRun;
Run run_cli(const std::string& args) { return smg::test::run_program(SMG_CLI_PATH, args, "smg_test_cli_io"); }
#endif
}  // namespace

TEST_CASE("cli::Args parses flags strictly") {
  cli::Args a({{"k", "16", "neighbours"}, {"gaps", "1,2,4", "gaps"}, {"detach-omega", "", "", true},
               {"aggregation", "paper", ""}});
  const char* argv[] = {"prog", "sub", "CASE", "--k", "8", "--gaps=1,3", "--detach-omega", "OUT"};
  a.parse(8, argv, 2);
  CHECK(a.positionals() == std::vector<std::string>{"CASE", "OUT"});
  CHECK(a.get_int("k") == 8);
  CHECK(a.get_ints("gaps") == std::vector<long long>{1, 3});
  CHECK(a.get_switch("detach-omega"));
  CHECK(a.get_choice("aggregation", {"paper", "robust_max"}) == "paper");

  cli::Args b({{"k", "16", ""}, {"tau", "0.75", ""}});
  const char* bad1[] = {"p", "--nope", "1"};
  CHECK_THROWS_WITH(b.parse(3, bad1, 1), "--nope: unknown flag");
  const char* bad2[] = {"p", "--k"};
  CHECK_THROWS_WITH(cli::Args({{"k", "16", ""}}).parse(2, bad2, 1), "--k: needs a value");
  cli::Args c({{"tau", "0.75", ""}});
  const char* bad3[] = {"p", "--tau", "0.7x"};
  c.parse(3, bad3, 1);
  CHECK_THROWS_WITH(c.get_double("tau"), "--tau: expects a finite number, got '0.7x'");
  cli::Args d({{"tau", "nan", ""}});
  CHECK_THROWS_AS(d.get_double("tau"), cli::UsageError);
}

TEST_CASE("JsonLine formats one JSON object") {
  cli::JsonLine j;
  j.add("subcommand", "graph").add("N", 5).add("ok", true).add("x", 0.5)
      .add("nan", std::numeric_limits<double>::quiet_NaN()).add("s", "a\"b\n");
  CHECK(j.str() == "{\"subcommand\":\"graph\",\"N\":5,\"ok\":true,\"x\":0.5,\"nan\":null,\"s\":\"a\\\"b\\n\"}");
}

#ifdef SMG_CLI_PATH
TEST_CASE("smg_cli: summary line, errors with exit code 2") {
  const fs::path dir = fs::temp_directory_path() / "smg_test_cli_case";
  fs::remove_all(dir);
  fs::create_directories(dir);
  npy::write((dir / "positions.npy").string(), std::vector<double>(3 * 4 * 3, 1.0), {3, 4, 3});
  npy::write((dir / "visibility.npy").string(), std::vector<std::uint8_t>(12, 1), {3, 4});

  Run r = run_cli("check " + dir.string());
  CHECK(r.code == 0);
  CHECK(r.err.empty());
  CHECK(r.out.rfind("{\"subcommand\":\"check\",\"T\":3,\"N\":4,\"C\":0,\"files\":[\"positions.npy\",\"visibility.npy\"],"
                    "\"precision\":\"float64\",\"seconds\":", 0) == 0);
  CHECK(std::count(r.out.begin(), r.out.end(), '\n') == 1);

  r = run_cli("frobnicate x y");
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli: error: unknown subcommand 'frobnicate' (try smg_cli --help)\n");

  r = run_cli("check " + dir.string() + " --bogus 1");
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli check: error: --bogus: unknown flag\n");

  r = run_cli("check /nonexistent/case");
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli check: error: /nonexistent/case: case directory does not exist\n");

  npy::write((dir / "quats.npy").string(), std::vector<double>(3 * 4 * 4, 0.0), {3, 4, 4});
  r = run_cli("check " + dir.string());
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli check: error: " + (dir / "quats.npy").string() + ": element [t=0][i=0] is the zero quaternion\n");
  CHECK(r.out.empty());

  npy::write((dir / "quats.npy").string(), std::vector<double>(3 * 5 * 4, 1.0), {3, 5, 4});
  r = run_cli("check " + dir.string());
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli check: error: " + (dir / "quats.npy").string() +
                     ": expected shape [T=3, N=4, 4], got [3, 5, 4]\n");

  r = run_cli("--help");
  CHECK(r.code == 0);
  CHECK(r.out.find("subcommands:") != std::string::npos);
  // The build's instruction set, as this test's own unit sees the same flags.
  CHECK(r.out.find(std::string("instruction set ") + SMG_ISA_NAME + " (") != std::string::npos);
  fs::remove_all(dir);
}
#endif
