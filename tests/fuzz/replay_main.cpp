// tests/fuzz/replay_main.cpp — fuzz_replay HARNESS PATH...: runs the harness once on every file
// under each PATH (a file or a folder, recursively, in sorted order), as libFuzzer's `-runs=0`
// replay does, but built by any compiler (the Release build's GCC, the sanitizer build's Clang).
// ctest runs it over tests/fuzz/corpus/<harness>/ (label fuzz_replay): in the sanitizer build,
// every seed and every past crash input under ASan + UBSan. Prints one line: the harness and how
// many inputs ran; exits 1 when a path is missing or holds no input (a corpus that vanished must
// not pass silently), 2 on bad usage.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include "fuzz_target.hpp"

namespace smg_fuzz {
namespace {
std::map<std::string, Target>& targets() {
  static std::map<std::string, Target> t;
  return t;
}
}  // namespace
bool register_target(const char* name, Target target) {
  targets()[name] = target;
  return true;
}
}  // namespace smg_fuzz

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  const auto& targets = smg_fuzz::targets();
  const auto it = argc >= 3 ? targets.find(argv[1]) : targets.end();
  if (it == targets.end()) {
    std::string names;
    for (const auto& kv : targets) names += " " + kv.first;
    std::fprintf(stderr, "usage: fuzz_replay HARNESS PATH...  (harnesses:%s)\n", names.c_str());
    return 2;
  }
  std::vector<fs::path> inputs;
  for (int a = 2; a < argc; ++a) {
    const fs::path p(argv[a]);
    std::error_code ec;
    if (fs::is_regular_file(p, ec)) {
      inputs.push_back(p);
    } else if (fs::is_directory(p, ec)) {
      for (const auto& e : fs::recursive_directory_iterator(p))
        if (e.is_regular_file()) inputs.push_back(e.path());
    } else {
      std::fprintf(stderr, "fuzz_replay %s: %s: no such file or folder\n", argv[1], argv[a]);
      return 1;
    }
  }
  if (inputs.empty()) {
    std::fprintf(stderr, "fuzz_replay %s: no inputs\n", argv[1]);
    return 1;
  }
  std::sort(inputs.begin(), inputs.end());
  for (const fs::path& p : inputs) {
    std::ifstream f(p, std::ios::binary);
    const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    if (f.bad()) {
      std::fprintf(stderr, "fuzz_replay %s: %s: cannot read\n", argv[1], p.string().c_str());
      return 1;
    }
    it->second(bytes.data(), bytes.size());
  }
  std::printf("fuzz_replay %s: %zu inputs, no crash\n", argv[1], inputs.size());
  return 0;
}
