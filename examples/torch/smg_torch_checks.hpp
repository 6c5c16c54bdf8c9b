// examples/torch/smg_torch_checks.hpp — argument checks of the smg_torch extension, shared by
// the CPU (.cpp) and CUDA (.cu) translation units: every failure raises one line naming the
// Python argument (ValueError; NotImplementedError for a device the operator has no code for).
//
// Tensors are checked against the call's reference tensor (positions, node_positions or means):
// its device and float dtype. Integer arguments arrive as Python ints and are range-checked
// before any narrowing. Large outputs are estimated against a memory limit (8 GiB by default,
// smg_torch.set_memory_limit; smg_cli's --max-memory-gb, docs/interop.md "Limits") before they
// are allocated, and an allocation that fails anyway becomes a ValueError naming the argument.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <new>
#include <sstream>
#include <string>
#include <utility>

#include <ATen/ATen.h>
#include <torch/csrc/utils/pybind.h>  // at::Tensor <-> torch.Tensor casters

#include "smg/core/status.hpp"

namespace smg_torch {

namespace py = pybind11;

inline constexpr const char* kNoCudaMessage =
    "smg_torch: CUDA tensors need smg_torch built with CUDA (smg_torch.has_cuda is False)";
inline constexpr const char* kCpuOnlyMessage =
    "smg_torch: CUDA tensors are not supported by this operator (CPU only)";

// Whether the CUDA operators were compiled in (set once by register_cuda, smg_torch_cuda.cu).
inline bool& has_cuda() {
  static bool on = false;
  return on;
}

[[noreturn]] inline void value_error(const std::string& message) { throw py::value_error(message); }

[[noreturn]] inline void not_implemented(const char* message) {
  PyErr_SetString(PyExc_NotImplementedError, message);
  throw py::error_already_set();
}

// Library names that differ from the Python argument: {library name, Python name}.
using Names = std::initializer_list<std::pair<const char*, const char*>>;

// A library message in the caller's names: "CarapOptions.alpha must be ..." -> "alpha: must
// be ..."; "CarapOptions.gaps[1].weight ..." -> "gap_weights[1]: ..."; a "settings: " or
// "camera: " prefix dropped; then a leading library name from `names` replaced ("rotations:
// element ..." -> "quats: element ...") or, when followed by a space, put in front ("near plane
// must be ..." -> "near: near plane must be ..."; "tile_size must be ..." -> "tile_size: must
// be ..." for a name listed as itself).
inline std::string python_message(std::string m, Names names) {
  if (const auto dot = m.find("Options."); dot != std::string::npos && dot < m.find(' ')) {
    m = m.substr(dot + 8);
    const auto space = m.find(' ');
    std::string field = m.substr(0, space);
    if (space != std::string::npos && field.back() != ':') {
      const auto bracket = field.find("].");
      if (field.rfind("gaps[", 0) == 0 && bracket != std::string::npos)
        field = (field.substr(bracket + 2) == "weight" ? "gap_weights" : "gaps") +
                field.substr(4, bracket - 3);
      m = field + ":" + m.substr(space);
    }
  }
  for (const char* prefix : {"settings: ", "camera: "})
    if (m.rfind(prefix, 0) == 0) m = m.substr(std::strlen(prefix));
  for (const auto& [lib, python] : names) {
    const std::size_t n = std::strlen(lib);
    if (m.rfind(lib, 0) != 0 || m.size() <= n) continue;
    if (m[n] == ' ' && std::strcmp(lib, python) == 0) return std::string(python) + ":" + m.substr(n);
    if (m[n] == ' ') return std::string(python) + ": " + m;
    if (m[n] == ':' || m[n] == '[' || m[n] == '.') return python + m.substr(n);
  }
  return m;
}

// ValueError with the library's message (in the caller's names) when `s` failed.
inline void ok(const smg::Status& s, Names names = {}) {
  if (!s) value_error(python_message(s.message(), names));
}

inline std::string shape_of(const at::Tensor& t) {
  std::string s = "[";
  for (int64_t d = 0; d < t.dim(); ++d) s += (d ? ", " : "") + std::to_string(t.size(d));
  return s + "]";
}

inline std::string dtype_name(at::ScalarType st) { return std::string(c10::toString(st)); }

// Checks rank and (when last >= 0) the size of the last dimension; `layout` names it.
inline void require_shape(const at::Tensor& t, const char* name, int64_t rank, int64_t last,
                          const char* layout) {
  if (t.dim() != rank || (last >= 0 && t.size(rank - 1) != last))
    value_error(std::string(name) + ": expected shape " + layout + ", got " + shape_of(t));
}

// A dense (strided) tensor, else one error naming it: smg reads storage, and a sparse tensor's
// own error ("reshape is not implemented for sparse tensors") names neither it nor the argument.
inline void require_dense(const at::Tensor& t, const char* name) {
  if (t.layout() == at::kStrided) return;
  std::ostringstream layout;
  layout << t.layout();
  value_error(std::string(name) + ": a tensor of layout " + layout.str() +
              "; smg takes dense (strided) tensors: pass .to_dense()");
}

// `t` as smg reads it: dense, its negative and conjugate bits resolved (torch._neg_view and
// conj().imag give views whose storage holds the negated values: read raw, a gradient would
// come out with the wrong sign). No copy when neither bit is set.
inline at::Tensor dense_input(const at::Tensor& t, const char* name) {
  require_dense(t, name);
  return t.resolve_conj().resolve_neg();
}

// For the CPU-only operators (build_graph, render, _library_seconds, _accel).
inline void require_cpu(const at::Tensor& t, const char* name) {
  require_dense(t, name);
  if (t.is_cuda()) not_implemented(kCpuOnlyMessage);
  if (!t.device().is_cpu()) value_error(std::string(name) + ": expected a CPU tensor");
}

// The call's reference tensor: every other tensor must be on its device, and every other float
// tensor must have its dtype.
struct Reference {
  const char* name = "positions";
  at::Device device{at::kCPU};
  at::ScalarType st = at::kDouble;
  bool cuda() const { return device.is_cuda(); }
  at::TensorOptions options() const { return at::TensorOptions().dtype(st).device(device); }
  at::TensorOptions int32() const { return at::TensorOptions().dtype(at::kInt).device(device); }
};

// `t` (named `name`) as the reference: a CPU tensor, or a CUDA tensor in a CUDA build; float32
// or float64.
inline Reference reference(const at::Tensor& t, const char* name) {
  if (t.is_cuda() && !has_cuda()) not_implemented(kNoCudaMessage);
  if (!t.is_cuda() && !t.device().is_cpu())
    value_error(std::string(name) + ": expected a CPU or CUDA tensor, got " + t.device().str());
  const auto st = t.scalar_type();
  if (st != at::kFloat && st != at::kDouble)
    value_error(std::string(name) + ": dtype must be float32 or float64, got " + dtype_name(st));
  return {name, t.device(), st};
}

// Checks that `t` is on the reference's device.
inline void require_device(const at::Tensor& t, const char* name, const Reference& r) {
  if (t.device() == r.device) return;
  if (t.is_cuda() && !has_cuda()) not_implemented(kNoCudaMessage);
  value_error(std::string(name) + ": expected a tensor on " + r.device.str() + " like " + r.name +
              ", got " + t.device().str());
}

// `t` on the reference's device, dense_input, made contiguous (a copy only when it was not or a
// bit was set).
inline at::Tensor on_device(const at::Tensor& t, const char* name, const Reference& r) {
  require_device(t, name, r);
  return dense_input(t, name).contiguous();
}

// A float tensor of the reference's dtype and device with the given rank and last dimension.
inline at::Tensor float_input(const at::Tensor& t, const char* name, const Reference& r,
                              int64_t rank, int64_t last, const char* layout) {
  at::Tensor c = on_device(t, name, r);
  if (c.scalar_type() != r.st)
    value_error(std::string(name) + ": dtype " + dtype_name(c.scalar_type()) + " does not match " +
                r.name + " (" + dtype_name(r.st) + ")");
  require_shape(c, name, rank, last, layout);
  return c;
}

// Graph indices [N, K] (int32 or int64, read in place) and weights [N, K] converted to the
// reference's dtype when they differ (the only copy of the graph).
struct GraphTensors {
  at::Tensor indices;
  at::Tensor weights;
  bool int64 = false;
  int64_t n = 0, k = 0;
};

inline GraphTensors graph_input(const at::Tensor& indices, const at::Tensor& weights,
                                const Reference& r) {
  GraphTensors g;
  g.indices = on_device(indices, "graph.indices", r);
  const at::Tensor w = on_device(weights, "graph.weights", r);
  if (indices.dim() != 2) value_error("graph.indices: expected shape [N, K], got " + shape_of(indices));
  if (w.dim() != 2 || w.size(0) != indices.size(0) || w.size(1) != indices.size(1))
    value_error("graph.weights: expected shape " + shape_of(indices) + " like graph.indices, got " +
                shape_of(w));
  const auto it = indices.scalar_type();
  if (it != at::kInt && it != at::kLong)
    value_error("graph.indices: dtype must be int32 or int64, got " + dtype_name(it));
  const auto wt = w.scalar_type();
  if (wt != at::kFloat && wt != at::kDouble)
    value_error("graph.weights: dtype must be float32 or float64, got " + dtype_name(wt));
  g.weights = w.to(r.st).contiguous();
  g.int64 = it == at::kLong;
  g.n = indices.size(0);
  g.k = indices.size(1);
  return g;
}

// Visibility [T, N] as uint8 0/1 (bool is reinterpreted in place; other dtypes are converted).
// A float visibility must be finite: checked on CPU tensors, and on CUDA tensors only when
// `check_contents` (it synchronises the stream).
inline at::Tensor visibility_input(const at::Tensor& v, const Reference& r, bool check_contents) {
  const at::Tensor c = on_device(v, "visibility", r);
  require_shape(c, "visibility", 2, -1, "[T, N]");
  if (c.scalar_type() == at::kByte) return c;
  if (c.scalar_type() == at::kBool) return c.view(at::kByte);
  if ((!r.cuda() || check_contents) && at::isFloatingType(c.scalar_type()) &&
      !at::isfinite(c).all().item<bool>())
    value_error("visibility: has a value that is not finite");
  return (c != 0).to(at::kByte).contiguous();
}

// Checks an index vector [n] of any integer dtype on the reference's device and returns it as
// dense_input (its range is checked by check_index_ranges, then it is converted to int32).
inline at::Tensor index_input(const at::Tensor& a, const char* name, const Reference& r) {
  require_device(a, name, r);
  const at::Tensor d = dense_input(a, name);
  if (d.dim() != 1) value_error(std::string(name) + ": expected shape [n], got " + shape_of(d));
  if (at::isFloatingType(d.scalar_type()) || d.scalar_type() == at::kBool)
    value_error(std::string(name) + ": dtype must be an integer type, got " + dtype_name(d.scalar_type()));
  return d;
}

// Entries of an index tensor that must lie in [lo, hi) (hi named `bound`); `graph` for a
// [N, K] neighbour table (the message gives i and k, as validate_neighbors does).
struct IndexRange {
  at::Tensor t;
  const char* name;
  int64_t lo, hi;
  const char* bound;
  bool graph = false;
};

// Checks every range with one host read of the flags (one synchronisation on CUDA); the first
// failure raises the library's message for it.
inline void check_index_ranges(std::initializer_list<IndexRange> ranges) {
  std::vector<at::Tensor> bad;
  for (const auto& c : ranges) bad.push_back(((c.t < c.lo) | (c.t >= c.hi)).any());
  if (bad.empty()) return;
  const at::Tensor flags = at::stack(bad).cpu();
  const bool* f = flags.data_ptr<bool>();
  std::size_t k = 0;
  for (const auto& c : ranges) {
    if (!f[k++]) continue;
    const at::Tensor flat = c.t.reshape({-1});
    const int64_t i = at::nonzero((flat < c.lo) | (flat >= c.hi)).view({-1})[0].item<int64_t>();
    const std::string v = std::to_string(flat[i].item<int64_t>());
    if (c.graph) {
      const int64_t K = c.t.size(1);
      value_error(std::string(c.name) + ": entry [i=" + std::to_string(i / K) + "][k=" +
                  std::to_string(i % K) + "] is out of range: " + v);
    }
    value_error(std::string(c.name) + ": element [" + std::to_string(i) + "] = " + v +
                " is out of range [0, " + c.bound + "=" + std::to_string(c.hi) + ")");
  }
}

// A Python int in [lo, hi], checked before it is narrowed to int64 or smaller.
inline int64_t int_arg(const py::handle& v, const std::string& name, int64_t lo, int64_t hi) {
  int overflow = 0;
  const long long x = PyLong_AsLongLongAndOverflow(v.ptr(), &overflow);
  if (x == -1 && !overflow && PyErr_Occurred()) {
    PyErr_Clear();
    value_error(name + ": expected an integer, got " + std::string(py::str(v.get_type().attr("__name__"))));
  }
  if (overflow || x < lo || x > hi)
    value_error(name + ": must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                "], got " + std::string(py::str(v)));
  return x;
}

// The memory limit in bytes (smg_torch.set_memory_limit; 8 GiB by default, as smg_cli's
// --max-memory-gb). One value for the module (every translation unit shares it).
inline constexpr double kGiB = 1073741824.0;
inline double& memory_limit() {
  static double bytes = 8 * kGiB;
  return bytes;
}

// ValueError "<what>: needs about X GiB, more than the limit of Y GiB (...)" when `bytes` (an
// estimate of the outputs and main workspaces of a request) exceeds the limit.
inline void check_memory(double bytes, const std::string& what) {
  if (bytes <= memory_limit()) return;
  char buf[200];
  std::snprintf(buf, sizeof buf,
                ": needs about %.3g GiB, more than the limit of %.3g GiB (smg_torch.set_memory_limit)",
                bytes / kGiB, memory_limit() / kGiB);
  value_error(what + buf);
}

// f() (allocations), with an allocator failure turned into a ValueError naming `what`.
template <class F>
auto allocating(const std::string& what, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const std::bad_alloc&) {
    value_error(what + ": out of memory (std::bad_alloc; see smg_torch.set_memory_limit)");
  } catch (const c10::Error& e) {
    std::string m = e.what_without_backtrace();
    m = m.substr(0, m.find('\n'));
    value_error(what + ": out of memory (" + m + "; see smg_torch.set_memory_limit)");
  }
}

}  // namespace smg_torch
