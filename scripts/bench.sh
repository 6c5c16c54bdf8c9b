#!/usr/bin/env bash
# scripts/bench.sh [options] [MODULE...] [-- ARGS...] — build and run the Google Benchmark suite.
#
#   scripts/bench.sh                 run every bench/bench_<module> into build/bench-results/
#                                    (<module>.json, <module>.load, performance.md); the committed
#                                    bench/results and docs/performance.md are not touched
#   scripts/bench.sh core energy     only those modules
#   --filter REGEX                   only the rows matching REGEX (--benchmark_filter)
#   --out DIR                        write results and the report to DIR instead
#   --reps N                         repetitions of every row (SMG_BENCH_REPS; report: median, min)
#   --tag TAG                        name the results <module>-TAG.json (a second size, say)
#   --publish                        also copy the results into bench/results/ and regenerate
#                                    docs/performance.md and the README's highlights from
#                                    bench/results/*.json
#   -- ARGS...                       pass the remaining arguments to every binary (e.g.
#                                    --benchmark_enable_random_interleaving=true, --n=20000)
#   --smoke                          every row very briefly, 1 repetition, smaller autodiff and
#                                    splatter problems, into build/bench-smoke; checks the
#                                    report generator (CI)
#
# Problem sizes, gaps, threads and precision are the binaries' run-time parameters, passed as
# SMG_BENCH_* environment variables (bench/README.md), e.g. C-ARAP at N = 20000, T = 50, K = 8,
# gap 1, float only, published beside the default size:
#
#   SMG_BENCH_N=20000 SMG_BENCH_T=50 SMG_BENCH_K=8 SMG_BENCH_GAPS=1 SMG_BENCH_PRECISION=float \
#     scripts/bench.sh --tag large --filter 'carap' energy
set -euo pipefail
cd "$(dirname "$0")/.."
usage() {
  sed -n '2,26p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
}
smoke=0 publish=0 filter='' out='' tag='' reps=''
modules=() passthrough=()
while [ $# -gt 0 ]; do
  case "$1" in
    --smoke) smoke=1 ;;
    --publish) publish=1 ;;
    --filter) [ $# -ge 2 ] || usage; filter=$2; shift ;;
    --filter=*) filter=${1#--filter=} ;;
    --out) [ $# -ge 2 ] || usage; out=$2; shift ;;
    --out=*) out=${1#--out=} ;;
    --tag) [ $# -ge 2 ] || usage; tag=$2; shift ;;
    --tag=*) tag=${1#--tag=} ;;
    --reps) [ $# -ge 2 ] || usage; reps=$2; shift ;;
    --reps=*) reps=${1#--reps=} ;;
    -h|--help) usage ;;
    --) shift; passthrough=("$@"); break ;;
    -*) echo "scripts/bench.sh: unknown option $1" >&2; usage ;;
    *) modules+=("$1") ;;
  esac
  shift
done
if [ "$smoke" = 1 ] && [ "$publish" = 1 ]; then
  echo "scripts/bench.sh: --smoke results are not publishable" >&2
  exit 2
fi
scripts/deps.sh cmake make g++ libeigen3-dev doctest-dev libbenchmark-dev libstb-dev zlib1g-dev libpng-dev libjpeg62-turbo-dev python3
build=${SMG_BUILD_DIR:-build/release}
# -DSMG_BUILD_BENCH=ON: build/release may have been configured first by scripts/example.sh without it.
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSMG_WERROR=ON -DSMG_BUILD_BENCH=ON >/dev/null
if [ ${#modules[@]} -eq 0 ]; then
  for src in bench/bench_*.cpp; do modules+=("$(basename "$src" .cpp | sed 's/^bench_//')"); done
fi
targets=()
for m in "${modules[@]}"; do
  [ -f "bench/bench_$m.cpp" ] || { echo "scripts/bench.sh: no benchmark bench/bench_$m.cpp" >&2; exit 2; }
  targets+=("bench_$m")
done
cmake --build "$build" -j"${SMG_BENCH_JOBS:-$(nproc)}" --target "${targets[@]}"

extra=()
if [ "$smoke" = 1 ]; then
  out=${out:-$build/bench-smoke}
  extra+=(--benchmark_min_time=0.001)
  export SMG_BENCH_REPS=${reps:-1}
  # Smaller problems where the default ones take most of a minute: autodiff on 2 frames, the
  # splatter at 10k Gaussians (the caller's SMG_BENCH_* values win).
  export SMG_BENCH_AD_FRAMES=${SMG_BENCH_AD_FRAMES:-2}
  export SMG_BENCH_G=${SMG_BENCH_G:-10000} SMG_BENCH_KNOB_G=${SMG_BENCH_KNOB_G:-10000}
else
  out=${out:-build/bench-results}
  [ -z "$reps" ] || export SMG_BENCH_REPS=$reps
fi
[ -z "$filter" ] || extra+=("--benchmark_filter=$filter")
extra+=(${passthrough[@]+"${passthrough[@]}"})
mkdir -p "$out"
for m in "${modules[@]}"; do
  name=$m${tag:+-$tag}
  echo "== bench_$m -> $out/$name.json"
  {
    echo "loadavg_before $(cut -d' ' -f1-3 /proc/loadavg)"
    echo "nproc $(nproc)"
  } > "$out/$name.load"
  "$build/bench/bench_$m" ${extra[@]+"${extra[@]}"} --benchmark_out="$out/$name.json" --benchmark_out_format=json
  echo "loadavg_after $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/$name.load"
done
python3 bench/report.py "$out" > "$out/performance.md"
echo "report written to $out/performance.md"
if [ "$publish" = 1 ]; then
  mkdir -p bench/results
  for m in "${modules[@]}"; do
    name=$m${tag:+-$tag}
    cp "$out/$name.json" "$out/$name.load" bench/results/
  done
  python3 bench/report.py bench/results > docs/performance.md
  python3 bench/report.py --readme README.md bench/results
  echo "published: bench/results/ updated, docs/performance.md and the README's highlights regenerated"
fi
