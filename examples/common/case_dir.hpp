// examples/common/case_dir.hpp — typed, checked loading of a case directory of .npy files.
//
// docs/interop.md: float arrays may be float32 or float64, integer arrays int32 or int64, bool
// arrays uint8 or bool; a missing required file, a wrong shape or dtype, or a NaN/Inf is an
// error whose message names the file and the problem.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "npy.hpp"

namespace cli {

// What the program is allocating right now, for the one-line error when a std::bad_alloc
// escapes anyway ("<context>: out of memory"). Set with AllocContext; kept when an exception
// leaves the scope so that the driver can report it.
inline std::string& alloc_context() {
  static std::string context;
  return context;
}
class AllocContext {
 public:
  explicit AllocContext(std::string what) : prev_(alloc_context()), exceptions_(std::uncaught_exceptions()) {
    alloc_context() = std::move(what);
  }
  ~AllocContext() {
    if (std::uncaught_exceptions() == exceptions_) alloc_context() = prev_;
  }
  AllocContext(const AllocContext&) = delete;
  AllocContext& operator=(const AllocContext&) = delete;

 private:
  std::string prev_;
  int exceptions_;
};

// A request larger than the memory limit (--max-memory-gb).
class LimitError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Throws LimitError("<what>: needs about X GiB, more than the limit of Y GiB ...") when
// `bytes` (an estimate of outputs + main workspaces) exceeds `limit` bytes.
inline void check_memory(double bytes, double limit, const std::string& what) {
  if (limit > 0 && !(bytes <= limit)) {
    char buf[160];
    std::snprintf(buf, sizeof buf, ": needs about %.3g GiB, more than the limit of %.3g GiB (--max-memory-gb)",
                  bytes / 1073741824.0, limit / 1073741824.0);
    throw LimitError(what + buf);
  }
}

template <class T>
struct Tensor {
  std::vector<std::int64_t> shape;
  std::vector<T> data;
  std::int64_t dim(std::size_t k) const { return shape.at(k); }
  T* ptr() { return data.data(); }
  const T* ptr() const { return data.data(); }
};

// One expected dimension: its name for messages ("T", "N", "" for a literal) and its size,
// -1 for "any" (then the loaded size can be read back from Tensor::shape).
struct Dim {
  std::string name;
  std::int64_t size = -1;
};

class CaseDir {
 public:
  // max_bytes > 0: the memory limit; a file whose array (plus its converted copy) exceeds it is
  // refused before it is read.
  explicit CaseDir(std::filesystem::path dir, double max_bytes = 0) : dir_(std::move(dir)), max_bytes_(max_bytes) {
    std::error_code ec;
    const auto st = std::filesystem::status(dir_, ec);
    if (!std::filesystem::exists(st)) throw npy::Error(dir_.string() + ": case directory does not exist");
    if (!std::filesystem::is_directory(st)) throw npy::Error(dir_.string() + ": not a directory");
  }

  const std::filesystem::path& path() const { return dir_; }
  // The path of a file of the case as the user names it (CASE/file), for messages.
  std::string file(const std::string& name) const { return (dir_ / name).string(); }
  // symlink_status: a dangling symlink or a FIFO "exists" too, and is then refused by load.
  bool has(const std::string& file) const {
    std::error_code ec;
    return std::filesystem::exists(std::filesystem::symlink_status(dir_ / file, ec));
  }
  double max_bytes() const { return max_bytes_; }

  // T = float or double: a float32/float64 array (float16 is refused), all finite.
  // T = int32_t or int64_t: an int32/int64 array.
  // T = uint8_t: a uint8/bool array of 0s and 1s.
  template <class T>
  Tensor<T> load(const std::string& file, const std::vector<Dim>& expected) const {
    const std::string path = (dir_ / file).string();
    if (!has(file)) throw npy::Error(path + ": missing required file");
    const AllocContext ctx(path);
    const npy::Array a = npy::read(path, max_bytes_ > 0 ? static_cast<std::uint64_t>(max_bytes_ / 2) : 0);
    check_dtype<T>(a.dtype, path);
    check_shape(a.shape, expected, path);
    Tensor<T> t;
    t.shape = a.shape;
    t.data = a.as<T>(path);
    if constexpr (std::is_floating_point_v<T>) {
      for (std::size_t k = 0; k < t.data.size(); ++k)
        if (!std::isfinite(t.data[k]))
          throw npy::Error(path + ": " + (std::isnan(t.data[k]) ? "NaN" : "Inf") + " at index " +
                           index_string(a.shape, k));
    }
    if constexpr (std::is_same_v<T, std::uint8_t>) {
      for (std::size_t k = 0; k < t.data.size(); ++k)
        if (t.data[k] > 1)
          throw npy::Error(path + ": value " + std::to_string(int(t.data[k])) + " at index " +
                           index_string(a.shape, k) + " (expected 0 or 1)");
    }
    return t;
  }

  template <class T>
  std::optional<Tensor<T>> load_optional(const std::string& file,
                                         const std::vector<Dim>& expected) const {
    if (!has(file)) return std::nullopt;
    return load<T>(file, expected);
  }

 private:
  template <class T>
  static void check_dtype(npy::DType d, const std::string& path) {
    const char* want = nullptr;
    if constexpr (std::is_floating_point_v<T>) {
      // float16 is refused: docs/interop.md promises float32/float64, and half precision would
      // silently lose the digits the library's checks are meant to compare.
      if (!npy::is_float(d) || d == npy::DType::f16) want = "float32 or float64";
    } else if constexpr (std::is_same_v<T, std::uint8_t>) {
      if (!npy::is_boolish(d)) want = "bool or uint8";
    } else {
      if (!npy::is_integer(d)) want = "int32 or int64";
    }
    if (want) throw npy::Error(path + ": dtype " + npy::dtype_name(d) + ", expected " + want);
  }
  static void check_shape(const std::vector<std::int64_t>& shape, const std::vector<Dim>& expected,
                          const std::string& path) {
    bool ok = shape.size() == expected.size();
    for (std::size_t k = 0; ok && k < shape.size(); ++k)
      if (expected[k].size >= 0 && shape[k] != expected[k].size) ok = false;
    if (ok) {
      // Empty inputs are refused consistently (docs/interop.md "Empty inputs").
      for (std::size_t k = 0; k < shape.size(); ++k)
        if ((expected[k].name == "T" || expected[k].name == "N") && shape[k] == 0)
          throw npy::Error(path + ": empty input (" + expected[k].name + " = 0 in shape " +
                           npy::shape_string(shape) + "); T and N must be at least 1");
      return;
    }
    std::ostringstream s;
    s << path << ": expected shape [";
    for (std::size_t k = 0; k < expected.size(); ++k) {
      s << (k ? ", " : "");
      if (!expected[k].name.empty()) s << expected[k].name << "=";
      if (expected[k].size >= 0) s << expected[k].size; else s << "any";
    }
    s << "], got " << npy::shape_string(shape);
    throw npy::Error(s.str());
  }
  static std::string index_string(const std::vector<std::int64_t>& shape, std::size_t flat) {
    std::vector<std::int64_t> idx(shape.size());
    for (std::size_t k = shape.size(); k-- > 0;) {
      idx[k] = static_cast<std::int64_t>(flat) % shape[k];
      flat /= static_cast<std::size_t>(shape[k]);
    }
    return npy::shape_string(idx);
  }

  std::filesystem::path dir_;
  double max_bytes_ = 0;
};

}  // namespace cli
