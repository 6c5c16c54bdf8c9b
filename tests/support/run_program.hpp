// tests/support/run_program.hpp — runs an example program as a user would (through the shell),
// capturing its exit code, stdout and stderr, for the tests of the command-line programs.
#pragma once

#include <doctest/doctest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <sys/wait.h>

#include "support/files.hpp"

namespace smg::test {

struct ProgramRun {
  int code = -1;
  std::string out, err;
};

// How run_program starts the program, for the tests that feed it hostile inputs.
struct RunOptions {
  std::string env;      // prefix of the command line, e.g. "LC_ALL=C" (shell syntax)
  int timeout_s = 0;    // > 0: run under `timeout`, so that a blocked program fails instead of hanging ctest
  bool no_stdin = false;  // stdin from /dev/null
  // true: a program that does not exit (killed by a signal) fails the test at once; false: the
  // run returns code -1 and the caller's checks of the code fail.
  bool require_exit = true;
};

// `program args` with stdout and stderr redirected into files under a folder named `tag` in the
// temporary directory (one per test program, so parallel ctest runs do not share them).
inline ProgramRun run_program(const std::string& program, const std::string& args, const std::string& tag,
                              const RunOptions& o = {}) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / tag;
  std::filesystem::create_directories(dir);
  std::string cmd = o.env.empty() ? "" : o.env + " ";
  if (o.timeout_s > 0) cmd += "timeout " + std::to_string(o.timeout_s) + " ";
  cmd += program + " " + args + " >" + (dir / "out").string() + " 2>" + (dir / "err").string();
  if (o.no_stdin) cmd += " </dev/null";
  const int status = std::system(cmd.c_str());
  if (o.require_exit) REQUIRE(WIFEXITED(status));
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(dir / "out"), slurp(dir / "err")};
}

// Number of '\n' in s.
inline int count_lines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }

// A usage error as the example programs report it: exit code 2, nothing on stdout, and one line on
// stderr that starts with "<program>: error: " and contains `message`.
inline void check_usage_error(const ProgramRun& r, const std::string& program, const std::string& message) {
  CHECK(r.code == 2);
  CHECK(r.out.empty());
  CHECK(count_lines(r.err) == 1);
  CHECK(r.err.rfind(program + ": error: ", 0) == 0);
  CHECK(r.err.find(message) != std::string::npos);
}

// One usage error: the arguments, and what the program's one error line must contain.
struct UsageCase {
  std::string args, message;
};

// For each case, `run(args)` (returning a ProgramRun) must be a usage error of `program`
// (check_usage_error).
template <class F>
void check_usage_errors(const F& run, const std::string& program, const std::vector<UsageCase>& cases) {
  for (const UsageCase& c : cases) {
    CAPTURE(c.args);
    const ProgramRun r = run(c.args);
    CAPTURE(r.err);
    check_usage_error(r, program, c.message);
  }
}

}  // namespace smg::test
