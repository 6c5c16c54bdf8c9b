#!/usr/bin/env bash
# scripts/test.sh — build everything (library checks, tests, examples, benchmarks) with
# -Wall -Wextra -Wpedantic -Werror and run the test suite. README's test command.
#
#   scripts/test.sh              Release build in build/release, run all tests
#   scripts/test.sh --sanitize   AddressSanitizer + UndefinedBehaviorSanitizer build in
#                                build/asan (tests and examples only; Clang), run all tests
#
# The Release mode also compiles the CUDA tests (tests/cuda) where nvcc exists: test_cuda runs the
# GPU kernels against the CPU on a machine with a CUDA device and prints one "skipped" line
# without one. The sanitizer build leaves CUDA out.
# The Release mode also builds the PyTorch extension (examples/torch) and runs tests/torch with
# Debian's /usr/bin/python3 when libtorch-dev, pybind11-dev, python3-torch and python3-pytest
# are installed (one line says so when they are not); the sanitizer build never builds it.
set -euo pipefail
cd "$(dirname "$0")/.."
mode=release
for arg in "$@"; do
  case "$arg" in
    --sanitize) mode=asan ;;
    *) echo "usage: scripts/test.sh [--sanitize]" >&2; exit 2 ;;
  esac
done
scripts/deps.sh cmake make g++ libeigen3-dev doctest-dev libbenchmark-dev libstb-dev zlib1g-dev libpng-dev libjpeg62-turbo-dev
# Headless Chromium for the view.html and PLY viewer tests (tests/pipeline/test_view_html.py,
# tests/ply_viewer/test_ply_viewer.py, which also needs npm and the npm registry); optional:
# without it (not root, or no package) those tests print one "skipped" line.
scripts/deps.sh chromium >/dev/null 2>&1 || echo "smg: chromium is not installed: the view.html and PLY viewer browser tests will be skipped"
# numpy and meshio read the trainer's PLY files (tests/pipeline/test_ply_readers.py); optional too.
scripts/deps.sh python3-numpy python3-meshio >/dev/null 2>&1 || echo "smg: python3-numpy/python3-meshio not installed: the PLY readers test skips or reads with numpy only"
jobs=$(nproc)
if [ "$mode" = asan ]; then
  build=${SMG_BUILD_DIR:-build/asan}
  # -O1 -g1: the sanitizers need some optimisation to run the tests at speed, but -O2 -g made this
  # build 2.4x slower to compile (216 against 89 CPU-seconds for tests/energy/test_autodiff.cpp);
  # -g1 keeps the file:line of every frame in a sanitizer report.
  # Clang compiles this build: the Release build is GCC's, so the sanitizer build makes Clang the
  # second compiler whose -Werror the code passes, and Clang instruments for ASan+UBSan in about a
  # quarter less CPU time than GCC (tests/energy's unity file: 127 against 192 CPU-seconds).
  # Without Clang (and not root to install it) it falls back to GCC, saying so.
  cxx=()
  if scripts/deps.sh clang libclang-rt-dev && command -v clang++ >/dev/null; then
    cxx=(-DCMAKE_CXX_COMPILER=clang++)
  else
    echo "smg: clang++ not available: the sanitizer build uses the default C++ compiler"
  fi
  cmake -S . -B "$build" "${cxx[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
        -DSMG_WERROR=ON -DSMG_SANITIZE=ON -DSMG_BUILD_BENCH=OFF -DSMG_BUILD_TORCH=OFF -DSMG_BUILD_CUDA=OFF
  export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}
  export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
else
  build=${SMG_BUILD_DIR:-build/release}
  # The project's one build folder, which scripts/example.sh (scripts/build_trainer.sh) may have
  # configured first without the tests and benchmarks: every part is turned on here.
  all=(-DSMG_BUILD_TESTS=ON -DSMG_BUILD_EXAMPLES=ON -DSMG_BUILD_BENCH=ON)
  # PyTorch extension: only with Debian's python3 + torch + pytest (the python3 first on PATH may
  # lack torch). CMake turns SMG_BUILD_TORCH on by itself when libtorch-dev and pybind11 exist.
  torch_py=/usr/bin/python3
  torch_ok=0
  if [ -x "$torch_py" ] && "$torch_py" -c "import torch, pytest" >/dev/null 2>&1; then
    torch_ok=1
  fi
  if [ "$torch_ok" = 1 ]; then
    cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSMG_WERROR=ON "${all[@]}" -DPython3_EXECUTABLE="$torch_py"
  else
    cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DSMG_WERROR=ON "${all[@]}" -DSMG_BUILD_TORCH=OFF
  fi
fi
cmake --build "$build" -j"$jobs"
ctest_skip=()
if [ "$mode" = asan ]; then
  # The browser test checks view.html in Chromium; the trainer run it makes is the one
  # test_pipeline runs under the sanitizers, so here it would only add about 70 s.
  ctest_skip=(-E '^view_html$')
fi
# tests/torch (Release, where the extension was built) runs next to ctest: ctest -j keeps about
# 1.2 of 2 cores busy (its browser and Python tests wait), and pytest is mostly one process, so
# running them one after the other left a core idle for about 25 s. Its output is printed after.
torch_pid=
if [ "$mode" = release ]; then
  if [ "$torch_ok" = 1 ] && [ -f "$build/python/smg_torch/__init__.py" ] &&
     ls "$build"/python/smg_torch/_C*.so >/dev/null 2>&1; then
    case "$build" in /*) pybuild=$build ;; *) pybuild=$PWD/$build ;; esac
    PYTHONPATH="$pybuild/python${PYTHONPATH:+:$PYTHONPATH}" "$torch_py" -m pytest -q -p no:cacheprovider tests/torch \
      > "$build/pytest_torch.log" 2>&1 &
    torch_pid=$!
  else
    echo "smg: tests/torch skipped (needs /usr/bin/python3 with torch and pytest, libtorch-dev, pybind11-dev)"
  fi
fi
ctest_rc=0
ctest --test-dir "$build" -j"$jobs" --output-on-failure "${ctest_skip[@]}" || ctest_rc=$?
if [ -n "$torch_pid" ]; then
  rc=0
  wait "$torch_pid" || rc=$?
  echo "smg: tests/torch (PyTorch extension, $torch_py -m pytest)"
  cat "$build/pytest_torch.log"
  # 5: no tests collected — not a failure.
  if [ "$rc" -ne 0 ] && [ "$rc" -ne 5 ]; then exit "$rc"; fi
fi
exit "$ctest_rc"
