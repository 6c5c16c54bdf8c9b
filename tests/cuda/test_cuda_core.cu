// The device-callable core and splat maths on the GPU against the same functions on the host:
// SO(3) Exp/Log and their Jacobians, quaternion products and matrices, the quaternion manifold,
// the rotation-gradient conversions, one Gaussian's projection and its vector-Jacobian product,
// spherical harmonics. A few hundred random inputs per kind plus the hard cases (θ ≈ 0 and the
// series switch points, near-180° and antipodal quaternions, Gaussians near the camera plane and
// beyond the field-of-view clamp, near-singular 2D covariances), in double (1e-12 relative) and
// float (1e-5 relative); the cases and the comparison are in core_cases.hpp. Runs only with a
// GPU (main.cu skips otherwise); a failure prints the quantity, both values and the inputs.
#include <doctest/doctest.h>

#include <cstdio>
#include <vector>

#include <cuda_runtime.h>

#include "cuda/core_cases.hpp"
#include "cuda/cuda_test_support.cuh"  // SMG_TEST_CUDA

namespace {

using smg_cuda_test::kIn;
using smg_cuda_test::kOut;

template <class S>
__global__ void eval_cases(int n, const int* kinds, const S* in, S* out) {
  const int k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k < n)
    smg_cuda_test::eval_case<S>(kinds[k], in + static_cast<size_t>(k) * kIn,
                                out + static_cast<size_t>(k) * kOut);
}

// Device memory freed on every exit path (a failed REQUIRE throws).
template <class T>
struct DeviceBuffer {
  T* ptr = nullptr;
  explicit DeviceBuffer(size_t n) { SMG_TEST_CUDA(cudaMalloc(&ptr, n * sizeof(T))); }
  ~DeviceBuffer() { cudaFree(ptr); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
};

template <class S>
void run_cases(double tol, const char* scalar_name) {
  const std::vector<smg_cuda_test::Case> cases = smg_cuda_test::make_cases(300);
  const int n = static_cast<int>(cases.size());
  std::vector<int> kinds(n);
  std::vector<S> in(static_cast<size_t>(n) * kIn), host(static_cast<size_t>(n) * kOut),
      device(static_cast<size_t>(n) * kOut, S(-12345));
  for (int c = 0; c < n; ++c) {
    kinds[c] = cases[c].kind;
    for (int k = 0; k < kIn; ++k) in[static_cast<size_t>(c) * kIn + k] = S(cases[c].in[k]);
  }
  for (int c = 0; c < n; ++c)
    smg_cuda_test::eval_case<S>(kinds[c], in.data() + static_cast<size_t>(c) * kIn,
                                host.data() + static_cast<size_t>(c) * kOut);

  DeviceBuffer<int> d_kinds(n);
  DeviceBuffer<S> d_in(in.size()), d_out(device.size());
  SMG_TEST_CUDA(cudaMemcpy(d_kinds.ptr, kinds.data(), n * sizeof(int), cudaMemcpyHostToDevice));
  SMG_TEST_CUDA(cudaMemcpy(d_in.ptr, in.data(), in.size() * sizeof(S), cudaMemcpyHostToDevice));
  SMG_TEST_CUDA(cudaMemset(d_out.ptr, 0xff, device.size() * sizeof(S)));  // NaN if not written
  const int block = 64;
  eval_cases<S><<<(n + block - 1) / block, block>>>(n, d_kinds.ptr, d_in.ptr, d_out.ptr);
  SMG_TEST_CUDA(cudaGetLastError());
  SMG_TEST_CUDA(cudaDeviceSynchronize());
  SMG_TEST_CUDA(
      cudaMemcpy(device.data(), d_out.ptr, device.size() * sizeof(S), cudaMemcpyDeviceToHost));

  const int failures = smg_cuda_test::compare<S>(cases, host, device, tol, scalar_name);
  CHECK_MESSAGE(failures == 0, failures, " of ", n, " cases differ between device and host in ",
                scalar_name, " (diagnostics above)");
}

}  // namespace

TEST_CASE("cuda core and splat maths: device matches host in double (1e-12 relative)") {
  run_cases<double>(1e-12, "double");
}

TEST_CASE("cuda core and splat maths: device matches host in float (1e-5 relative)") {
  run_cases<float>(1e-5, "float");
}
