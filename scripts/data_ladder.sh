#!/usr/bin/env bash
# scripts/data_ladder.sh SCENE [--out DIR] [--variants "base ... full"] [-- TRAINER_FLAGS...]
#
# Runs smg_trainer --data SCENE for every variant of the ablation ladder (base, mosca, smg-only,
# no-carap, no-lrm, full) with the same flags and prints one Markdown table: Dycheck's mPSNR and
# mSSIM over the validation frames, and the 3D EPE / fractions within 5 and 10 cm when SCENE holds
# queries.json and queries_tracks3d.npy (what smg_trainer --export-dycheck writes), plus nodes,
# seconds and peak memory. Each run's metrics.json stays under OUT/<variant>/ (docs/data.md;
# default OUT: build/data_ladder). The trainer is built into build/release (scripts/build_trainer.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
[[ $# -ge 1 ]] || { echo "usage: scripts/data_ladder.sh SCENE [--out DIR] [--variants LIST] [-- FLAGS]" >&2; exit 2; }
scene="$1"; shift
out=build/data_ladder
variants="base mosca smg-only no-carap no-lrm full"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --out) out="$2"; shift 2 ;;
    --variants) variants="$2"; shift 2 ;;
    --) shift; break ;;
    *) echo "data_ladder.sh: unknown argument '$1' (use -- before trainer flags)" >&2; exit 2 ;;
  esac
done
flags=("$@")
scripts/deps.sh python3
scripts/build_trainer.sh >/dev/null
build=${SMG_BUILD_DIR:-build/release}
queries=()
if [[ -f "$scene/queries.json" && -f "$scene/queries_tracks3d.npy" ]]; then
  queries=(--track-queries "$scene/queries.json" --track-truth "$scene/queries_tracks3d.npy")
fi
mkdir -p "$out"
for v in $variants; do
  echo "data_ladder: variant $v on $scene ${flags[*]:-}" >&2
  "$build/examples/smg_trainer" --data "$scene" --variant "$v" --out "$out/$v" --quiet "${queries[@]}" \
    "${flags[@]}" > /dev/null
done
python3 - "$out" "$variants" <<'PY'
import json, sys
out, variants = sys.argv[1], sys.argv[2].split()
print("| variant | mPSNR (dB) | mSSIM | mSSIM covisible | 3D EPE (m) | δ5cm | δ10cm | nodes | stage 2 (s) | total (s) | peak MiB |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for v in variants:
    m = json.load(open(f"{out}/{v}/metrics.json"))
    f = lambda k, p: (f"{m[k]:.{p}f}" if k in m else "—")
    print(f"| {v} | {f('mpsnr',2)} | {f('mssim',4)} | {f('mssim_covisible',4)} | {f('epe',4)} | {f('delta_5cm',3)} | "
          f"{f('delta_10cm',3)} | {m['nodes']} | {f('seconds_stage2',1)} | {f('seconds_total',1)} | {f('peak_memory_mib',0)} |")
PY
