// examples/torch/smg_torch_cuda.cu — smg_torch's operators on CUDA tensors: node confidences,
// C-ARAP and plain ARAP through smg/cuda/ (the same per-element maths as the CPU operators), on
// the current stream of the tensors' device. Built when torch has CUDA and nvcc is available
// (setup.py / CMake); smg_torch._C.has_cuda says whether it was.
//
// Inputs must all be on one CUDA device; contiguous tensors are read in place; graph weights of
// the other float dtype are converted. Shapes and options are checked before launch (ValueError,
// one line); array contents (NaN, index range, confidences in [0, 1]) only with validate=True in
// Python, which runs the CPU validators on a host copy (one synchronising copy per call).
// smg's scratch memory comes from PyTorch's caching allocator (smg::cuda::set_allocator).
#include <optional>
#include <string>
#include <vector>

#include <ATen/ATen.h>
#include <c10/cuda/CUDACachingAllocator.h>
#include <c10/cuda/CUDAGuard.h>
#include <c10/cuda/CUDAStream.h>
#include <torch/csrc/utils/pybind.h>
#include <pybind11/stl.h>

#include "smg/cuda/carap.cuh"
#include "smg/cuda/confidence.cuh"
#include "smg/cuda/validate.cuh"

namespace smg_torch {

namespace py = pybind11;

namespace {

using OptTensor = std::optional<at::Tensor>;

[[noreturn]] void value_error(const std::string& m) { throw py::value_error(m); }
void ok(const smg::Status& s) {
  if (!s) value_error(s.message());
}

std::string shape_of(const at::Tensor& t) {
  std::string s = "[";
  for (int64_t d = 0; d < t.dim(); ++d) s += (d ? ", " : "") + std::to_string(t.size(d));
  return s + "]";
}

// Every tensor on positions' CUDA device; float tensors of positions' dtype; made contiguous.
struct CudaInputs {
  at::ScalarType st;
  at::Device device{at::kCUDA};
  at::Tensor x, q, c, idx, w, vis;
  int64_t T = 0, N = 0, K = 0;
  bool int64 = false;
};

at::Tensor on_device(const at::Tensor& t, const char* name, const at::Device& d) {
  if (!t.is_cuda() || t.device() != d)
    value_error(std::string(name) + ": expected a tensor on " + d.str() + " like positions, got " +
                t.device().str());
  return t.contiguous();
}

at::Tensor float_on(const at::Tensor& t, const char* name, const CudaInputs& in, int64_t rank,
                    int64_t last, const char* layout) {
  at::Tensor r = on_device(t, name, in.device);
  if (r.scalar_type() != in.st)
    value_error(std::string(name) + ": dtype " + std::string(c10::toString(r.scalar_type())) +
                " does not match positions (" + std::string(c10::toString(in.st)) + ")");
  if (r.dim() != rank || (last >= 0 && r.size(rank - 1) != last))
    value_error(std::string(name) + ": expected shape " + layout + ", got " + shape_of(r));
  return r;
}

CudaInputs prepare(const at::Tensor& positions, const OptTensor& quats, const at::Tensor& indices,
                   const at::Tensor& weights, const OptTensor& confidence) {
  CudaInputs in;
  if (!positions.is_cuda()) value_error("positions: expected a CUDA tensor");
  in.device = positions.device();
  in.st = positions.scalar_type();
  if (in.st != at::kFloat && in.st != at::kDouble)
    value_error("positions: dtype must be float32 or float64, got " +
                std::string(c10::toString(in.st)));
  in.x = float_on(positions, "positions", in, 3, 3, "[T, N, 3]");
  in.T = in.x.size(0);
  in.N = in.x.size(1);
  if (quats) in.q = float_on(*quats, "quats", in, 3, 4, "[T, N, 4]");
  if (confidence) in.c = float_on(*confidence, "confidence", in, 2, -1, "[T, N]");
  in.idx = on_device(indices, "graph.indices", in.device);
  if (in.idx.dim() != 2) value_error("graph.indices: expected shape [N, K], got " + shape_of(in.idx));
  if (in.idx.scalar_type() != at::kInt && in.idx.scalar_type() != at::kLong)
    value_error("graph.indices: dtype must be int32 or int64");
  in.int64 = in.idx.scalar_type() == at::kLong;
  in.w = on_device(weights, "graph.weights", in.device);
  if (in.w.dim() != 2 || in.w.size(0) != in.idx.size(0) || in.w.size(1) != in.idx.size(1))
    value_error("graph.weights: expected shape " + shape_of(in.idx) + " like graph.indices, got " +
                shape_of(in.w));
  if (in.w.scalar_type() != at::kFloat && in.w.scalar_type() != at::kDouble)
    value_error("graph.weights: dtype must be float32 or float64");
  in.w = in.w.to(in.st).contiguous();
  in.K = in.idx.size(1);
  return in;
}

template <class F>
auto dispatch(const CudaInputs& in, F&& f) {
  if (in.st == at::kFloat) {
    if (in.int64) return f(float{}, std::int64_t{});
    return f(float{}, std::int32_t{});
  }
  if (in.int64) return f(double{}, std::int64_t{});
  return f(double{}, std::int32_t{});
}

template <class S>
const S* cptr(const at::Tensor& t) {
  return t.defined() && t.numel() ? t.data_ptr<S>() : nullptr;
}
template <class S>
S* mptr(const at::Tensor& t) {
  return t.defined() && t.numel() ? t.data_ptr<S>() : nullptr;
}

template <class S, class I>
smg::NeighborsView<S, I> graph_view(const CudaInputs& in) {
  return smg::NeighborsView<S, I>(cptr<I>(in.idx), cptr<S>(in.w), in.N, in.K);
}

at::Tensor node_confidences_cuda(const at::Tensor& positions, const at::Tensor& indices,
                                 const at::Tensor& weights, const OptTensor& visibility,
                                 double kappa_m, double kappa_r, double lambda_m, double lambda_r,
                                 double eps, bool validate) {
  CudaInputs in = prepare(positions, std::nullopt, indices, weights, std::nullopt);
  const c10::cuda::CUDAGuard guard(in.device);
  if (visibility) {
    at::Tensor v = on_device(*visibility, "visibility", in.device);
    if (v.dim() != 2) value_error("visibility: expected shape [T, N], got " + shape_of(v));
    in.vis = v.scalar_type() == at::kByte ? v : (v != 0).to(at::kByte).contiguous();
  }
  smg::ConfidenceOptions o;
  o.kappa_m = kappa_m;
  o.kappa_r = kappa_r;
  o.lambda_m = lambda_m;
  o.lambda_r = lambda_r;
  o.eps = eps;
  at::Tensor out = at::empty({in.T, in.N}, in.x.options());
  const cudaStream_t stream = c10::cuda::getCurrentCUDAStream(in.device.index()).stream();
  dispatch(in, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    smg::VisibilityView<const std::uint8_t> vv;
    if (in.vis.defined()) vv = {in.vis.data_ptr<std::uint8_t>(), in.vis.size(0), in.vis.size(1)};
    if (validate)
      ok(smg::cuda::validate_confidence<S, I>({cptr<S>(in.x), in.T, in.N}, vv, graph_view<S, I>(in),
                                              o, {mptr<S>(out), in.T, in.N}, stream));
    ok(smg::cuda::node_confidences<S, I>({cptr<S>(in.x), in.T, in.N}, vv, graph_view<S, I>(in), o,
                                         {mptr<S>(out), in.T, in.N}, {}, {}, stream));
    return 0;
  });
  return out;
}

py::tuple carap_cuda(bool plain, const at::Tensor& positions, const at::Tensor& quats,
                     const at::Tensor& indices, const at::Tensor& weights,
                     const OptTensor& confidence, double alpha, double lambda_c, double lambda_l,
                     const std::vector<int64_t>& gaps,
                     const std::optional<std::vector<double>>& gap_weights, bool normalize,
                     bool grad_x, bool grad_q, bool validate) {
  CudaInputs in = prepare(positions, quats, indices, weights, plain ? std::nullopt : confidence);
  const c10::cuda::CUDAGuard guard(in.device);
  if (gaps.empty()) value_error("gaps: needs at least one gap");
  if (gap_weights && gap_weights->size() != gaps.size())
    value_error("gap_weights: needs one weight per gap");
  smg::CarapOptions co;
  smg::ArapOptions ao;
  co.alpha = alpha;
  co.lambda_c = ao.lambda_c = lambda_c;
  co.lambda_l = ao.lambda_l = lambda_l;
  smg::GapList list;
  for (std::size_t k = 0; k < gaps.size(); ++k) {
    if (gaps[k] < 1 || gaps[k] > 1000000) value_error("gaps: entries must be integers >= 1");
    list.push_back({static_cast<int>(gaps[k]), gap_weights ? (*gap_weights)[k] : 1.0});
  }
  co.gaps = ao.gaps = list;
  co.normalization = ao.normalization = normalize ? smg::Normalization::mean : smg::Normalization::sum;
  at::Tensor gx, gq;
  if (grad_x) gx = at::zeros({in.T, in.N, 3}, in.x.options());
  if (grad_q) gq = at::zeros({in.T, in.N, 4}, in.x.options());
  at::Tensor energy = at::empty({}, in.x.options().dtype(at::kDouble));
  const cudaStream_t stream = c10::cuda::getCurrentCUDAStream(in.device.index()).stream();
  dispatch(in, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto gv = graph_view<S, I>(in);
    smg::cuda::ReverseGraph rev;
    ok(smg::cuda::build_reverse_graph(cptr<I>(in.idx), in.N, in.K, stream, rev));
    using Acc = smg::Accumulator<S>;
    Acc* e = reinterpret_cast<Acc*>(energy.data_ptr<double>());
    const smg::PositionsView<S> gxv =
        grad_x ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N) : smg::PositionsView<S>();
    smg::RotationGradientView<S> gqv;
    if (grad_q) gqv = smg::QuaternionsView<S>(mptr<S>(gq), in.T, in.N);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const smg::QuaternionsView<const S> qv(cptr<S>(in.q), in.T, in.N);
    if (validate && plain) ok(smg::cuda::validate_arap<S, I>(xv, qv, gv, ao, gxv, gqv, stream));
    if (validate && !plain) {
      smg::FrameScalarsView<const S> cv;
      if (in.c.defined()) cv = {cptr<S>(in.c), in.c.size(0), in.c.size(1)};
      ok(smg::cuda::validate_carap<S, I>(xv, qv, cv, gv, co, gxv, gqv, stream));
    }
    if (plain) {
      ok(smg::cuda::arap<S, I>(xv, qv, gv, ao, rev, e, gxv, gqv, stream));
    } else {
      smg::FrameScalarsView<const S> cv;
      if (in.c.defined()) cv = {cptr<S>(in.c), in.c.size(0), in.c.size(1)};
      ok(smg::cuda::carap<S, I>(xv, qv, cv, gv, co, rev, e, gxv, gqv, stream));
    }
    return 0;
  });
  auto opt = [](const at::Tensor& t) { return t.defined() ? py::cast(t) : py::none(); };
  return py::make_tuple(energy.to(in.st), opt(gx), opt(gq));
}

// smg's scratch from PyTorch's CUDA caching allocator (stream-aware: a block freed on a stream
// is reused on it without synchronisation).
void* torch_allocate(std::size_t bytes, cudaStream_t stream, void*) {
  try {
    return c10::cuda::CUDACachingAllocator::raw_alloc_with_stream(bytes, stream);
  } catch (const std::exception&) {
    return nullptr;  // smg reports "could not allocate N bytes"
  }
}
void torch_deallocate(void* p, cudaStream_t, void*) { c10::cuda::CUDACachingAllocator::raw_delete(p); }

}  // namespace

void register_cuda(py::module_& m) {
  using namespace pybind11::literals;
  smg::cuda::set_allocator({&torch_allocate, &torch_deallocate, nullptr});
  m.attr("has_cuda") = true;
  m.def("cuda_node_confidences", &node_confidences_cuda, "positions"_a, "indices"_a, "weights"_a,
        "visibility"_a, "kappa_m"_a, "kappa_r"_a, "lambda_m"_a, "lambda_r"_a, "eps"_a, "validate"_a);
  m.def(
      "cuda_carap",
      [](const at::Tensor& x, const at::Tensor& q, const at::Tensor& idx, const at::Tensor& w,
         const OptTensor& c, double alpha, double lc, double ll, const std::vector<int64_t>& gaps,
         const std::optional<std::vector<double>>& gw, bool normalize, bool gx, bool gq,
         bool validate) {
        return carap_cuda(false, x, q, idx, w, c, alpha, lc, ll, gaps, gw, normalize, gx, gq,
                          validate);
      },
      "positions"_a, "quats"_a, "indices"_a, "weights"_a, "confidence"_a, "alpha"_a, "lambda_c"_a,
      "lambda_l"_a, "gaps"_a, "gap_weights"_a, "normalize"_a, "grad_positions"_a, "grad_quats"_a,
      "validate"_a);
  m.def(
      "cuda_arap",
      [](const at::Tensor& x, const at::Tensor& q, const at::Tensor& idx, const at::Tensor& w,
         double lc, double ll, const std::vector<int64_t>& gaps,
         const std::optional<std::vector<double>>& gw, bool normalize, bool gx, bool gq,
         bool validate) {
        return carap_cuda(true, x, q, idx, w, std::nullopt, 1.0, lc, ll, gaps, gw, normalize, gx,
                          gq, validate);
      },
      "positions"_a, "quats"_a, "indices"_a, "weights"_a, "lambda_c"_a, "lambda_l"_a, "gaps"_a,
      "gap_weights"_a, "normalize"_a, "grad_positions"_a, "grad_quats"_a, "validate"_a);
}

}  // namespace smg_torch
