#!/usr/bin/env bash
# scripts/check_packaging.sh — prove the three ways of consuming smg:
#   1. cmake --install, then find_package(smg) from an out-of-tree project (tests/consumer);
#   2. add_subdirectory(smg) from that project;
#   3. copying include/ next to Eigen: a plain compiler call, no CMake.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh cmake make g++ libeigen3-dev
root=$(pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

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
