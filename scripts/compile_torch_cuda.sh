#!/usr/bin/env bash
# scripts/compile_torch_cuda.sh — compile smg_torch's CUDA operators (examples/torch/smg_torch_cuda.cu)
# with nvcc against Debian's libtorch headers, on a machine without a GPU: a check that the GPU
# glue (every smg::cuda launcher it instantiates, the fused step's driver included) still
# compiles. It links nothing and runs nothing (tests/torch/test_cuda.py needs a GPU and a CUDA
# build of torch). Not part of CI (about 100 s on 2 cores); run it after changing include/smg/cuda
# or examples/torch. Debian's CPU-only libtorch lacks one generated header of c10's CUDA part,
# c10/cuda/impl/cuda_cmake_macros.h (it defines only export macros): an empty one is put in a
# temporary directory. Usage: scripts/compile_torch_cuda.sh [nvcc]
set -euo pipefail
cd "$(dirname "$0")/.."
nvcc=${1:-${NVCC:-/usr/local/cuda/bin/nvcc}}
[ -x "$nvcc" ] || { echo "compile_torch_cuda: no nvcc at $nvcc" >&2; exit 1; }
scripts/deps.sh libeigen3-dev libtorch-dev pybind11-dev python3-dev
py_inc=$(/usr/bin/python3 -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/c10/cuda/impl"
echo '#pragma once' > "$tmp/c10/cuda/impl/cuda_cmake_macros.h"
"$nvcc" -std=c++17 -c examples/torch/smg_torch_cuda.cu -o "$tmp/smg_torch_cuda.o" \
  -I"$tmp" -Iinclude -Iexamples/torch -I/usr/include/eigen3 -I/usr/include/torch/csrc/api/include \
  -I"$py_inc" --expt-relaxed-constexpr -diag-suppress=20012 -DTORCH_EXTENSION_NAME=_C -D_GLIBCXX_USE_CXX11_ABI=1 \
  --generate-code=arch=compute_90,code=sm_90 -Xcompiler -fPIC
echo "compile_torch_cuda: examples/torch/smg_torch_cuda.cu compiled ($(du -k "$tmp/smg_torch_cuda.o" | cut -f1) KiB object)"
