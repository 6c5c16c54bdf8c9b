#!/usr/bin/env bash
# scripts/device_check.sh — the GPU checks of one lent device session, as one prepared run
# (docs/cuda.md, "Tests"; not part of CI, which has no GPU). It runs on the device machine, in a
# copy of the working tree, with the headers the machine lacks carried in .dev/ (made here by
# `scripts/device_check.sh --prepare`: Eigen and doctest headers and two small CMake package
# files; .dev/ is ignored through .git/info/exclude). Every stage has its own time limit and
# writes its log under $OUT, so a stage that fails or runs over still leaves the others' output:
#   1. smg_torch with its CUDA operators (setup.py build_ext --inplace, in the background);
#   2. test_cuda (CMake + Ninja, the GPU suite and the cuda-host suite), then run;
#   3. tests/torch with the CUDA build (the CUDA tests run instead of skipping);
#   4. bench/torch/bench_compat.py --device cuda (smg, eager torch, torch.compile);
#   5. bench/torch/bench_cuda.py (the fused step and the operators against autograd).
# Usage (device tool): bash scripts/device_check.sh     with carry [".dev"]
#        here, once:   bash scripts/device_check.sh --prepare
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--prepare" ]; then
  grep -qx '/.dev/' .git/info/exclude 2>/dev/null || echo '/.dev/' >> .git/info/exclude
  rm -rf .dev && mkdir -p .dev/include .dev/cmake
  cp -r /usr/include/eigen3/Eigen /usr/include/eigen3/unsupported /usr/include/doctest .dev/include/
  cat > .dev/cmake/Eigen3Config.cmake <<'EOF'
set(EIGEN3_VERSION_STRING 3.4.0)
if(NOT TARGET Eigen3::Eigen)
  add_library(Eigen3::Eigen INTERFACE IMPORTED)
  set_target_properties(Eigen3::Eigen PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${CMAKE_CURRENT_LIST_DIR}/../include")
endif()
EOF
  printf 'set(PACKAGE_VERSION 3.4.0)\nset(PACKAGE_VERSION_COMPATIBLE TRUE)\n' > .dev/cmake/Eigen3ConfigVersion.cmake
  cat > .dev/cmake/doctestConfig.cmake <<'EOF'
if(NOT TARGET doctest::doctest)
  add_library(doctest::doctest INTERFACE IMPORTED)
  set_target_properties(doctest::doctest PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${CMAKE_CURRENT_LIST_DIR}/../include")
endif()
EOF
  echo "device_check: .dev prepared ($(du -sh .dev | cut -f1)); carry it: carry [\".dev\"]"
  exit 0
fi
OUT=${OUT:-/tmp/device_out}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1 PATH=/usr/local/cuda/bin:$PATH
dev=$PWD/.dev
[ -d "$dev/include/Eigen" ] || { echo "device_check: no .dev/include/Eigen: run --prepare here and carry .dev" >&2; exit 1; }
t0=$(date +%s)
stamp() { echo "[device_check $(( $(date +%s) - t0 )) s] $*"; }
{ nvidia-smi -L; nvcc --version | tail -2; python3 -c 'import torch; print("torch", torch.__version__, torch.version.cuda)'; nproc; } 2>&1 | tee "$OUT/machine.txt"
# A Python whose own libstdc++ is older than the compiler's (the H100 session's) needs the system one.
pre=""; [ -f /usr/lib/x86_64-linux-gnu/libstdc++.so.6 ] && pre=/usr/lib/x86_64-linux-gnu/libstdc++.so.6

stamp "1. smg_torch (CUDA) build, background"
( cd examples/torch && EIGEN3_INCLUDE_DIR=$dev/include TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=8 \
    timeout 330 python3 setup.py build_ext --inplace > "$OUT/torch_build.log" 2>&1; echo "rc=$?" >> "$OUT/torch_build.log" ) &
bpid=$!

stamp "2. test_cuda"
{ timeout 320 cmake -S . -B /tmp/b -G Ninja -DCMAKE_BUILD_TYPE=Release -DSMG_BUILD_EXAMPLES=OFF -DSMG_BUILD_BENCH=OFF \
    -DSMG_BUILD_TESTS=ON -DSMG_BUILD_TORCH=OFF -DSMG_BUILD_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90 -DEigen3_DIR=$dev/cmake -Ddoctest_DIR=$dev/cmake \
  && timeout 320 cmake --build /tmp/b --target test_cuda -j 8; } > "$OUT/test_cuda_build.log" 2>&1
echo "rc=$?" >> "$OUT/test_cuda_build.log"; tail -3 "$OUT/test_cuda_build.log"
exe=$(find /tmp/b -name test_cuda -type f -perm -u+x | head -1)
[ -n "$exe" ] && timeout 120 "$exe" > "$OUT/test_cuda.log" 2>&1; echo "rc=$?" >> "$OUT/test_cuda.log"; tail -4 "$OUT/test_cuda.log"

stamp "waiting for smg_torch"
wait $bpid; tail -3 "$OUT/torch_build.log"
export PYTHONPATH=$PWD/examples/torch
stamp "3. tests/torch"
LD_PRELOAD=$pre timeout 150 python3 -m pytest -q -p no:cacheprovider -rs tests/torch > "$OUT/pytest.log" 2>&1
echo "rc=$?" >> "$OUT/pytest.log"; tail -15 "$OUT/pytest.log"

stamp "4. bench_compat --device cuda"
LD_PRELOAD=$pre timeout 150 python3 bench/torch/bench_compat.py --device cuda --repeat 20 --json "$OUT/compat_cuda.json" 2>&1 | tee "$OUT/bench_compat.log"

stamp "5. bench_cuda"
LD_PRELOAD=$pre timeout 120 python3 bench/torch/bench_cuda.py --repeat 20 --json "$OUT/torch_cuda.json" 2>&1 | tee "$OUT/bench_cuda.log"
stamp done
