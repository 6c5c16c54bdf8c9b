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
    std::printf("test_cuda: skipped, no CUDA device (%s)\n",
                e != cudaSuccess ? cudaGetErrorString(e) : "no device found");
    return 0;
  }
  cudaDeviceProp prop{};
  cudaGetDeviceProperties(&prop, 0);
  std::printf("test_cuda: device 0 is %s (sm_%d%d)\n", prop.name, prop.major, prop.minor);
  doctest::Context context(argc, argv);
  return context.run();
}
