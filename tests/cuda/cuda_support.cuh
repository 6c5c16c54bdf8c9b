// Small helpers of the CUDA tests: device copies of host vectors and back, and relative error.
#pragma once

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <cuda_runtime.h>

namespace smg_test {

#define CUDA_CHECK(expr)                                                              \
  do {                                                                                \
    const cudaError_t e_ = (expr);                                                    \
    if (e_ != cudaSuccess) FAIL(#expr << ": " << cudaGetErrorString(e_));             \
  } while (0)

// Device array with a host mirror; freed at scope exit.
template <class T>
struct DeviceVector {
  T* p = nullptr;
  std::size_t n = 0;
  DeviceVector() = default;
  explicit DeviceVector(const std::vector<T>& h) : n(h.size()) {
    if (n) {
      CUDA_CHECK(cudaMalloc(&p, n * sizeof(T)));
      CUDA_CHECK(cudaMemcpy(p, h.data(), n * sizeof(T), cudaMemcpyHostToDevice));
    }
  }
  explicit DeviceVector(std::size_t count, T value = T(0)) : DeviceVector(std::vector<T>(count, value)) {}
  DeviceVector(const DeviceVector&) = delete;
  DeviceVector& operator=(const DeviceVector&) = delete;
  ~DeviceVector() {
    if (p) cudaFree(p);
  }
  std::vector<T> host() const {
    std::vector<T> h(n);
    if (n) CUDA_CHECK(cudaMemcpy(h.data(), p, n * sizeof(T), cudaMemcpyDeviceToHost));
    return h;
  }
};

// max |a − b| / max(max |b|, floor): the error relative to the array's scale.
template <class A, class B>
double max_relative(const std::vector<A>& a, const std::vector<B>& b, double floor = 1e-300) {
  REQUIRE(a.size() == b.size());
  double scale = floor, err = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    scale = std::max(scale, std::abs(double(b[k])));
    err = std::max(err, std::abs(double(a[k]) - double(b[k])));
  }
  return err / scale;
}

inline bool bit_identical(const void* a, const void* b, std::size_t bytes) {
  return std::equal(static_cast<const char*>(a), static_cast<const char*>(a) + bytes,
                    static_cast<const char*>(b));
}

}  // namespace smg_test
