#!/usr/bin/env bash
# scripts/ladder.sh [--seeds "0 1 2 3 4"] [--jobs J] [--out DIR] [--doc docs/results.md]
#                   [--section NAME] [--report-only] [-- TRAINER_FLAGS...]
#
#   scripts/ladder.sh --jobs 2                                  the standard scene -> section standard
#   scripts/ladder.sh --jobs 2 --out build/ladder_occluder -- --scene occluder   -> section occluder
#
# The ablation ladder (the paper's Table 5): runs smg_trainer for every variant (base, mosca,
# smg-only, no-carap, no-lrm, full) on every seed with the same flags, keeps each run's
# metrics.json under OUT/<variant>_s<seed>/, and writes the tables (means with 95 % confidence
# intervals, paired per-seed differences; scripts/ladder_report.py) into the section NAME of the
# results page, whatever they show. The flags after `--` go to every run unchanged (for example
# `--scene occluder`) and are recorded in the page with the machine and the date.
# --section defaults to the scene's name: `standard`, or the value of `--scene` when that is the
# only trainer flag; with any other trainer flag it must be given, so that a run at other settings
# never overwrites a published ladder. The trainer is built into build/release
# (scripts/build_trainer.sh); after a report into docs/results.md the README's highlights are
# regenerated (bench/report.py --readme README.md).
#
# --jobs J runs J trainers at once, each with nproc/J threads (results do not depend on the thread
# count). A run whose OUT/<variant>_s<seed>/metrics.json exists with the same flags is not run
# again, so an interrupted ladder resumes, as long as a short canary run shows the trainer still
# computes what made them; --report-only only rewrites the page.
set -euo pipefail
cd "$(dirname "$0")/.."
seeds="0 1 2 3 4"
out=build/ladder
doc=docs/results.md
section=
jobs=1
report_only=0
while [[ $# -gt 0 ]]; do
  case "$1" in
    --seeds) seeds="$2"; shift 2 ;;
    --jobs) jobs="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --doc) doc="$2"; shift 2 ;;
    --section) section="$2"; shift 2 ;;
    --report-only) report_only=1; shift ;;
    --) shift; break ;;
    *) echo "ladder.sh: unknown argument '$1' (use -- before trainer flags)" >&2; exit 2 ;;
  esac
done
[[ "$jobs" =~ ^[1-9][0-9]*$ ]] || { echo "ladder.sh: --jobs must be a positive integer, got '$jobs'" >&2; exit 2; }
flags=("$@")
if [[ -z "$section" ]]; then
  if [[ ${#flags[@]} -eq 0 ]]; then
    section=standard
  elif [[ ${#flags[@]} -eq 2 && "${flags[0]}" == --scene ]]; then
    section=${flags[1]}
  elif [[ ${#flags[@]} -eq 1 && "${flags[0]}" == --scene=* ]]; then
    section=${flags[0]#--scene=}
  else
    echo "ladder.sh: trainer flags '${flags[*]}' need --section NAME (the section of $doc to write)" >&2
    exit 2
  fi
fi
variants="base mosca smg-only no-carap no-lrm full"
if [[ $report_only == 0 ]]; then
  scripts/deps.sh python3
  scripts/build_trainer.sh
  build=${SMG_BUILD_DIR:-build/release}
  threads=$(( $(nproc) / jobs )); (( threads >= 1 )) || threads=1
  mkdir -p "$out"
  # The runs kept in OUT are reused only while the trainer still computes what made them: the
  # studies' canary (scripts/ladder_report.py check_cache; stops naming the figure that differs).
  python3 -c 'import sys; sys.path.insert(0, "scripts"); import ladder_report as r; r.check_cache(sys.argv[1], sys.argv[2])' \
    "$build/examples/smg_trainer" "$out"
  todo=()
  for seed in $seeds; do
    for v in $variants; do
      dir="$out/${v}_s${seed}"
      if [[ -f "$dir/metrics.json" && -f "$dir/flags.txt" && "$(cat "$dir/flags.txt")" == "${flags[*]:-}" ]]; then
        continue
      fi
      todo+=("$v $seed")
    done
  done
  echo "ladder: ${#todo[@]} runs, $jobs at a time with $threads threads each" >&2
  # Flags travel as one word-split string (trainer flags and values hold no spaces).
  export LADDER_BIN="$build/examples/smg_trainer" LADDER_OUT="$out" LADDER_THREADS="$threads" \
         LADDER_FLAGS="${flags[*]:-}"
  printf '%s\n' "${todo[@]+"${todo[@]}"}" | xargs -r -P "$jobs" -L 1 bash -c '
    v=$1; seed=$2; dir="$LADDER_OUT/${v}_s${seed}"
    echo "ladder: variant $v, seed $seed $LADDER_FLAGS" >&2
    # shellcheck disable=SC2086
    "$LADDER_BIN" --variant "$v" --seed "$seed" --threads "$LADDER_THREADS" --out "$dir" --quiet --no-pictures --no-view \
      $LADDER_FLAGS > "$dir.json" && printf "%s" "$LADDER_FLAGS" > "$dir/flags.txt"' _
fi
python3 scripts/ladder_report.py --out "$out" --doc "$doc" --section "$section" --seeds "$seeds" \
  --variants "$variants" --flags "${flags[*]:-}" --jobs "$jobs"
if [[ "$doc" == docs/results.md ]]; then
  python3 bench/report.py --readme README.md
fi
