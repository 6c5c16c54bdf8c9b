// examples/torch/smg_torch_common.hpp — shared helpers of the smg_torch extension: tensor checks
// that raise ValueError with one line naming the argument, zero-copy views over contiguous CPU
// tensors, the dtype / index-type dispatch and the executor on torch's intra-op pool.
//
// Copies (documented in README "From PyTorch"): a non-contiguous tensor is made contiguous
// (.contiguous(), a no-op for a contiguous one); graph weights of the other float dtype are
// converted to the positions' dtype (N×K values); visibility that is not uint8/bool is
// converted to uint8. Everything else is read in place through smg's views.
#pragma once

#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include <ATen/ATen.h>
#include <ATen/Parallel.h>
#include <torch/csrc/utils/pybind.h>  // at::Tensor <-> torch.Tensor casters
#include <pybind11/stl.h>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"

namespace smg_torch {

namespace py = pybind11;

// ValueError with the given message (the library's Status message, or ours for shapes).
[[noreturn]] inline void value_error(const std::string& message) { throw py::value_error(message); }

inline void ok(const smg::Status& s) {
  if (!s) value_error(s.message());
}

inline std::string shape_of(const at::Tensor& t) {
  std::ostringstream s;
  s << "[";
  for (int64_t d = 0; d < t.dim(); ++d) s << (d ? ", " : "") << t.size(d);
  s << "]";
  return s.str();
}

inline std::string dtype_name(const at::Tensor& t) { return std::string(c10::toString(t.scalar_type())); }

// A CPU tensor, else NotImplementedError (CUDA) / ValueError (other devices).
inline void require_cpu(const at::Tensor& t, const char* name) {
  if (t.is_cuda()) {
    PyErr_SetString(PyExc_NotImplementedError,
                    "smg_torch: CUDA tensors are not supported yet (CPU only)");
    throw py::error_already_set();
  }
  if (!t.device().is_cpu()) value_error(std::string(name) + ": expected a CPU tensor");
}

// Checks rank and (when last >= 0) the size of the last dimension; `layout` names it.
inline void require_shape(const at::Tensor& t, const char* name, int64_t rank, int64_t last,
                          const char* layout) {
  if (t.dim() != rank || (last >= 0 && t.size(rank - 1) != last))
    value_error(std::string(name) + ": expected shape " + layout + ", got " + shape_of(t));
}

// The float tensor of scalar S, contiguous (a copy only when it was not).
template <class S>
at::Tensor float_input(const at::Tensor& t, const char* name, at::ScalarType st) {
  require_cpu(t, name);
  if (t.scalar_type() != st)
    value_error(std::string(name) + ": dtype " + dtype_name(t) + " does not match positions (" +
                std::string(c10::toString(st)) + ")");
  return t.contiguous();
}

inline at::ScalarType float_type_of(const at::Tensor& t, const char* name) {
  require_cpu(t, name);
  const auto st = t.scalar_type();
  if (st != at::kFloat && st != at::kDouble)
    value_error(std::string(name) + ": dtype must be float32 or float64, got " + dtype_name(t));
  return st;
}

// Graph indices [N, K] (int32 or int64, read in place) and weights [N, K] converted to the
// positions' dtype when they differ (the only copy of the graph).
struct GraphTensors {
  at::Tensor indices;
  at::Tensor weights;
  bool int64 = false;
  int64_t n = 0, k = 0;
};

inline GraphTensors graph_input(const at::Tensor& indices, const at::Tensor& weights,
                                at::ScalarType st) {
  GraphTensors g;
  require_cpu(indices, "graph.indices");
  require_cpu(weights, "graph.weights");
  if (indices.dim() != 2) value_error("graph.indices: expected shape [N, K], got " + shape_of(indices));
  if (weights.dim() != 2 || weights.size(0) != indices.size(0) || weights.size(1) != indices.size(1))
    value_error("graph.weights: expected shape " + shape_of(indices) + " like graph.indices, got " +
                shape_of(weights));
  const auto it = indices.scalar_type();
  if (it != at::kInt && it != at::kLong)
    value_error("graph.indices: dtype must be int32 or int64, got " + dtype_name(indices));
  const auto wt = weights.scalar_type();
  if (wt != at::kFloat && wt != at::kDouble)
    value_error("graph.weights: dtype must be float32 or float64, got " + dtype_name(weights));
  g.indices = indices.contiguous();
  g.weights = weights.to(st).contiguous();
  g.int64 = it == at::kLong;
  g.n = indices.size(0);
  g.k = indices.size(1);
  return g;
}

// Visibility [T, N] as uint8 0/1 (bool is reinterpreted in place; other dtypes are converted).
inline at::Tensor visibility_input(const at::Tensor& v) {
  require_cpu(v, "visibility");
  require_shape(v, "visibility", 2, -1, "[T, N]");
  if (v.scalar_type() == at::kByte) return v.contiguous();
  if (v.scalar_type() == at::kBool) return v.contiguous().view(at::kByte);
  if (at::isFloatingType(v.scalar_type()) && !at::isfinite(v).all().item<bool>())
    value_error("visibility: has a value that is not finite");
  return (v != 0).to(at::kByte).contiguous();
}

// smg's chunks on torch's intra-op threads (docs/conventions.md "The caller's executor").
inline void torch_run(void*, smg::Index count, int, void (*job)(void*, smg::Index), void* ctx) {
  at::parallel_for(0, count, 1, [&](int64_t b, int64_t e) {
    for (int64_t c = b; c < e; ++c) job(ctx, c);
  });
}

// Per call: as many threads as torch uses now (torch.set_num_threads).
inline smg::ParallelOptions parallel_options() {
  smg::ParallelOptions p;
  p.threads = at::get_num_threads();
  return p;
}

inline at::TensorOptions options_of(at::ScalarType st) {
  return at::TensorOptions().dtype(st).device(at::kCPU);
}

// Calls f(S{}, I{}) with S = float/double and I = int32/int64.
template <class F>
auto dispatch(at::ScalarType st, bool int64, F&& f) {
  if (st == at::kFloat) {
    if (int64) return f(float{}, std::int64_t{});
    return f(float{}, std::int32_t{});
  }
  if (int64) return f(double{}, std::int64_t{});
  return f(double{}, std::int32_t{});
}

template <class S>
inline const S* cptr(const at::Tensor& t) {
  return t.numel() ? t.data_ptr<S>() : nullptr;
}
template <class S>
inline S* mptr(at::Tensor& t) {
  return t.numel() ? t.data_ptr<S>() : nullptr;
}

// Module registration, one per source file.
void register_energy(py::module_& m);
void register_skin(py::module_& m);
void register_splat(py::module_& m);
void register_graph(py::module_& m);
void register_cuda(py::module_& m);

}  // namespace smg_torch
