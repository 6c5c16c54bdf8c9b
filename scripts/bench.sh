#!/usr/bin/env bash
# scripts/bench.sh [--smoke] [MODULE...] — build and run the Google Benchmark suite.
#
#   scripts/bench.sh              run every bench/bench_<module>, store JSON in
#                                 bench/results/<module>.json, regenerate docs/performance.md
#   scripts/bench.sh core graph   only those modules (the report still merges all results)
#   scripts/bench.sh --smoke      run every benchmark very briefly into build/, check the
#                                 report generator; results and docs are not touched (CI)
set -euo pipefail
cd "$(dirname "$0")/.."
smoke=0
modules=()
for arg in "$@"; do
  case "$arg" in
    --smoke) smoke=1 ;;
    -*) echo "usage: scripts/bench.sh [--smoke] [MODULE...]" >&2; exit 2 ;;
    *) modules+=("$arg") ;;
  esac
done
scripts/deps.sh cmake make g++ libeigen3-dev doctest-dev libbenchmark-dev libstb-dev python3
build=${SMG_BUILD_DIR:-build/release}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSMG_WERROR=ON >/dev/null
cmake --build "$build" -j"$(nproc)"
if [ ${#modules[@]} -eq 0 ]; then
  for exe in "$build"/bench/bench_*; do
    [ -x "$exe" ] && modules+=("$(basename "$exe" | sed 's/^bench_//')")
  done
fi
if [ "$smoke" = 1 ]; then
  out=$build/bench-smoke
  extra=(--benchmark_min_time=0.001)
else
  out=bench/results
  extra=()
fi
mkdir -p "$out"
for m in "${modules[@]}"; do
  exe="$build/bench/bench_$m"
  [ -x "$exe" ] || { echo "no benchmark executable $exe" >&2; exit 2; }
  echo "== bench_$m"
  "$exe" "${extra[@]}" --benchmark_out="$out/$m.json" --benchmark_out_format=json
done
if [ "$smoke" = 1 ]; then
  python3 bench/report.py "$out" > "$out/performance.md"
  echo "smoke run ok: report written to $out/performance.md"
else
  python3 bench/report.py bench/results > docs/performance.md
  echo "docs/performance.md regenerated from bench/results/*.json"
fi
