// examples/torch/smg_torch_cuda.cu — the CUDA launches of smg_torch's operators: node
// confidences, C-ARAP, plain ARAP, LRM, the fused step (regularizers) and DQB/LBS skinning through smg/cuda/ (the same
// per-element maths as the CPU operators), on the current stream of the tensors' device. Built
// when torch has CUDA and nvcc is available (setup.py); smg_torch._C.has_cuda says whether it was.
//
// Everything else is shared with the CPU operators (smg_torch_common.hpp): each operator's .cpp
// checks the arguments (all on positions' device), builds the options, allocates the outputs and
// calls the function registered here in cuda_ops() when positions is a CUDA tensor. Array contents
// (NaN, index range, confidences in [0, 1]) are checked only with validate=True: the energies'
// here, by the CPU validators on a host copy (one synchronising copy per call); dqb's index
// ranges, sigma and incoming gradients by the shared code (smg_torch_skin.cpp). Without
// validate=True nothing is read back to the host: dqb's launches, its driver incidence included,
// are stream-ordered and never synchronise.
// smg's scratch memory comes from PyTorch's caching allocator (smg::cuda::set_allocator).
#include <type_traits>

#include <c10/cuda/CUDACachingAllocator.h>
#include <c10/cuda/CUDAGuard.h>
#include <c10/cuda/CUDAStream.h>

#include "smg/cuda/carap.cuh"
#include "smg/cuda/confidence.cuh"
#include "smg/cuda/dqb.cuh"
#include "smg/cuda/lrm.cuh"
#include "smg/cuda/point_knn.cuh"
#include "smg/cuda/regularizers.cuh"
#include "smg/cuda/skin_weights.cuh"
#include "smg/cuda/validate.cuh"
#include "smg_torch_common.hpp"
#include "smg_torch_skin_views.hpp"

namespace smg_torch {

namespace {

cudaStream_t stream_of(const Reference& r) {
  return c10::cuda::getCurrentCUDAStream(r.device.index()).stream();
}

template <class S>
smg::FrameScalarsView<const S> conf_view(const EnergyInputs& in) {
  if (!in.c.defined()) return {};
  return {cptr<S>(in.c), in.c.size(0), in.c.size(1)};
}

template <class S>
smg::PositionsView<S> grad_view(const EnergyInputs& in, const at::Tensor& gx) {
  return gx.defined() ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N) : smg::PositionsView<S>();
}

void confidences_cuda(const EnergyInputs& in, const smg::ConfidenceOptions& o, bool validate,
                      const at::Tensor& out) {
  const c10::cuda::CUDAGuard guard(in.ref.device);
  const cudaStream_t stream = stream_of(in.ref);
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    smg::VisibilityView<const std::uint8_t> vv;
    if (in.vis.defined()) vv = {cptr<std::uint8_t>(in.vis), in.vis.size(0), in.vis.size(1)};
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const smg::FrameScalarsView<S> cv(mptr<S>(out), in.T, in.N);
    const auto gv = graph_view<S, I>(in.g);
    if (validate) ok(smg::cuda::validate_confidence<S, I>(xv, vv, gv, o, cv, stream), kEnergyNames);
    ok(smg::cuda::node_confidences<S, I>(xv, vv, gv, o, cv, {}, {}, stream), kEnergyNames);
    return 0;
  });
}

// carap / arap -> the energy (0-dim, the inputs' dtype); gradients into gx, gq when defined.
at::Tensor carap_cuda(const EnergyInputs& in, const CarapCall& call, bool validate,
                      const at::Tensor& gx, const at::Tensor& gq) {
  const c10::cuda::CUDAGuard guard(in.ref.device);
  const cudaStream_t stream = stream_of(in.ref);
  at::Tensor energy = at::empty({}, in.x.options().dtype(at::kDouble));
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto gv = graph_view<S, I>(in.g);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const smg::QuaternionsView<const S> qv(cptr<S>(in.q), in.T, in.N);
    const auto gxv = grad_view<S>(in, gx);
    smg::RotationGradientView<S> gqv;
    if (gq.defined()) gqv = smg::QuaternionsView<S>(mptr<S>(gq), in.T, in.N);
    auto* e = reinterpret_cast<smg::Accumulator<S>*>(energy.data_ptr<double>());
    smg::cuda::ReverseGraph rev;
    ok(smg::cuda::build_reverse_graph(cptr<I>(in.g.indices), in.N, in.g.k, stream, rev));
    if (call.plain) {
      if (validate) ok(smg::cuda::validate_arap<S, I>(xv, qv, gv, call.arap, gxv, gqv, stream), kEnergyNames);
      ok(smg::cuda::arap<S, I>(xv, qv, gv, call.arap, rev, e, gxv, gqv, stream), kEnergyNames);
    } else {
      const auto cv = conf_view<S>(in);
      if (validate)
        ok(smg::cuda::validate_carap<S, I>(xv, qv, cv, gv, call.carap, gxv, gqv, stream), kEnergyNames);
      ok(smg::cuda::carap<S, I>(xv, qv, cv, gv, call.carap, rev, e, gxv, gqv, stream), kEnergyNames);
    }
    return 0;
  });
  return energy.to(in.ref.st);
}

at::Tensor lrm_cuda(const EnergyInputs& in, const smg::LrmOptions& o, bool validate,
                    const at::Tensor& gx) {
  const c10::cuda::CUDAGuard guard(in.ref.device);
  const cudaStream_t stream = stream_of(in.ref);
  at::Tensor energy = at::empty({}, in.x.options().dtype(at::kDouble));
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto gv = graph_view<S, I>(in.g);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const auto cv = conf_view<S>(in);
    const auto gxv = grad_view<S>(in, gx);
    if (validate) ok(smg::cuda::validate_lrm<S, I>(xv, cv, gv, o, gxv, {}, stream), kEnergyNames);
    smg::cuda::ReverseGraph rev;
    ok(smg::cuda::build_reverse_graph(cptr<I>(in.g.indices), in.N, in.g.k, stream, rev));
    auto* e = reinterpret_cast<smg::Accumulator<S>*>(energy.data_ptr<double>());
    ok(smg::cuda::lrm<S, I>(xv, cv, gv, o, rev, e, gxv, {}, stream), kEnergyNames);
    return 0;
  });
  return energy.to(in.ref.st);
}

// dqb forward: smg::cuda::skin_drivers, skinning_weights and skin_blend into the outputs
// (drivers [P, D] int32, weights [P, D], positions [Q, P, 3], quaternions [Q, P, 4]).
void dqb_forward_cuda(const SkinInputs& in, const smg::SkinOptions& opt, const at::Tensor& drivers,
                      const at::Tensor& weights, const at::Tensor& out_x, const at::Tensor& out_q) {
  const c10::cuda::CUDAGuard guard(in.ref.device);
  const cudaStream_t stream = stream_of(in.ref);
  const int64_t D = drivers.size(1);
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    ok(smg::cuda::skin_drivers(graph_view<S, I>(in.g),
                               smg::SkinIndexView(cptr<std::int32_t>(in.anchor), in.P),
                               smg::TableView<std::int32_t, Eigen::Dynamic>(mptr<std::int32_t>(drivers), in.P, D),
                               stream),
       kSkinNames);
    const auto nodes = nodes_of<S>(in);
    ok(smg::cuda::skinning_weights<S>(
           nodes.positions, smg::SkinDriversView(cptr<std::int32_t>(drivers), in.P, D),
           smg::SkinIndexView(cptr<std::int32_t>(in.t_ref), in.P),
           smg::TableView<const S, 3>(cptr<S>(in.pts), in.P),
           smg::TableView<const S, 1>(cptr<S>(in.sigma), in.N),
           smg::TableView<S, Eigen::Dynamic>(mptr<S>(weights), in.P, D), stream),
       kSkinNames);
    smg::SkinBlendOutputs<S> o;
    o.positions = {mptr<S>(out_x), in.Q, in.P};
    o.quaternions = {mptr<S>(out_q), in.Q, in.P};
    ok(smg::cuda::skin_blend(nodes, points_of<S>(in, drivers, weights),
                             smg::SkinIndexView(cptr<std::int32_t>(in.t_query), in.Q), o, opt, stream),
       kSkinNames);
    return 0;
  });
}

// dqb backward: smg::cuda::skin_blend_backward into the gradients that are defined; the driver
// incidence (for the node gradients) is built on the device. Nothing is read back or
// synchronised: t_query is read by the kernels (a frame out of range is skipped there).
void dqb_backward_cuda(const SkinInputs& in, const smg::SkinOptions& opt, const at::Tensor& drivers,
                       const at::Tensor& weights, const at::Tensor& grad_x, const at::Tensor& grad_q,
                       const at::Tensor& gx, const at::Tensor& gq, const at::Tensor& gp,
                       const at::Tensor& gpq) {
  const c10::cuda::CUDAGuard guard(in.ref.device);
  const cudaStream_t stream = stream_of(in.ref);
  dispatch(in.ref.st, false, [&](auto s, auto) {
    using S = decltype(s);
    const auto go = output_gradients<S>(in, grad_x, grad_q);
    auto gr = blend_gradients<S>(in, gx, gq, gp, gpq);
    smg::cuda::ReverseGraph incidence;
    if (gx.defined() || gq.defined())
      ok(smg::cuda::build_driver_incidence(cptr<std::int32_t>(drivers), in.P, drivers.size(1), in.N,
                                           stream, incidence));
    ok(smg::cuda::skin_blend_backward(nodes_of<S>(in), points_of<S>(in, drivers, weights),
                                      smg::SkinIndexView(cptr<std::int32_t>(in.t_query), in.Q), go,
                                      gr, incidence, opt, stream),
       kSkinNames);
    return 0;
  });
}

// regularizers: smg::cuda::regularizers (the fused step) into energies [E] (float64: the
// RegularizerResult<S> of either dtype is E doubles, E = energy_names().size()), c, gx and gq
// when defined.
void regularizers_cuda(const EnergyInputs& in, const smg::RegularizerOptions& o, bool validate,
                       const at::Tensor& energies, const at::Tensor& c, const at::Tensor& gx,
                       const at::Tensor& gq) {
  const c10::cuda::CUDAGuard guard(in.ref.device);
  const cudaStream_t stream = stream_of(in.ref);
  const bool rigid = smg::reads_rotations(o.terms);  // a term that reads the rotations is on
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    static_assert(std::is_same<smg::Accumulator<S>, double>::value &&
                      sizeof(smg::RegularizerResult<S>) % sizeof(double) == 0,
                  "RegularizerResult<S> must be the doubles of the energies tensor");
    if (energies.numel() * int64_t(sizeof(double)) != int64_t(sizeof(smg::RegularizerResult<S>)))
      value_error("regularizers: the energies tensor does not match RegularizerResult");
    const auto gv = graph_view<S, I>(in.g);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const smg::QuaternionsView<const S> qv =
        rigid ? smg::QuaternionsView<const S>(cptr<S>(in.q), in.T, in.N) : smg::QuaternionsView<const S>();
    smg::VisibilityView<const std::uint8_t> vv;
    if (in.vis.defined()) vv = {cptr<std::uint8_t>(in.vis), in.vis.size(0), in.vis.size(1)};
    const smg::FrameScalarsView<S> cv =
        c.defined() ? smg::FrameScalarsView<S>(mptr<S>(c), in.T, in.N) : smg::FrameScalarsView<S>();
    const auto gxv = grad_view<S>(in, gx);
    smg::RotationGradientView<S> gqv;
    if (gq.defined()) gqv = smg::QuaternionsView<S>(mptr<S>(gq), in.T, in.N);
    if (validate)
      ok(smg::cuda::validate_regularizers<S, I>(xv, qv, vv, gv, o, cv, gxv, gqv, stream), kEnergyNames);
    smg::cuda::ReverseGraph rev;
    ok(smg::cuda::build_reverse_graph(cptr<I>(in.g.indices), in.N, in.g.k, stream, rev));
    auto* r = reinterpret_cast<smg::RegularizerResult<S>*>(energies.data_ptr<double>());
    ok(smg::cuda::regularizers<S, I>(xv, qv, vv, gv, o, rev, r, cv, gxv, gqv, stream), kEnergyNames);
    return 0;
  });
}

// knn_points on a CUDA tensor: smg::cuda::point_knn on the current stream (no synchronisation).
void point_knn_cuda(const Reference& ref, const at::Tensor& points, int k, double radius, bool include_self,
                    const at::Tensor& indices, const at::Tensor& distances2) {
  const c10::cuda::CUDAGuard guard(ref.device);
  const cudaStream_t stream = stream_of(ref);
  const int64_t N = points.size(0);
  dispatch(ref.st, true, [&](auto s, auto) {
    using S = decltype(s);
    ok(smg::cuda::point_knn<S, std::int64_t>(smg::TableView<const S, 3>(cptr<S>(points), N), k, radius,
                                             include_self, {mptr<std::int64_t>(indices), N, k},
                                             {mptr<S>(distances2), N, k}, stream));
    return 0;
  });
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
  smg::cuda::set_allocator({&torch_allocate, &torch_deallocate, nullptr});
  has_cuda() = true;
  m.attr("has_cuda") = true;
  CudaOps& ops = cuda_ops();
  ops.node_confidences = &confidences_cuda;
  ops.carap = &carap_cuda;
  ops.lrm = &lrm_cuda;
  ops.regularizers = &regularizers_cuda;
  ops.point_knn = &point_knn_cuda;
  ops.dqb_forward = &dqb_forward_cuda;
  ops.dqb_backward = &dqb_backward_cuda;
}

}  // namespace smg_torch
