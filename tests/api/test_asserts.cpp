// SMG_ASSERT (smg/core/config.hpp): with assertions on, a mis-shaped view or an out-of-range
// access aborts with one line naming the violated condition, instead of writing out of bounds.
#include <doctest/doctest.h>

#include <string>
#include <vector>

#include "support/operators.hpp"
#include "support/run_program.hpp"

#ifdef SMG_ASSERT_PROBE_PATH
TEST_CASE("debug assertions catch mis-shaped views and out-of-range accesses") {
  std::vector<std::string> modes = {"view"};  // then every operator, misused by name
  smg::test::for_each_operator([&](auto op) { modes.push_back(op.name); });
  for (const std::string& mode : modes) {
    CAPTURE(mode);
    const auto r = smg::test::run_program(SMG_ASSERT_PROBE_PATH, mode, "smg_assert_probe");
    CHECK(r.code != 0);
    CHECK(r.code != 3);  // 3: the probe ran past the misuse
    // The program's own stderr is one line (the shell may add its "Aborted" after it).
    CHECK(r.err.rfind("smg: assertion failed: ", 0) == 0);
    const std::string rest = r.err.substr(r.err.find('\n') + 1);
    CHECK((rest.empty() || (smg::test::count_lines(rest) == 1 && rest.find("Abort") != std::string::npos)));
  }
  const auto ok = smg::test::run_program(SMG_ASSERT_PROBE_PATH, "ok", "smg_assert_probe");
  CHECK(ok.code == 0);
  CHECK(ok.err.empty());
}
#endif
