// Optional cross-check of the splatter against an independent PyTorch statement of gsplat's
// maths (tests/reference/gsplat_reference.py): images, alphas, expected depths, radii and
// autograd gradients of random scenes rendered through `smg_cli render`.
//
// Runs only where a python3 with numpy and torch is found (PATH's python3, then
// /usr/bin/python3; SMG_PYTHON overrides); otherwise it reports the skip and passes. The
// default build needs neither.
#include <doctest/doctest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <sys/wait.h>

namespace fs = std::filesystem;

namespace {
int run(const std::string& cmd, std::string* output = nullptr) {
  std::string out;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return -1;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = pclose(p);
  if (output) *output = out;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}
}  // namespace

TEST_CASE("smg_cli render agrees with an independent torch statement of gsplat (optional)") {
#ifndef SMG_CLI_PATH
  MESSAGE("skipped: smg_cli is not built (SMG_BUILD_EXAMPLES=OFF)");
#else
  std::vector<std::string> candidates;
  if (const char* env = std::getenv("SMG_PYTHON")) candidates.push_back(env);
  candidates.push_back("python3");
  candidates.push_back("/usr/bin/python3");
  std::string python;
  for (const auto& c : candidates)
    if (run(c + " -c 'import torch, numpy'") == 0) {
      python = c;
      break;
    }
  if (python.empty()) {
    MESSAGE("skipped: no python3 with torch and numpy (Debian: apt-get install python3-torch)");
    return;
  }
  const fs::path script = fs::path(__FILE__).parent_path() / "gsplat_reference.py";
  REQUIRE(fs::exists(script));
  const fs::path work = fs::temp_directory_path() / "smg_test_gsplat_reference";
  fs::remove_all(work);
  std::string out;
  const int code = run(python + " " + script.string() + " --cli " + SMG_CLI_PATH +
                           " --workdir " + work.string(),
                       &out);
  MESSAGE(out);
  CHECK(code == 0);
  fs::remove_all(work);
#endif
}
