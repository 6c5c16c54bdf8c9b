// doctest main of the CUDA tests: without a usable CUDA device it prints one line and succeeds
// (CI machines have no GPU), otherwise it runs every test case.
#define DOCTEST_CONFIG_IMPLEMENT
#include <doctest/doctest.h>

#include <cstdio>

#include <cuda_runtime.h>

int main(int argc, char** argv) {
  int n = 0;
  const cudaError_t e = cudaGetDeviceCount(&n);
  if (e != cudaSuccess || n == 0) {
    // Without a device: the suite "cuda-host" only, which runs the kernels' per-element steps in
    // host loops against the CPU functions (tests/cuda/test_cuda_host_steps.cu).
    std::printf("test_cuda: no CUDA device (%s): GPU tests skipped, host suite cuda-host runs\n",
                e != cudaSuccess ? cudaGetErrorString(e) : "no device found");
    doctest::Context context(argc, argv);
    context.setOption("test-suite", "cuda-host");
    return context.run();
  }
  cudaDeviceProp prop{};
  cudaGetDeviceProperties(&prop, 0);
  std::printf("test_cuda: device 0 is %s (sm_%d%d)\n", prop.name, prop.major, prop.minor);
  doctest::Context context(argc, argv);
  return context.run();
}
