// examples/torch/smg_torch_common.hpp — shared glue of the smg_torch extension, included by the
// CPU translation units (.cpp) and the CUDA one (smg_torch_cuda.cu): the argument checks
// (smg_torch_checks.hpp), the option builders (smg_torch_options.hpp), the checked inputs that
// an operator hands to its CPU or CUDA implementation, the dtype / index-type dispatch, and the
// thread count of torch's intra-op pool (the executor over that pool is smg_torch_ext.cpp's: it
// must be compiled with OpenMP, which the CUDA translation unit is not).
//
// Device dispatch: each operator is one Python name (smg_torch._C.carap, ...). Its .cpp checks
// the arguments on the reference tensor's device, builds the options and allocates the outputs,
// then runs the CPU loops, or, for a CUDA reference, the launches in cuda_ops() (filled by
// register_cuda; in a build without CUDA a CUDA tensor raises NotImplementedError).
//
// Copies (documented in docs/interop.md's smg_torch part): a non-contiguous tensor is made
// contiguous (.contiguous(), a no-op for a contiguous one); graph weights of the other float
// dtype are converted to the reference's dtype (N×K values); visibility that is not uint8/bool
// is converted to uint8; index vectors (anchor, t_ref, t_query) become int32 copies. Everything
// else is read in place through smg's views.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <ATen/ATen.h>
#include <ATen/Parallel.h>
#include <torch/csrc/utils/pybind.h>  // at::Tensor <-> torch.Tensor casters
#include <pybind11/stl.h>

#include "smg/core/parallel.hpp"
#include "smg/core/status.hpp"
#include "smg/graph/neighbors.hpp"
#include "smg_torch_checks.hpp"
#include "smg_torch_options.hpp"

namespace smg_torch {

using OptTensor = std::optional<at::Tensor>;

// Per call: as many threads as torch uses now (torch.set_num_threads).
inline smg::ParallelOptions parallel_options() {
  smg::ParallelOptions p;
  p.threads = at::get_num_threads();
  return p;
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

// Data pointers for smg's views; null for an undefined or empty tensor.
template <class S>
inline const S* cptr(const at::Tensor& t) {
  return t.defined() && t.numel() ? t.data_ptr<S>() : nullptr;
}
template <class S>
inline S* mptr(const at::Tensor& t) {
  return t.defined() && t.numel() ? t.data_ptr<S>() : nullptr;
}

template <class S, class I>
smg::NeighborsView<S, I> graph_view(const GraphTensors& g) {
  return smg::NeighborsView<S, I>(cptr<I>(g.indices), cptr<S>(g.weights), g.n, g.k);
}

// Library names that differ from the Python arguments (for ok()): the energies' `rotations` are
// the caller's quats; the skin blend's `positions` and `quaternions` are the nodes'.
inline constexpr Names kEnergyNames = {{"rotations", "quats"}, {"grad_rotations", "grad_quats"}};
inline constexpr Names kSkinNames = {{"positions", "node_positions"}, {"quaternions", "node_quats"}};

// The checked tensors of an energy call (node_confidences, carap, arap, lrm), on positions'
// device: x [T, N, 3]; q [T, N, 4], c [T, N] and vis [T, N] uint8 when given.
struct EnergyInputs {
  Reference ref;
  at::Tensor x, q, c, vis;
  GraphTensors g;
  int64_t T = 0, N = 0;
};

// The checked tensors of a dqb call, on node_positions' device: x [T, N, 3], q [T, N, 4],
// points [P, 3], point quaternions [P, 4] or undefined, sigma [N] (forward), graph (forward);
// anchor [P], t_ref [P] and t_query [Q] as int32.
struct SkinInputs {
  Reference ref;
  at::Tensor x, q, pts, pq, sigma, anchor, t_ref, t_query;
  GraphTensors g;
  int64_t T = 0, N = 0, P = 0, Q = 0;
};

// The CUDA implementations (smg_torch_cuda.cu), on checked inputs and allocated outputs; null
// in a build without CUDA. The energies return the energy as a 0-dim tensor of the inputs' dtype.
struct CudaOps {
  void (*node_confidences)(const EnergyInputs&, const smg::ConfidenceOptions&, bool validate,
                           const at::Tensor& out) = nullptr;
  at::Tensor (*carap)(const EnergyInputs&, const CarapCall&, bool validate, const at::Tensor& gx,
                      const at::Tensor& gq) = nullptr;
  at::Tensor (*lrm)(const EnergyInputs&, const smg::LrmOptions&, bool validate,
                    const at::Tensor& gx) = nullptr;
  // The fused step: energies [3] (float64: carap, arap, lrm) overwritten; conf, gx, gq filled or
  // added to when defined.
  void (*regularizers)(const EnergyInputs&, const smg::RegularizerOptions&, bool validate,
                       const at::Tensor& energies, const at::Tensor& conf, const at::Tensor& gx,
                       const at::Tensor& gq) = nullptr;
  // Exact point KNN (G15): points [N, 3] (finite, checked by the caller), into indices int64
  // [N, k] and squared distances [N, k] of points' dtype, on points' device.
  void (*point_knn)(const Reference& ref, const at::Tensor& points, int k, double radius,
                    bool include_self, const at::Tensor& indices, const at::Tensor& distances2) = nullptr;
  void (*dqb_forward)(const SkinInputs&, const smg::SkinOptions&, const at::Tensor& drivers,
                      const at::Tensor& weights, const at::Tensor& out_x,
                      const at::Tensor& out_q) = nullptr;
  void (*dqb_backward)(const SkinInputs&, const smg::SkinOptions&, const at::Tensor& drivers,
                       const at::Tensor& weights, const at::Tensor& grad_x, const at::Tensor& grad_q,
                       const at::Tensor& gx, const at::Tensor& gq, const at::Tensor& gp,
                       const at::Tensor& gpq) = nullptr;
};

inline CudaOps& cuda_ops() {
  static CudaOps ops;
  return ops;
}

// CUDA implementation `f` of cuda_ops() (set in a CUDA build whenever a CUDA reference passed
// reference()); NotImplementedError in a build without CUDA.
template <class F>
F& cuda(F& f) {
  if (!f) not_implemented(kNoCudaMessage);
  return f;
}

// Module registration, one per source file.
void register_energy(py::module_& m);
void register_skin(py::module_& m);
void register_splat(py::module_& m);
void register_graph(py::module_& m);
void register_cuda(py::module_& m);

}  // namespace smg_torch
