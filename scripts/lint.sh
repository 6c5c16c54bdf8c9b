#!/usr/bin/env bash
# scripts/lint.sh — static analysis: cppcheck over the headers and examples, clang-tidy
# (.clang-tidy) over every translation unit of the tests and examples, which instantiate the
# library's templates. Findings fail the run; justified exceptions are annotated in the code
# with NOLINT(<check>) and a reason; xargs exits non-zero if any file has findings. (--extra-arg=-std=c++17: g++ 12 defaults to C++17, so CMake
# records no -std flag, but clang-tidy's default is C++14.)
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh cmake make g++ libeigen3-dev doctest-dev libbenchmark-dev libstb-dev zlib1g-dev libpng-dev libjpeg62-turbo-dev cppcheck clang-tidy
build=${SMG_BUILD_DIR:-build/lint}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Debug -DCMAKE_EXPORT_COMPILE_COMMANDS=ON -DSMG_BUILD_BENCH=OFF \
      -DSMG_BUILD_TORCH=OFF -DSMG_BUILD_CUDA=OFF >/dev/null

echo "== cppcheck"
# cppcheck checks the headers through the examples that include them. Left to itself it tries up
# to 12 preprocessor configurations per file, most of which no build uses (298 CPU-s, against
# 30 for one); it checks instead the three configurations the builds compile: portable (no
# compiler macros: the scalar fallbacks of core/lanes), GCC/Clang with smg's assertions (the
# sanitizer build), and GCC/Clang with AVX2+FMA (the vector-extension lanes). The stb user
# leaves the two named configurations: cppcheck 2.10 takes its __has_include guard for false.
cppcheck_run() {
  cppcheck --quiet --error-exitcode=1 --std=c++17 --language=c++ --inline-suppr \
    --enable=warning,performance,portability --suppress=missingIncludeSystem \
    --suppress=unknownMacro -I include -I examples/common -i examples/torch "$@" examples
}
# The three runs go side by side, one job each: one run with -j2 kept 1.4 of 2 cores busy (42
# CPU-s in 31 s), so three in a row left a core idle for about 25 s. Each run's findings are
# captured and printed as one block.
stb_users=(-i examples/trainer/image_io.cpp)
pids=()
for cfg in 1 2 3; do
  case $cfg in
    1) args=(--max-configs=1) ;;
    2) args=("${stb_users[@]}" -D__GNUC__ -DSMG_ENABLE_ASSERTS) ;;
    3) args=("${stb_users[@]}" -D__GNUC__ -D__AVX__ -D__AVX2__ -D__FMA__) ;;
  esac
  (cppcheck_run "${args[@]}" > "$build/cppcheck_$cfg.log" 2>&1) &
  pids+=($!)
done
cppcheck_rc=0
for k in 0 1 2; do
  wait "${pids[$k]}" || { cppcheck_rc=1; cat "$build/cppcheck_$((k + 1)).log"; echo "cppcheck: findings in configuration $((k + 1))"; }
done
[ "$cppcheck_rc" = 0 ] || exit 1

echo "== clang-tidy"
# One clang-tidy per translation unit of the build, nproc at a time; each file's findings are
# printed as one block (captured, so parallel runs do not interleave). The translation units are
# those of compile_commands.json: every example source, and one unity file per test folder
# (SMG_UNITY_BUILD, tests/CMakeLists.txt) that includes each of the folder's test files, so every
# test file is checked in the same compiler run the build makes; --header-filter adds tests/ so
# that findings in those included files are reported like findings in a main file.
# examples/torch (the PyTorch extension) is left out: it is not configured here (torch optional).
/usr/bin/env python3 - "$build/compile_commands.json" > "$build/lint_files.txt" <<'PY'
import json, os, sys
for f in sorted({os.path.normpath(e["file"]) for e in json.load(open(sys.argv[1]))}):
    if "/tests/consumer/" not in f and "/examples/torch/" not in f:
        print(f)
PY
[ -s "$build/lint_files.txt" ] || { echo "lint: no translation units in $build/compile_commands.json" >&2; exit 1; }
echo "clang-tidy: $(wc -l < "$build/lint_files.txt") translation units"
xargs -P "$(nproc)" -I{} bash -c '
    # A unity file includes .cpp files by design: bugprone-suspicious-include is off for it alone.
    case "$2" in */Unity/*) extra=--checks=-bugprone-suspicious-include ;; *) extra= ;; esac
    out=$(clang-tidy -p "$1" --quiet --extra-arg=-std=c++17 $extra \
          --header-filter=".*/(include/smg|examples|tests)/.*" "$2" 2>/dev/null) && exit 0
    printf "%s\nclang-tidy: findings in %s\n" "$out" "$2"; exit 1' _ "$build" {} < "$build/lint_files.txt"
