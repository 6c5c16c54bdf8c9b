#!/usr/bin/env bash
# scripts/check_packaging.sh — prove the three ways of consuming smg:
#   1. cmake --install, then find_package(smg) from an out-of-tree project (tests/consumer), and
#      docs/quickstart.md's find_package command block run as written (examples/quickstart);
#      also the page's in-tree block (build/release, the four programs, ctest -R quickstart);
#   2. add_subdirectory(smg) from that project;
#   3. copying include/ next to Eigen: README's "By copying the headers" command block run as written
#      on a quick-start program, and a plain compiler call on tests/consumer;
#   4. the pip route to smg_torch (docs/torch.md's "pip" block: a venv that sees Debian's torch,
#      pip install --no-build-isolation ./examples/torch, import), then tests/torch/test_energy.py
#      against the installed package. Skipped with one line where /usr/bin/python3 has no torch
#      or no venv module (scripts/deps.sh python3-torch python3-venv, as root).
# The command blocks are the fenced blocks after "<!-- run: NAME -->" in those pages; they run
# in a fresh copy of the repository's tracked files (git ls-files) with HOME in a scratch folder.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh cmake make g++ libeigen3-dev
# Every `cmake --build` below, the documented blocks' included, builds on all cores (the
# quick-start route builds four programs).
export CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-$(nproc)}
root=$(pwd)
work=$(mktemp -d)
# The pip route runs in the background (below): on any exit its process tree is stopped before
# the scratch folder it writes into is removed.
pip_pid=
kill_tree() { local c; for c in $(cat /proc/"$1"/task/*/children 2>/dev/null); do kill_tree "$c"; done; kill "$1" 2>/dev/null || true; }
trap '[ -n "$pip_pid" ] && kill_tree "$pip_pid"; wait 2>/dev/null; rm -rf "$work"' EXIT

# The command block after "<!-- run: NAME -->" in a markdown page.
run_block() {  # page name
  awk -v mark="<!-- run: $2 -->" '
    $0 == mark { armed = 1; next }
    armed && /^```/ { if (inside) exit; inside = 1; next }
    inside { print }' "$1"
}
# A fresh copy of the tracked files: what a new clone has.
mkdir -p "$work/fresh/smg" "$work/home"
git ls-files -z | (cd "$root" && xargs -0 cp --parents -t "$work/fresh/smg")

# 4. The pip route, as docs/torch.md shows it, in the fresh copy (the build's files stay there).
# Cheaper than the documented default and the same route: CFLAGS=-g0 drops the -g that Debian's
# Python adds, SMG_TORCH_OPT=-O1 replaces -O3 (setup.py), MAX_JOBS = the cores (ninja's jobs).
# Measured on smg_torch_energy.cpp, CPU-seconds: 53 as documented, 36 with -g0, 24 with -g0 -O1.
# setup.py compiles the C++ sources as one file (87 CPU-s for the module at -g0 -O1, against 143
# as five), one compiler on one core: so the route runs in the background from here, beside
# routes 1-3, which mostly keep one core busy, and its lines are printed at the end. It starts
# first: on its own it is the longest route (113 s in CI's stage 3, against about 35 s for the rest).
pip_route() {
  scripts/deps.sh python3-venv >/dev/null 2>&1 || true
  if /usr/bin/python3 -c "import torch" >/dev/null 2>&1 && /usr/bin/python3 -m venv "$work/venv-probe" >/dev/null 2>&1; then
    block=$(run_block docs/torch.md pip)
    [ -n "$block" ] || { echo "packaging: docs/torch.md has no pip block" >&2; exit 1; }
    t0=$(date +%s)
    (cd "$work/fresh/smg" && HOME="$work/home" CFLAGS=-g0 SMG_TORCH_OPT=-O1 MAX_JOBS="$(nproc)" PYTHONPATH= \
       bash -euo pipefail -c "$block") >"$work/pip.log" 2>&1 ||
      { cat "$work/pip.log"; echo "packaging: docs/torch.md pip block failed" >&2; exit 1; }
    where=$(cd "$work/fresh/smg" && PYTHONPATH= V/bin/python3 -c "import smg_torch; print(smg_torch.__file__)")
    case "$where" in
      "$work/fresh/smg/V/"*) ;;
      *) echo "packaging: the venv imported smg_torch from $where, not from its own site-packages" >&2; exit 1 ;;
    esac
    if /usr/bin/python3 -c "import pytest" >/dev/null 2>&1; then
      (cd "$work/fresh/smg" && PYTHONPATH= V/bin/python3 -m pytest -q -p no:cacheprovider tests/torch/test_energy.py) \
        >"$work/pip-test.log" 2>&1 || { cat "$work/pip-test.log"; echo "packaging: tests/torch/test_energy.py failed against the pip-installed smg_torch" >&2; exit 1; }
      tested=", tests/torch/test_energy.py: $(tail -n 1 "$work/pip-test.log")"
    else
      tested=" (python3-pytest missing: tests/torch/test_energy.py not run)"
    fi
    echo "packaging: docs/torch.md pip route (venv, --no-build-isolation, import smg_torch from $where): ok in $(( $(date +%s) - t0 ))s$tested"
  else
    echo "packaging: pip route skipped: /usr/bin/python3 lacks torch or venv (scripts/deps.sh python3-torch python3-venv)"
  fi
}
(pip_route > "$work/pip.out" 2>&1) &
pip_pid=$!

cmake -S . -B "$work/build" -DSMG_BUILD_TESTS=OFF -DSMG_BUILD_EXAMPLES=OFF -DSMG_BUILD_BENCH=OFF \
      -DSMG_BUILD_TORCH=OFF >/dev/null
cmake --install "$work/build" --prefix "$work/prefix" >/dev/null
cmake -S tests/consumer -B "$work/consumer-installed" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
cmake --build "$work/consumer-installed" >/dev/null
"$work/consumer-installed/smg_consumer"
echo "packaging: find_package(smg) after cmake --install: ok"

cmake -S tests/consumer -B "$work/consumer-subdir" -DSMG_CONSUMER_USE_SUBDIRECTORY="$root" >/dev/null
cmake --build "$work/consumer-subdir" >/dev/null
"$work/consumer-subdir/smg_consumer"
echo "packaging: add_subdirectory(smg): ok"

mkdir -p "$work/copied"
cp -r include "$work/copied/include"
g++ -std=c++17 -Wall -Wextra -Wpedantic -Werror -I"$work/copied/include" -I/usr/include/eigen3 \
    tests/consumer/main.cpp -o "$work/copied/smg_consumer" -pthread
"$work/copied/smg_consumer"
echo "packaging: copied include/ + Eigen: ok"


block=$(run_block docs/quickstart.md find_package)
[ -n "$block" ] || { echo "packaging: docs/quickstart.md has no find_package block" >&2; exit 1; }
(cd "$work/fresh/smg" && HOME="$work/home" bash -euo pipefail -c "$block") >"$work/qs.log" 2>&1 ||
  { cat "$work/qs.log"; echo "packaging: docs/quickstart.md find_package block failed" >&2; exit 1; }
for p in views energies dqb render; do
  "$work/fresh/smg/build/quickstart/quickstart_$p" | tail -n 1 | grep -qx "quickstart $p: ok"
done
echo "packaging: docs/quickstart.md find_package route (examples/quickstart, 4 programs): ok"

# docs/quickstart.md's in-tree block, as written. By default in the fresh copy, where build/release
# is a new folder (the whole project configured, the four programs built). SMG_REUSE_BUILD=1 runs
# it in the repository root instead, on the build/release an earlier step made (CI: stage 1's), so
# it costs a reconfigure, four up-to-date targets and four short tests. That the block builds
# every program its `ctest -R` selects, which only a fresh folder would show, check_docs checks.
block=$(run_block docs/quickstart.md in-tree)
[ -n "$block" ] || { echo "packaging: docs/quickstart.md has no in-tree block" >&2; exit 1; }
if [ "${SMG_REUSE_BUILD:-0}" = 1 ]; then where=$root; else where=$work/fresh/smg; fi
t0=$(date +%s)
(cd "$where" && HOME="$work/home" bash -euo pipefail -c "$block") >"$work/intree.log" 2>&1 ||
  { cat "$work/intree.log"; echo "packaging: docs/quickstart.md in-tree block failed (in $where)" >&2; exit 1; }
grep -qx "quickstart energies: ok" "$work/intree.log" ||
  { cat "$work/intree.log"; echo "packaging: docs/quickstart.md in-tree block: quickstart_energies did not print its ok line" >&2; exit 1; }
grep -q "100% tests passed, 0 tests failed out of 4" "$work/intree.log" ||
  { cat "$work/intree.log"; echo "packaging: docs/quickstart.md in-tree block: ctest did not run the 4 quick-start tests" >&2; exit 1; }
echo "packaging: docs/quickstart.md in-tree block (in $where): ok in $(( $(date +%s) - t0 ))s"

block=$(run_block README.md "copied headers")
[ -n "$block" ] || { echo "packaging: README.md has no copied-headers block" >&2; exit 1; }
mkdir -p "$work/fresh/my_project"
cp examples/quickstart/energies.cpp "$work/fresh/my_project/main.cpp"
(cd "$work/fresh" && HOME="$work/home" bash -euo pipefail -c "$block") ||
  { echo "packaging: README.md copied-headers block failed" >&2; exit 1; }
"$work/fresh/my_project/main" | tail -n 1 | grep -qx "quickstart energies: ok"
echo "packaging: README.md copied-headers route, as written: ok"

pip_rc=0
wait "$pip_pid" || pip_rc=$?
pip_pid=
cat "$work/pip.out"
exit "$pip_rc"
