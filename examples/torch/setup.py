"""The pip route (torch.utils.cpp_extension, no CMake; pyproject.toml declares the build):
builds smg_torch._C from examples/torch/*.cpp over smg's headers and Eigen, against the torch
already installed, and installs the smg_torch package (docs/torch.md, "Building it"):

    python3 -m venv --system-site-packages V && V/bin/pip install --no-build-isolation ./examples/torch
    EIGEN3_INCLUDE_DIR=/path/to/eigen3 ...      # when Eigen is not in /usr/include/eigen3
    SMG_TORCH_NO_CUDA=1 ...                     # the CPU operators only
    SMG_TORCH_OPT=-O1 ...                       # optimisation level (default -O3; CI's packaging
                                                # check builds at -O1: it proves the route, faster)
    cd examples/torch && python3 setup.py build_ext --inplace   # without pip: PYTHONPATH=examples/torch

The CMake route (README "From PyTorch") builds the same module into <build>/python/smg_torch/.
"""
import glob
import os
import sys

from setuptools import setup
import torch
from torch.utils.cpp_extension import CUDA_HOME, BuildExtension, CppExtension, CUDAExtension

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
sources = sorted(glob.glob(os.path.join(HERE, "smg_torch_*.cpp")))
parts = [os.path.basename(s)[len("smg_torch_"):-4] for s in sources]
macros = [("SMG_TORCH_" + p.upper(), None) for p in parts if p in ("skin", "splat", "graph")]

include_dirs = [os.path.join(ROOT, "include"), HERE,
                os.environ.get("EIGEN3_INCLUDE_DIR", "/usr/include/eigen3")]
# The CUDA operators (smg_torch_cuda.cu) when torch has CUDA and nvcc is found (CUDA_HOME);
# SMG_TORCH_NO_CUDA=1 builds the CPU operators only. -DNDEBUG as in CMake's Release build: smg's
# debug assertions (SMG_ASSERT: bounds checks on every view access) stay off in the extension.
with_cuda = (torch.version.cuda is not None and CUDA_HOME is not None
             and os.environ.get("SMG_TORCH_NO_CUDA", "0") != "1")
# OpenMP for the C++ sources, as torch compiles ATen: smg's loops run through at::parallel_for,
# a header template whose `#pragma omp parallel` is compiled into this module, and without
# OpenMP it runs serially whatever torch.set_num_threads says (smg_torch_ext.cpp stops the build
# then). The compiler's OpenMP runtime must be the one torch loads (Debian: g++'s libgomp).
openmp = ["/openmp"] if sys.platform == "win32" else ["-fopenmp"]
opt = os.environ.get("SMG_TORCH_OPT", "-O3")
if opt not in ("-O0", "-O1", "-O2", "-O3", "-Os"):
    sys.exit("setup.py: SMG_TORCH_OPT must be one of -O0 -O1 -O2 -O3 -Os, got %r" % opt)
openmp_link = [] if sys.platform == "win32" else ["-fopenmp"]
if with_cuda:
    ext = CUDAExtension(
        "smg_torch._C", sources + [os.path.join(HERE, "smg_torch_cuda.cu")],
        include_dirs=include_dirs, define_macros=macros + [("SMG_TORCH_CUDA", None)],
        extra_compile_args={"cxx": [opt, "-std=c++17", "-DNDEBUG"] + openmp,
                            "nvcc": [opt, "-std=c++17", "-DNDEBUG", "--expt-relaxed-constexpr",
                                     "-diag-suppress=20012"]},
        extra_link_args=openmp_link)
else:
    ext = CppExtension("smg_torch._C", sources, include_dirs=include_dirs, define_macros=macros,
                       extra_compile_args=[opt, "-std=c++17", "-DNDEBUG"] + openmp,
                       extra_link_args=openmp_link)

setup(
    name="smg_torch",
    version="0.1.0",
    packages=["smg_torch"],
    package_dir={"smg_torch": "smg_torch"},  # relative to this file (pip runs setup.py here)
    ext_modules=[ext],
    cmdclass={"build_ext": BuildExtension},
)
