#!/usr/bin/env bash
# scripts/build_trainer.sh — build the example scene trainer (examples/trainer, target smg_trainer)
# in the project's one build folder, build/release (SMG_BUILD_DIR overrides it): the folder
# scripts/test.sh and scripts/bench.sh build, so every script and page uses
# build/release/examples/smg_trainer. A first configure from here leaves the tests and benchmarks
# out (the trainer needs neither doctest nor Google Benchmark); scripts/test.sh turns them on in
# the same folder. Used by scripts/example.sh, ladder.sh, data_ladder.sh and carap_study.py.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh cmake make g++ libeigen3-dev libstb-dev zlib1g-dev libpng-dev libjpeg62-turbo-dev
build=${SMG_BUILD_DIR:-build/release}
first=()
[ -f "$build/CMakeCache.txt" ] || first=(-DSMG_BUILD_TESTS=OFF -DSMG_BUILD_BENCH=OFF)
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSMG_BUILD_EXAMPLES=ON ${first[@]+"${first[@]}"} >/dev/null
cmake --build "$build" -j"$(nproc)" --target smg_trainer
