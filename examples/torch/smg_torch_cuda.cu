// examples/torch/smg_torch_cuda.cu — smg_torch's operators on CUDA tensors: node confidences,
// C-ARAP, plain ARAP, LRM and DQB/LBS skinning through smg/cuda/ (the same per-element maths as
// the CPU operators), on the current stream of the tensors' device. Built when torch has CUDA and
// nvcc is available (setup.py / CMake); smg_torch._C.has_cuda says whether it was.
//
// Inputs must all be on one CUDA device; contiguous tensors are read in place; graph weights of
// the other float dtype are converted. Shapes and options are checked before launch (ValueError,
// one line); array contents (NaN, index range, confidences in [0, 1]) only with validate=True in
// Python, which runs the CPU validators on a host copy (one synchronising copy per call) — except
// for dqb, which always checks its index ranges and sigma > 0 on the device (one synchronising
// copy of the flags, the CPU operator's messages).
// smg's scratch memory comes from PyTorch's caching allocator (smg::cuda::set_allocator).
#include <cmath>
#include <optional>
#include <sstream>
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
#include "smg/cuda/dqb.cuh"
#include "smg/cuda/lrm.cuh"
#include "smg/cuda/skin_weights.cuh"
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

py::tuple lrm_cuda(const at::Tensor& positions, const at::Tensor& indices, const at::Tensor& weights,
                   const OptTensor& confidence, double alpha, double huber_delta, bool detach_omega,
                   bool normalize, bool grad_x, bool validate) {
  CudaInputs in = prepare(positions, std::nullopt, indices, weights, confidence);
  const c10::cuda::CUDAGuard guard(in.device);
  smg::LrmOptions o;
  o.alpha = alpha;
  o.huber_delta = huber_delta;
  o.detach_omega = detach_omega;
  o.normalization = normalize ? smg::Normalization::mean : smg::Normalization::sum;
  at::Tensor gx;
  if (grad_x) gx = at::zeros({in.T, in.N, 3}, in.x.options());
  at::Tensor energy = at::empty({}, in.x.options().dtype(at::kDouble));
  const cudaStream_t stream = c10::cuda::getCurrentCUDAStream(in.device.index()).stream();
  dispatch(in, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto gv = graph_view<S, I>(in);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    smg::FrameScalarsView<const S> cv;
    if (in.c.defined()) cv = {cptr<S>(in.c), in.c.size(0), in.c.size(1)};
    const smg::PositionsView<S> gxv =
        grad_x ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N) : smg::PositionsView<S>();
    if (validate) ok(smg::cuda::validate_lrm<S, I>(xv, cv, gv, o, gxv, {}, stream));
    smg::cuda::ReverseGraph rev;
    ok(smg::cuda::build_reverse_graph(cptr<I>(in.idx), in.N, in.K, stream, rev));
    using Acc = smg::Accumulator<S>;
    ok(smg::cuda::lrm<S, I>(xv, cv, gv, o, rev, reinterpret_cast<Acc*>(energy.data_ptr<double>()),
                            gxv, {}, stream));
    return 0;
  });
  return py::make_tuple(energy.to(in.st), gx.defined() ? py::cast(gx) : py::none());
}

// dqb: every tensor on node_positions' device. The index inputs (anchor, t_ref, t_query; any
// integer dtype) become int32 copies; node quaternions, points, point quaternions and sigma must
// have node_positions' dtype.
struct DqbInputs {
  CudaInputs n;  // x, q (and the graph in the forward)
  at::Tensor pts, pq, t_ref, t_query;
  int64_t P = 0, Q = 0;
};

at::Tensor index_on(const at::Tensor& t, const char* name, const at::Device& d) {
  at::Tensor r = on_device(t, name, d);
  if (r.dim() != 1) value_error(std::string(name) + ": expected shape [n], got " + shape_of(r));
  if (at::isFloatingType(r.scalar_type()) || r.scalar_type() == at::kBool)
    value_error(std::string(name) + ": dtype must be an integer type, got " +
                std::string(c10::toString(r.scalar_type())));
  return r;
}

DqbInputs prepare_dqb(const at::Tensor& node_positions, const at::Tensor& node_quats,
                      const at::Tensor& points, const OptTensor& point_quats,
                      const at::Tensor& t_ref, const at::Tensor& t_query) {
  DqbInputs in;
  CudaInputs& n = in.n;
  if (!node_positions.is_cuda()) value_error("node_positions: expected a CUDA tensor");
  n.device = node_positions.device();
  n.st = node_positions.scalar_type();
  if (n.st != at::kFloat && n.st != at::kDouble)
    value_error("node_positions: dtype must be float32 or float64, got " +
                std::string(c10::toString(n.st)));
  n.x = float_on(node_positions, "node_positions", n, 3, 3, "[T, N, 3]");
  n.T = n.x.size(0);
  n.N = n.x.size(1);
  n.q = float_on(node_quats, "node_quats", n, 3, 4, "[T, N, 4]");
  if (n.q.size(0) != n.T || n.q.size(1) != n.N)
    value_error("node_quats: expected shape [T=" + std::to_string(n.T) + ", N=" +
                std::to_string(n.N) + ", 4] like node_positions, got " + shape_of(n.q));
  in.pts = float_on(points, "points", n, 2, 3, "[P, 3]");
  in.P = in.pts.size(0);
  if (point_quats) {
    in.pq = float_on(*point_quats, "point_quats", n, 2, 4, "[P, 4]");
    if (in.pq.size(0) != in.P)
      value_error("point_quats: expected shape [P=" + std::to_string(in.P) + ", 4], got " +
                  shape_of(in.pq));
  }
  in.t_ref = index_on(t_ref, "t_ref", n.device);
  if (in.t_ref.numel() != in.P)
    value_error("t_ref: expected shape [P=" + std::to_string(in.P) + "], got " + shape_of(t_ref));
  in.t_query = index_on(t_query, "t_query", n.device);
  in.Q = in.t_query.numel();
  return in;
}

// What the CPU operator checks in the arrays' contents that the kernels rely on to stay in
// bounds or meaningful: index values in range, graph indices in [−1, N), sigma > 0 and finite.
// One synchronising copy of the flags; the messages are the CPU's.
struct RangeCheck {
  at::Tensor t;
  std::string name;
  int64_t lo, hi;
  const char* bound_name;
  bool graph;  // a [N, K] neighbour table (message with i, k)
};

void check_contents(const std::vector<RangeCheck>& checks, const at::Tensor& sigma) {
  std::vector<at::Tensor> bad;
  for (const auto& c : checks) bad.push_back(((c.t < c.lo) | (c.t >= c.hi)).any());
  bad.push_back((~(sigma > 0) | ~at::isfinite(sigma)).any());
  const at::Tensor flags = at::stack(bad).cpu();
  const bool* f = flags.data_ptr<bool>();
  for (std::size_t k = 0; k < checks.size(); ++k) {
    if (!f[k]) continue;
    const RangeCheck& c = checks[k];
    const at::Tensor flat = c.t.reshape({-1});
    const int64_t i = at::nonzero((flat < c.lo) | (flat >= c.hi)).view({-1})[0].item<int64_t>();
    const int64_t v = flat[i].item<int64_t>();
    if (c.graph) {
      const int64_t K = c.t.size(1);
      value_error(c.name + ": entry [i=" + std::to_string(i / K) + "][k=" + std::to_string(i % K) +
                  "] is out of range: " + std::to_string(v));
    }
    value_error(c.name + ": element [" + std::to_string(i) + "] = " + std::to_string(v) +
                " is out of range [0, " + c.bound_name + "=" + std::to_string(c.hi) + ")");
  }
  if (f[checks.size()]) {
    const int64_t i =
        at::nonzero(~(sigma > 0) | ~at::isfinite(sigma)).view({-1})[0].item<int64_t>();
    const double v = sigma[i].item<double>();
    std::ostringstream m;  // the CPU's messages (validate_skin_sigma)
    m << "sigma: element [" << i << "]";
    if (std::isfinite(v))
      m << " = " << v << " is not positive";
    else
      m << " is " << (std::isnan(v) ? "NaN" : "Inf");
    value_error(m.str());
  }
}

template <class S>
smg::SkinNodes<S> dqb_nodes(const DqbInputs& in) {
  return {smg::PositionsView<const S>(cptr<S>(in.n.x), in.n.T, in.n.N),
          smg::QuaternionsView<const S>(cptr<S>(in.n.q), in.n.T, in.n.N)};
}

template <class S>
smg::SkinPoints<S> dqb_points(const DqbInputs& in, const at::Tensor& drivers,
                              const at::Tensor& weights) {
  smg::SkinPoints<S> p;
  p.drivers = smg::SkinDriversView(cptr<std::int32_t>(drivers), in.P, drivers.size(1));
  p.weights = smg::TableView<const S, Eigen::Dynamic>(cptr<S>(weights), in.P, weights.size(1));
  p.t_ref = smg::SkinIndexView(cptr<std::int32_t>(in.t_ref), in.P);
  p.positions = smg::TableView<const S, 3>(cptr<S>(in.pts), in.P);
  if (in.pq.defined()) p.quaternions = smg::TableView<const S, 4>(cptr<S>(in.pq), in.P);
  return p;
}

// -> (positions [Q, P, 3], quaternions [Q, P, 4], drivers [P, K+1] int32, weights [P, K+1]):
// _C.dqb_forward on the device (smg::cuda::skin_drivers, skinning_weights, skin_blend).
py::tuple dqb_forward_cuda(const at::Tensor& node_positions, const at::Tensor& node_quats,
                           const at::Tensor& indices, const at::Tensor& gweights,
                           const at::Tensor& points, const OptTensor& point_quats,
                           const at::Tensor& anchor, const at::Tensor& t_ref,
                           const at::Tensor& t_query, const at::Tensor& sigma, bool lbs) {
  DqbInputs in = prepare_dqb(node_positions, node_quats, points, point_quats, t_ref, t_query);
  CudaInputs& n = in.n;
  const c10::cuda::CUDAGuard guard(n.device);
  n.idx = on_device(indices, "graph.indices", n.device);
  if (n.idx.dim() != 2 || n.idx.size(0) != n.N)
    value_error("graph.indices: expected shape [N=" + std::to_string(n.N) + ", K], got " +
                shape_of(n.idx));
  if (n.idx.scalar_type() != at::kInt && n.idx.scalar_type() != at::kLong)
    value_error("graph.indices: dtype must be int32 or int64");
  n.int64 = n.idx.scalar_type() == at::kLong;
  n.w = on_device(gweights, "graph.weights", n.device);
  if (n.w.dim() != 2 || n.w.size(0) != n.idx.size(0) || n.w.size(1) != n.idx.size(1))
    value_error("graph.weights: expected shape " + shape_of(n.idx) + " like graph.indices, got " +
                shape_of(n.w));
  if (n.w.scalar_type() != at::kFloat && n.w.scalar_type() != at::kDouble)
    value_error("graph.weights: dtype must be float32 or float64");
  n.w = n.w.to(n.st).contiguous();
  n.K = n.idx.size(1);
  const at::Tensor a = index_on(anchor, "anchor", n.device);
  if (a.numel() != in.P)
    value_error("anchor: expected shape [P=" + std::to_string(in.P) + "], got " + shape_of(anchor));
  const at::Tensor sg = float_on(sigma, "sigma", n, 1, -1, "[N]");
  if (sg.size(0) != n.N)
    value_error("sigma: expected shape [N=" + std::to_string(n.N) + "], got " + shape_of(sg));
  check_contents({{n.idx, "graph", -1, n.N, "N", true},
                  {a, "anchor", 0, n.N, "N", false},
                  {in.t_ref, "t_ref", 0, n.T, "T", false},
                  {in.t_query, "t_query", 0, n.T, "T", false}},
                 sg);
  const at::Tensor anchor32 = a.to(at::kInt).contiguous();
  in.t_ref = in.t_ref.to(at::kInt).contiguous();
  in.t_query = in.t_query.to(at::kInt).contiguous();
  const int64_t D = n.K + 1;
  at::Tensor drivers = at::empty({in.P, D}, n.x.options().dtype(at::kInt));
  at::Tensor weights = at::empty({in.P, D}, n.x.options());
  at::Tensor out_x = at::empty({in.Q, in.P, 3}, n.x.options());
  at::Tensor out_q = at::empty({in.Q, in.P, 4}, n.x.options());
  const cudaStream_t stream = c10::cuda::getCurrentCUDAStream(n.device.index()).stream();
  dispatch(n, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    ok(smg::cuda::skin_drivers(graph_view<S, I>(n), smg::SkinIndexView(cptr<std::int32_t>(anchor32), in.P),
                               smg::TableView<std::int32_t, Eigen::Dynamic>(
                                   mptr<std::int32_t>(drivers), in.P, D),
                               stream));
    const auto nodes = dqb_nodes<S>(in);
    ok(smg::cuda::skinning_weights<S>(
        nodes.positions, smg::SkinDriversView(cptr<std::int32_t>(drivers), in.P, D),
        smg::SkinIndexView(cptr<std::int32_t>(in.t_ref), in.P),
        smg::TableView<const S, 3>(cptr<S>(in.pts), in.P),
        smg::TableView<const S, 1>(cptr<S>(sg), n.N),
        smg::TableView<S, Eigen::Dynamic>(mptr<S>(weights), in.P, D), stream));
    smg::SkinBlendOutputs<S> o;
    o.positions = {mptr<S>(out_x), in.Q, in.P};
    o.quaternions = {mptr<S>(out_q), in.Q, in.P};
    smg::SkinOptions opt;
    opt.method = lbs ? smg::SkinMethod::lbs : smg::SkinMethod::dqb;
    ok(smg::cuda::skin_blend(nodes, dqb_points<S>(in, drivers, weights),
                             smg::SkinIndexView(cptr<std::int32_t>(in.t_query), in.Q), o, opt,
                             stream));
    return 0;
  });
  return py::make_tuple(out_x, out_q, drivers, weights);
}

// -> (grad node_positions, grad node_quats (raw), grad points, grad point_quats (raw)); each
// None unless requested: _C.dqb_backward on the device (smg::cuda::skin_blend_backward).
py::tuple dqb_backward_cuda(const at::Tensor& node_positions, const at::Tensor& node_quats,
                            const at::Tensor& points, const OptTensor& point_quats,
                            const at::Tensor& t_ref, const at::Tensor& t_query,
                            const at::Tensor& drivers, const at::Tensor& weights,
                            const OptTensor& grad_positions, const OptTensor& grad_quats, bool lbs,
                            bool need_x, bool need_q, bool need_p, bool need_pq) {
  DqbInputs in = prepare_dqb(node_positions, node_quats, points, point_quats, t_ref, t_query);
  const CudaInputs& n = in.n;
  const c10::cuda::CUDAGuard guard(n.device);
  // t_ref and t_query are the tensors the forward range-checked.
  in.t_ref = in.t_ref.to(at::kInt).contiguous();
  in.t_query = in.t_query.to(at::kInt).contiguous();
  const at::Tensor drv = on_device(drivers, "drivers", n.device);
  if (drv.scalar_type() != at::kInt || drv.dim() != 2 || drv.size(0) != in.P)
    value_error("drivers: expected an int32 tensor [P=" + std::to_string(in.P) + ", D], got " +
                shape_of(drv));
  const at::Tensor wts = float_on(weights, "weights", n, 2, drv.size(1), "[P, D] like drivers");
  if (wts.size(0) != in.P)
    value_error("weights: expected shape " + shape_of(drv) + " like drivers, got " + shape_of(wts));
  at::Tensor gop, goq;
  if (grad_positions) {
    gop = float_on(*grad_positions, "grad_positions", n, 3, 3, "[Q, P, 3]");
    if (gop.size(0) != in.Q || gop.size(1) != in.P)
      value_error("grad_positions: expected shape [Q, P, 3], got " + shape_of(gop));
  }
  if (grad_quats) {
    goq = float_on(*grad_quats, "grad_quats", n, 3, 4, "[Q, P, 4]");
    if (goq.size(0) != in.Q || goq.size(1) != in.P)
      value_error("grad_quats: expected shape [Q, P, 4], got " + shape_of(goq));
  }
  at::Tensor gx, gq, gp, gpq;
  if (need_x) gx = at::zeros({n.T, n.N, 3}, n.x.options());
  if (need_q) gq = at::zeros({n.T, n.N, 4}, n.x.options());
  if (need_p) gp = at::zeros({in.P, 3}, n.x.options());
  if (need_pq && in.pq.defined()) gpq = at::zeros({in.P, 4}, n.x.options());
  const cudaStream_t stream = c10::cuda::getCurrentCUDAStream(n.device.index()).stream();
  dispatch(n, [&](auto s, auto) {
    using S = decltype(s);
    const auto pts = dqb_points<S>(in, drv, wts);
    smg::SkinBlendOutputGradients<S> go;
    if (gop.defined()) go.positions = {cptr<S>(gop), in.Q, in.P};
    if (goq.defined()) go.quaternions = {cptr<S>(goq), in.Q, in.P};
    smg::SkinBlendGradients<S> gr;
    if (gx.defined()) gr.node_positions = {mptr<S>(gx), n.T, n.N};
    if (gq.defined()) gr.node_quaternions = {mptr<S>(gq), n.T, n.N};
    if (gp.defined()) gr.points = {mptr<S>(gp), in.P};
    if (gpq.defined()) gr.point_quaternions = {mptr<S>(gpq), in.P};
    smg::cuda::ReverseGraph incidence;
    if (gx.defined() || gq.defined())
      ok(smg::cuda::build_driver_incidence(cptr<std::int32_t>(drv), in.P, drv.size(1), n.N, stream,
                                           incidence));
    smg::SkinOptions opt;
    opt.method = lbs ? smg::SkinMethod::lbs : smg::SkinMethod::dqb;
    ok(smg::cuda::skin_blend_backward(dqb_nodes<S>(in), pts,
                                      smg::SkinIndexView(cptr<std::int32_t>(in.t_query), in.Q), go,
                                      gr, incidence, opt, stream));
    return 0;
  });
  auto opt = [](const at::Tensor& t) { return t.defined() ? py::cast(t) : py::none(); };
  return py::make_tuple(opt(gx), opt(gq), opt(gp), opt(gpq));
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
  m.def("cuda_lrm", &lrm_cuda, "positions"_a, "indices"_a, "weights"_a, "confidence"_a, "alpha"_a,
        "huber_delta"_a, "detach_omega"_a, "normalize"_a, "grad_positions"_a, "validate"_a);
  m.def("cuda_dqb_forward", &dqb_forward_cuda, "node_positions"_a, "node_quats"_a, "indices"_a,
        "weights"_a, "points"_a, "point_quats"_a, "anchor"_a, "t_ref"_a, "t_query"_a, "sigma"_a,
        "lbs"_a);
  m.def("cuda_dqb_backward", &dqb_backward_cuda, "node_positions"_a, "node_quats"_a, "points"_a,
        "point_quats"_a, "t_ref"_a, "t_query"_a, "drivers"_a, "weights"_a, "grad_positions"_a,
        "grad_quats"_a, "lbs"_a, "need_x"_a, "need_q"_a, "need_p"_a, "need_pq"_a);
}

}  // namespace smg_torch
