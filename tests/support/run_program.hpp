// tests/support/run_program.hpp — runs an example program as a user would (through the shell),
// capturing its exit code, stdout and stderr, for the tests of the command-line programs.
#pragma once

#include <doctest/doctest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <sys/wait.h>

namespace smg::test {

struct ProgramRun {
  int code = -1;
  std::string out, err;
};

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream f(p);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// `program args` with stdout and stderr redirected into files under a folder named `tag` in the
// temporary directory (one per test program, so parallel ctest runs do not share them).
inline ProgramRun run_program(const std::string& program, const std::string& args, const std::string& tag) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / tag;
  std::filesystem::create_directories(dir);
  const std::string cmd = program + " " + args + " >" + (dir / "out").string() + " 2>" + (dir / "err").string();
  const int status = std::system(cmd.c_str());
  REQUIRE(WIFEXITED(status));
  return {WEXITSTATUS(status), slurp(dir / "out"), slurp(dir / "err")};
}

// Number of '\n' in s.
inline int count_lines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }

}  // namespace smg::test
