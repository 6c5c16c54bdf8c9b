// examples/torch/smg_torch_ext.cpp — the compiled module smg_torch._C (docs: README "From
// PyTorch"). The Python package smg_torch wraps these functions in torch.autograd.Function.
#include <torch/python.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <set>
#include <thread>

#include "smg/core/version.hpp"
#include "smg_torch_common.hpp"

// torch's intra-op pool is OpenMP's here (torch.__config__.parallel_info(): "ATen parallel
// backend: OpenMP"; Debian's torch and pip's Linux wheels). at::parallel_for is then a header
// template whose `#pragma omp parallel` is compiled into this translation unit: without -fopenmp
// the pragma is ignored, _OPENMP is undefined, ATen/ParallelOpenMP.h leaves INTRA_OP_PARALLEL
// undefined, and every at::parallel_for here runs serially on the calling thread whatever
// torch.set_num_threads says (issue 24: smg ran on one core inside torch). CMake and setup.py
// compile this file with OpenMP; this check keeps a build without it from running serially
// unnoticed.
#if AT_PARALLEL_OPENMP && !defined(_OPENMP)
#error "smg_torch_ext.cpp needs OpenMP (-fopenmp) with torch's OpenMP backend: at::parallel_for would run serially"
#endif

namespace smg_torch {
namespace {

// smg's executor (smg/core/parallel.hpp, docs/conventions.md "The caller's executor"): smg's
// chunks on torch's intra-op threads through at::parallel_for, the entry point ATen gives
// extensions, so they follow torch.set_num_threads, share torch's pool instead of starting a
// second one, and run serially inside another intra-op region (at::in_parallel_region). Grain 1:
// smg has already cut the work into chunks (about 256 per loop); ATen hands each thread a
// contiguous share of them. Defined in this file only: the CUDA translation unit, compiled
// without OpenMP, must not hold a second, serial definition of the same inline function.
void torch_run(void*, smg::Index count, int, void (*job)(void*, smg::Index), void* ctx) {
  at::parallel_for(0, count, 1, [&](int64_t b, int64_t e) {
    for (int64_t c = b; c < e; ++c) job(ctx, c);
  });
}

// _parallel_threads(chunks, wanted, timeout_seconds): test hook (tests/torch/test_threads.py),
// not API. Runs one smg parallel loop of `chunks` chunks (grain 1, torch's thread count, on the
// executor installed below). Each chunk notes its OS thread, then waits until `wanted` distinct
// threads have run a chunk or `timeout_seconds` after the call began have passed. Returns the
// number of distinct threads that ran chunks. The wait is a rendezvous, so the count does not
// depend on timing: a thread holding a chunk cannot take the next one until the others have
// joined, hence every thread the executor gives the loop runs a chunk however the OS schedules
// them (count = min(threads, wanted, chunks)), and a loop run on one thread counts 1 after one
// timeout.
int64_t parallel_threads(const py::int_& chunks_arg, const py::int_& wanted_arg, double timeout_seconds) {
  const int64_t chunks = int_arg(chunks_arg, "chunks", 1, 1000000);
  const int64_t wanted = int_arg(wanted_arg, "wanted", 1, 1024);
  if (!(timeout_seconds > 0 && timeout_seconds <= 600))
    value_error("_parallel_threads: timeout_seconds must be in (0, 600]");
  std::mutex mutex;
  std::condition_variable joined;
  std::set<std::thread::id> seen;
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(timeout_seconds));
  smg::ParallelOptions par = parallel_options();
  par.grain = 1;
  py::gil_scoped_release release;
  smg::parallel_for(
      chunks,
      [&](smg::Index, smg::Index) {
        std::unique_lock<std::mutex> lock(mutex);
        if (seen.insert(std::this_thread::get_id()).second) joined.notify_all();
        joined.wait_until(lock, deadline, [&] { return static_cast<int64_t>(seen.size()) >= wanted; });
      },
      par);
  return static_cast<int64_t>(seen.size());
}

// Whether this CPU runs smg_torch._C_avx2 (AVX2 and FMA, and the OS saves the AVX registers:
// libgcc's cpu model checks XGETBV before it sets the AVX features).
bool cpu_supports_avx2_fma() {
#if (defined(__GNUC__) || defined(__clang__)) && (defined(__x86_64__) || defined(__i386__))
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
  return false;
#endif
}

}  // namespace
}  // namespace smg_torch

// The module's name: _C, or _C_avx2 for the AVX2 + FMA build of the energy operators
// (examples/torch/CMakeLists.txt, setup.py).
#ifndef SMG_TORCH_MODULE
#define SMG_TORCH_MODULE _C
#endif

PYBIND11_MODULE(SMG_TORCH_MODULE, m) {
  using namespace pybind11::literals;
  m.doc() = "smg_torch._C: smg's operators over CPU tensors, and with has_cuda over CUDA tensors for "
            "node_confidences, carap, arap, lrm, regularizers, dqb and knn_points (use the smg_torch package)";
  // smg's parallel loops run on torch's intra-op pool; each call asks for at::get_num_threads().
  smg::set_executor({&smg_torch::torch_run, nullptr});
  m.attr("version") = SMG_VERSION_STRING;
  m.def("_parallel_threads", &smg_torch::parallel_threads, "chunks"_a, "wanted"_a, "timeout_seconds"_a);
  // The instruction set this module was compiled for (what its -m flags defined), and whether
  // this CPU has AVX2 + FMA (smg_torch picks _C_avx2 by it).
  m.attr("_isa") = SMG_ISA_NAME;
  m.def("_cpu_supports_avx2_fma", &smg_torch::cpu_supports_avx2_fma);
  smg_torch::register_energy(m);
#ifdef SMG_TORCH_SKIN
  smg_torch::register_skin(m);
#endif
#ifdef SMG_TORCH_SPLAT
  smg_torch::register_splat(m);
#endif
#ifdef SMG_TORCH_GRAPH
  smg_torch::register_graph(m);
#endif
#ifdef SMG_TORCH_CUDA
  smg_torch::register_cuda(m);  // smg_torch_cuda.cu: cuda_* operators, has_cuda = True
#else
  m.attr("has_cuda") = false;
#endif
}
