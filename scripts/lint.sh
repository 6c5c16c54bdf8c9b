#!/usr/bin/env bash
# scripts/lint.sh — static analysis: cppcheck over the headers and examples, clang-tidy
# (.clang-tidy) over every translation unit of the tests and examples, which instantiate the
# library's templates. Findings fail the run; justified exceptions are annotated in the code
# with NOLINT(<check>) and a reason. (--extra-arg=-std=c++17: g++ 12 defaults to C++17, so CMake
# records no -std flag, but clang-tidy's default is C++14.)
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh cmake make g++ libeigen3-dev doctest-dev libbenchmark-dev libstb-dev cppcheck clang-tidy
build=${SMG_BUILD_DIR:-build/lint}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Debug -DCMAKE_EXPORT_COMPILE_COMMANDS=ON -DSMG_BUILD_BENCH=OFF >/dev/null

echo "== cppcheck"
cppcheck --quiet --error-exitcode=1 --std=c++17 --language=c++ --inline-suppr \
  --enable=warning,performance,portability --suppress=missingIncludeSystem \
  --suppress=unknownMacro -I include -I examples/common \
  include examples

echo "== clang-tidy"
files=$(find tests examples -name '*.cpp' -not -path 'tests/consumer/*' | sort)
status=0
for f in $files; do
  clang-tidy -p "$build" --quiet --extra-arg=-std=c++17 "$f" 2>/dev/null || { echo "clang-tidy: findings in $f"; status=1; }
done
exit $status
