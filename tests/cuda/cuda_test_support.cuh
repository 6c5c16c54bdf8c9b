// tests/cuda/cuda_test_support.cuh — small helpers of the CUDA tests: owned device arrays
// uploaded from / downloaded to std::vector, a stream, comparisons that print where and by
// how much two results differ (the GPU runs happen after merging, on another machine, so a
// failure must say enough on its own), and the host construction of in-edge lists.
#pragma once

#include <doctest/doctest.h>

#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace smg::test::cuda {

// Fails the test case (with the CUDA error) when a runtime call fails.
#define SMG_TEST_CUDA(expr)                                                                 \
  do {                                                                                      \
    const cudaError_t smg_test_err_ = (expr);                                               \
    REQUIRE_MESSAGE(smg_test_err_ == cudaSuccess, #expr, ": ", cudaGetErrorName(smg_test_err_), \
                    " (", cudaGetErrorString(smg_test_err_), ")");                          \
  } while (0)

// The name and sizes a random case of these tests starts with: frames T, nodes N, neighbours per
// node K, points P, drivers per point D (each case uses those it has; the others stay 0).
struct CaseSizes {
  std::string name;
  std::ptrdiff_t T = 0, N = 0, K = 0, P = 0, D = 0;  // smg::Index
};

template <class T>
class DeviceArray {
 public:
  DeviceArray() = default;
  explicit DeviceArray(const std::vector<T>& host) { upload(host); }
  DeviceArray(const DeviceArray&) = delete;
  DeviceArray& operator=(const DeviceArray&) = delete;
  ~DeviceArray() {
    if (p_) cudaFree(p_);
  }
  void upload(const std::vector<T>& host) {
    resize(host.size());
    if (!host.empty())
      SMG_TEST_CUDA(cudaMemcpy(p_, host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice));
  }
  void resize(std::size_t n) {
    if (p_) cudaFree(p_);
    p_ = nullptr;
    n_ = n;
    if (n > 0) SMG_TEST_CUDA(cudaMalloc(reinterpret_cast<void**>(&p_), n * sizeof(T)));
  }
  std::vector<T> download() const {
    std::vector<T> h(n_);
    if (n_ > 0) SMG_TEST_CUDA(cudaMemcpy(h.data(), p_, n_ * sizeof(T), cudaMemcpyDeviceToHost));
    return h;
  }
  T* get() const { return p_; }
  std::size_t size() const { return n_; }

 private:
  T* p_ = nullptr;
  std::size_t n_ = 0;
};

struct Stream {
  cudaStream_t s = nullptr;
  Stream() { SMG_TEST_CUDA(cudaStreamCreateWithFlags(&s, cudaStreamNonBlocking)); }
  ~Stream() {
    if (s) cudaStreamDestroy(s);
  }
  void sync() const { SMG_TEST_CUDA(cudaStreamSynchronize(s)); }
};

// Tolerance of GPU vs CPU relative to the largest magnitude: 1e-12 in double, 1e-5 in float.
template <class S>
constexpr double tolerance() {
  return sizeof(S) == 8 ? 1e-12 : 1e-5;
}

// Checks max_k |gpu[k] − cpu[k]| <= tol · max(max_k |cpu[k]|, floor); on failure prints the
// worst element (index, both values), the scale, the tolerance and `what`.
template <class S>
bool check_close(const std::vector<S>& gpu, const std::vector<S>& cpu, double tol,
                 const std::string& what, double floor = 1e-300) {
  if (gpu.size() != cpu.size()) {
    FAIL_CHECK(what << ": sizes differ, gpu " << gpu.size() << " vs cpu " << cpu.size());
    return false;
  }
  double scale = floor, worst = 0;
  std::size_t at = 0;
  for (std::size_t k = 0; k < cpu.size(); ++k) {
    scale = std::max(scale, std::abs(double(cpu[k])));
    double d = std::abs(double(gpu[k]) - double(cpu[k]));
    if (!std::isfinite(d)) d = HUGE_VAL;  // a NaN or Inf on either side fails
    if (d > worst) {
      worst = d;
      at = k;
    }
  }
  const bool ok = worst <= tol * scale;
  if (!ok)
    FAIL_CHECK(what << ": max |gpu - cpu| = " << worst << " at element " << at << " (gpu "
                    << (cpu.empty() ? 0.0 : double(gpu[at])) << ", cpu "
                    << (cpu.empty() ? 0.0 : double(cpu[at])) << "), scale " << scale
                    << ", relative " << worst / scale << " > tolerance " << tol);
  return ok;
}

// Scalar version (energies): |gpu − cpu| <= tol · max(|cpu|, floor).
inline bool check_close_scalar(double gpu, double cpu, double tol, const std::string& what,
                               double floor = 1e-300) {
  const double scale = std::max(std::abs(cpu), floor);
  const bool ok = std::isfinite(gpu) && std::abs(gpu - cpu) <= tol * scale;
  if (!ok)
    FAIL_CHECK(what << ": gpu " << gpu << " vs cpu " << cpu << ", |diff| " << std::abs(gpu - cpu)
                    << ", relative " << std::abs(gpu - cpu) / scale << " > tolerance " << tol);
  return ok;
}

// Bitwise equality of two runs' results.
template <class T>
bool check_bitwise(const std::vector<T>& a, const std::vector<T>& b, const std::string& what) {
  const bool same = a.size() == b.size() &&
                    (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
  if (!same) {
    std::size_t at = 0;
    while (at < std::min(a.size(), b.size()) && std::memcmp(&a[at], &b[at], sizeof(T)) == 0) ++at;
    FAIL_CHECK(what << ": two runs differ (first at element " << at << " of " << a.size() << ")");
  }
  return same;
}

// The in-edge lists of an index table on the host, the reference for build_reverse_graph and
// build_driver_incidence (what build_driver_incidence ran on the host before it moved to the
// device): for target j in [0, nodes), the slots e with table[e] == j in increasing e, at
// ent[off[j] .. off[j+1]); entries outside [0, nodes) (−1 padding) skipped.
template <class I>
void host_in_edges(const std::vector<I>& table, std::int64_t nodes, std::vector<std::int32_t>& off,
                   std::vector<std::int64_t>& ent) {
  auto valid = [&](I j) { return j >= 0 && std::int64_t(j) < nodes; };
  off.assign(static_cast<std::size_t>(nodes + 1), 0);
  for (const I j : table)
    if (valid(j)) ++off[static_cast<std::size_t>(j) + 1];
  for (std::size_t j = 0; j < static_cast<std::size_t>(nodes); ++j) off[j + 1] += off[j];
  ent.assign(static_cast<std::size_t>(off.back()), 0);
  std::vector<std::int32_t> fill(off.begin(), off.end() - 1);
  for (std::size_t e = 0; e < table.size(); ++e)
    if (valid(table[e]))
      ent[static_cast<std::size_t>(fill[static_cast<std::size_t>(table[e])]++)] = std::int64_t(e);
}

// A double array converted to S (the scalar a case runs in).
template <class S>
std::vector<S> cast(const std::vector<double>& v) {
  return std::vector<S>(v.begin(), v.end());
}

}  // namespace smg::test::cuda
