#!/usr/bin/env bash
# scripts/device_check.sh — the GPU checks of one lent device session, as one prepared run
# (docs/cuda.md, "Tests"; not part of CI, which has no GPU). It runs on the device machine, in a
# copy of the working tree, with the headers the machine lacks carried in .dev/ (made here by
# `scripts/device_check.sh --prepare`: Eigen's and doctest's headers; .dev/ is ignored through
# .git/info/exclude). Every stage has its own time limit and
# writes its log under $OUT, so a stage that fails or runs over still leaves the others' output:
#   1. smg_torch with its CUDA operators (setup.py build_ext --inplace, in the background);
#   2. test_cuda (nvcc per file: the GPU suite and the cuda-host suite), then run;
#   3. tests/torch with the CUDA build (the CUDA tests run instead of skipping);
#   4. bench/torch/bench_compat.py --device cuda (smg, eager torch, torch.compile);
#   5. bench/torch/bench_cuda.py (the fused step and the operators against autograd).
# Usage (device tool): bash scripts/device_check.sh     with carry [".dev"]
#   SMG_DEVICE_PYTEST="tests/torch/test_x.py ..."  the pytest files (default: all of tests/torch)
#   SMG_DEVICE_COMPAT_ARGS="--cases D3DGS"         bench_compat's case filter; SMG_DEVICE_BENCH_CUDA=0 skips 5
#        here, once:   bash scripts/device_check.sh --prepare
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--prepare" ]; then
  ex=$(git rev-parse --git-common-dir)/info/exclude; grep -qx '/.dev/' "$ex" 2>/dev/null || echo '/.dev/' >> "$ex"
  rm -rf .dev && mkdir -p .dev/include
  cp -r /usr/include/eigen3/Eigen /usr/include/eigen3/unsupported /usr/include/doctest .dev/include/
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
# nvcc directly, one object per file in parallel (the tests' CMake needs the trainer's libpng, libjpeg
# and stb, which that machine lacks), with the flags of smg_cuda_flags and tests/cuda/CMakeLists.txt.
tc=/tmp/test_cuda; mkdir -p $tc; pids=()
for f in tests/cuda/main.cu tests/cuda/test_*.cu; do
  timeout 300 nvcc -std=c++17 -O3 -DNDEBUG -arch=sm_90 --expt-relaxed-constexpr -diag-suppress=20012 -Xcompiler=-O1 \
    -Iinclude -Itests -I$dev/include -c "$f" -o "$tc/$(basename "$f").o" >> "$OUT/test_cuda_build.log" 2>&1 &
  pids+=($!)
done
wait "${pids[@]}"
timeout 60 nvcc -arch=sm_90 "$tc"/*.o -o "$tc/test_cuda" >> "$OUT/test_cuda_build.log" 2>&1
echo "rc=$?" >> "$OUT/test_cuda_build.log"; tail -3 "$OUT/test_cuda_build.log"
[ -x "$tc/test_cuda" ] && timeout 120 "$tc/test_cuda" > "$OUT/test_cuda.log" 2>&1; echo "rc=$?" >> "$OUT/test_cuda.log"; tail -4 "$OUT/test_cuda.log"

stamp "waiting for smg_torch"
wait $bpid; tail -3 "$OUT/torch_build.log"
export PYTHONPATH=$PWD/examples/torch
stamp "3. tests/torch"
LD_PRELOAD=$pre timeout 150 python3 -m pytest -q -p no:cacheprovider -rs ${SMG_DEVICE_PYTEST:-tests/torch} > "$OUT/pytest.log" 2>&1
echo "rc=$?" >> "$OUT/pytest.log"; tail -15 "$OUT/pytest.log"

stamp "4. bench_compat --device cuda"
LD_PRELOAD=$pre timeout 150 python3 bench/torch/bench_compat.py --device cuda --repeat 20 ${SMG_DEVICE_COMPAT_ARGS:-} \
  --json "$OUT/compat_cuda.json" 2>&1 | tee "$OUT/bench_compat.log"

stamp "5. bench_cuda"
[ "${SMG_DEVICE_BENCH_CUDA:-1}" = 1 ] && LD_PRELOAD=$pre timeout 120 python3 bench/torch/bench_cuda.py --repeat 20 --json "$OUT/torch_cuda.json" 2>&1 | tee "$OUT/bench_cuda.log"
stamp done
