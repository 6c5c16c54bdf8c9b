#!/usr/bin/env bash
# scripts/example.sh [TRAINER_FLAGS...] — the README's first command: builds the example scene
# trainer into build/release (scripts/build_trainer.sh) and runs it (docs/trainer.md). With no
# flags: the default run (the full SMG variant, seed 0, 32 frames at 160x120; about 1 minute on
# 2 cores), pictures and metrics.json in trainer_out/. `scripts/example.sh --quick` is the small
# run CI uses; `--help` lists the flags. Only the library's own dependencies and Debian's
# libstb-dev (PNG output), zlib1g-dev (.npz reading), libpng-dev and libjpeg62-turbo-dev (reading
# scene images) are needed: cmake make g++ libeigen3-dev libstb-dev zlib1g-dev libpng-dev
# libjpeg62-turbo-dev.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/build_trainer.sh
exec "${SMG_BUILD_DIR:-build/release}/examples/smg_trainer" "$@"
