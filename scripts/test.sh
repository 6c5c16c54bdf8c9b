#!/usr/bin/env bash
# scripts/test.sh — build everything (library checks, tests, examples, benchmarks) with
# -Wall -Wextra -Wpedantic -Werror and run the test suite. README's test command.
#
#   scripts/test.sh              Release build in build/release, run all tests
#   scripts/test.sh --sanitize   AddressSanitizer + UndefinedBehaviorSanitizer build in
#                                build/asan (tests and examples only), run all tests
set -euo pipefail
cd "$(dirname "$0")/.."
mode=release
for arg in "$@"; do
  case "$arg" in
    --sanitize) mode=asan ;;
    *) echo "usage: scripts/test.sh [--sanitize]" >&2; exit 2 ;;
  esac
done
scripts/deps.sh cmake make g++ libeigen3-dev doctest-dev libbenchmark-dev libstb-dev
jobs=$(nproc)
if [ "$mode" = asan ]; then
  build=${SMG_BUILD_DIR:-build/asan}
  cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSMG_WERROR=ON -DSMG_SANITIZE=ON \
        -DSMG_BUILD_BENCH=OFF
  export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}
  export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
else
  build=${SMG_BUILD_DIR:-build/release}
  cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSMG_WERROR=ON
fi
cmake --build "$build" -j"$jobs"
ctest --test-dir "$build" -j"$jobs" --output-on-failure
