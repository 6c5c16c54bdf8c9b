#!/usr/bin/env bash
# scripts/example.sh [ARGS...] — build and run the example (README's first command).
# Only the library's own dependencies are needed (no doctest, no Google Benchmark).
# Until the scene trainer lands, this runs the core tour.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh cmake make g++ libeigen3-dev libstb-dev
build=${SMG_BUILD_DIR:-build/example}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSMG_BUILD_TESTS=OFF -DSMG_BUILD_BENCH=OFF \
      -DSMG_BUILD_EXAMPLES=ON >/dev/null
cmake --build "$build" -j"$(nproc)" --target core_tour
exec "$build/examples/core_tour" "$@"
