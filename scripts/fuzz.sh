#!/usr/bin/env bash
# scripts/fuzz.sh MINUTES [READER...] — runs each libFuzzer harness of tests/fuzz (all of them, or
# the READERs named: npy npz json png jpeg colmap scene) for MINUTES minutes (a decimal such as
# 0.5 is fine), one after the other, under ASan + UBSan, and prints a table: reader, runs,
# minutes, findings. Builds them first into build/fuzz with Clang (-fsanitize=fuzzer; Debian's
# clang and libclang-rt-dev, installed by scripts/deps.sh as root).
#
# Each harness starts from its seed corpus tests/fuzz/corpus/<reader>/ (read only) and keeps what
# it adds in build/fuzz/work/<reader>/corpus/. A finding (a crash, a sanitizer report, a leak, an
# input slower than 10 s, an allocation over 1 GB or 2 GB of memory in all) is saved as
# build/fuzz/work/<reader>/crash-* (oom-*, leak-*, timeout-*): reproduce it with
# `build/fuzz/tests/fuzz/fuzz_<reader> FILE`, fix the reader, then copy the file into
# tests/fuzz/corpus/<reader>/ as regression-<what>, where ctest's fuzz_replay tests replay it in
# every build. Exits 1 when anything was found.
set -euo pipefail
cd "$(dirname "$0")/.."
all=(npy npz json png jpeg colmap scene)
if [ $# -lt 1 ] || ! [[ "$1" =~ ^[0-9]+([.][0-9]+)?$ ]]; then
  echo "usage: scripts/fuzz.sh MINUTES [READER...]   (readers: ${all[*]})" >&2
  exit 2
fi
minutes=$1
shift
readers=("$@")
[ ${#readers[@]} -eq 0 ] && readers=("${all[@]}")
for r in "${readers[@]}"; do
  [ -d "tests/fuzz/corpus/$r" ] || { echo "scripts/fuzz.sh: no harness '$r' (readers: ${all[*]})" >&2; exit 2; }
done
seconds=$(awk -v m="$minutes" 'BEGIN { s = int(m * 60 + 0.5); print (s < 1 ? 1 : s) }')
scripts/deps.sh cmake make clang libclang-rt-dev libeigen3-dev doctest-dev libstb-dev zlib1g-dev libpng-dev libjpeg62-turbo-dev
build=${SMG_FUZZ_BUILD_DIR:-build/fuzz}
# Every translation unit with libFuzzer's coverage (fuzzer-no-link), the harnesses linked with
# libFuzzer's main (tests/fuzz/CMakeLists.txt); -O1 -g1 as the sanitizer build.
cmake -S . -B "$build" -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" -DCMAKE_CXX_FLAGS="-fsanitize=fuzzer-no-link" \
      -DSMG_SANITIZE=ON -DSMG_BUILD_FUZZ=ON -DSMG_BUILD_TESTS=ON -DSMG_BUILD_EXAMPLES=OFF -DSMG_BUILD_BENCH=OFF \
      -DSMG_BUILD_TORCH=OFF -DSMG_BUILD_CUDA=OFF >/dev/null
targets=()
for r in "${readers[@]}"; do targets+=(--target "fuzz_$r"); done
cmake --build "$build" -j"$(nproc)" "${targets[@]}"
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
found=0
table="| reader | runs | minutes | findings |\n|---|---:|---:|---:|\n"
for r in "${readers[@]}"; do
  work=$build/work/$r
  mkdir -p "$work/corpus"
  touch "$work/.start"  # findings of this run only: artifacts newer than this
  log=$work/fuzz.log
  echo "scripts/fuzz.sh: $r for $seconds s (log: $log)"
  rc=0
  "$build/tests/fuzz/fuzz_$r" "$work/corpus" "tests/fuzz/corpus/$r" -max_total_time="$seconds" -timeout=10 \
      -rss_limit_mb=2048 -malloc_limit_mb=1024 -print_final_stats=1 -artifact_prefix="$work/" >"$log" 2>&1 || rc=$?
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  findings=$(find "$work" -maxdepth 1 -type f -newer "$work/.start" \( -name 'crash-*' -o -name 'oom-*' -o -name 'leak-*' -o -name 'timeout-*' \) | wc -l)
  if [ "$rc" -ne 0 ] && [ "$findings" -eq 0 ]; then findings=1; fi  # stopped without an artifact: see the log
  [ "$findings" -gt 0 ] && found=1 && tail -n 30 "$log"
  table+="| $r | ${runs:-?} | $minutes | $findings |\n"
done
printf "%b" "$table"
exit "$found"
