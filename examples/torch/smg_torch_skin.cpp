// examples/torch/smg_torch_skin.cpp — dual-quaternion blending (or LBS) for smg_torch:
// drivers (S1) and distance-aware weights (S2)-(S4) — constants for the gradient — then the
// blend (S6)-(S13) forward, and its analytic backward (S14)-(S18) w.r.t. the node positions, the
// raw node quaternions, the points and the raw point quaternions.
//
// CPU or CUDA tensors (node_positions' device decides): the checks, outputs and memory estimate
// here are shared; the CUDA launches are in smg_torch_cuda.cu.
// Contents (index ranges, sigma > 0, finite incoming gradients) are checked on CPU tensors
// always, and on CUDA tensors only with validate=True: each check reads the device back, which
// synchronises the stream. Without it nothing of a CUDA call is read on the host (shapes, dtypes
// and devices are metadata); the kernels then take the contents as a precondition, except that
// a t_query entry out of range gives NaN outputs and adds nothing to the gradients instead of an
// out-of-bounds read (smg/cuda/dqb.cuh).
// Copies: anchor, t_ref and t_query are narrowed to int32 (after the range check in their own
// dtype when there is one: unchecked int64 values beyond int32 wrap), the driver table [P, K+1]
// int32 and the weights [P, K+1] are new tensors (saved for backward).
#include <optional>
#include <string>

#include "smg/skin.hpp"
#include "smg_torch_common.hpp"
#include "smg_torch_skin_views.hpp"

namespace smg_torch {

namespace {

// Checks node_positions [T, N, 3] (the reference), node_quats [T, N, 4], points [P, 3],
// point_quats [P, 4] and the index vectors t_ref [P], t_query [Q] (dtype and shape; their
// ranges are checked by check_index_ranges, then they are converted with int32_indices).
SkinInputs prepare(const at::Tensor& node_positions, const at::Tensor& node_quats,
                   const at::Tensor& points, const OptTensor& point_quats, const at::Tensor& t_ref,
                   const at::Tensor& t_query) {
  SkinInputs in;
  in.ref = reference(node_positions, "node_positions");
  in.x = float_input(node_positions, "node_positions", in.ref, 3, 3, "[T, N, 3]");
  in.T = in.x.size(0);
  in.N = in.x.size(1);
  in.q = float_input(node_quats, "node_quats", in.ref, 3, 4, "[T, N, 4]");
  if (in.q.size(0) != in.T || in.q.size(1) != in.N)
    value_error("node_quats: expected shape [T=" + std::to_string(in.T) + ", N=" +
                std::to_string(in.N) + ", 4] like node_positions, got " + shape_of(in.q));
  in.pts = float_input(points, "points", in.ref, 2, 3, "[P, 3]");
  in.P = in.pts.size(0);
  if (point_quats) {
    in.pq = float_input(*point_quats, "point_quats", in.ref, 2, 4, "[P, 4]");
    if (in.pq.size(0) != in.P)
      value_error("point_quats: expected shape [P=" + std::to_string(in.P) + ", 4], got " +
                  shape_of(in.pq));
  }
  const at::Tensor t_ref_in = index_input(t_ref, "t_ref", in.ref);
  if (t_ref_in.numel() != in.P)
    value_error("t_ref: expected shape [P=" + std::to_string(in.P) + "], got " + shape_of(t_ref_in));
  const at::Tensor t_query_in = index_input(t_query, "t_query", in.ref);
  in.t_ref = t_ref_in;
  in.t_query = t_query_in;
  in.Q = t_query_in.numel();
  return in;
}

// The range-checked index vectors as int32 (what smg's skin views read).
void int32_indices(SkinInputs& in) {
  for (at::Tensor* t : {&in.anchor, &in.t_ref, &in.t_query})
    if (t->defined()) *t = t->to(at::kInt).contiguous();
}

// The checks of validate_skinning_weights and validate_skin_blend on everything except the
// driver table (built by skin_drivers), the weights (built by skinning_weights), the index
// vectors and sigma (checked by dqb_forward on either device): node positions and quaternions,
// points, point quaternions.
template <class S>
void check_skin_inputs(const SkinInputs& in) {
  const auto nodes = nodes_of<S>(in);
  ok(smg::validate_positions<S>(nodes.positions, -1, -1, "node_positions"));
  ok(smg::validate_quaternions<S>(nodes.quaternions, nodes.frames(), nodes.nodes(),
                                  smg::QuaternionNorm::normalize_on_entry, "node_quats"));
  const smg::TableView<const S, 3> points(cptr<S>(in.pts), in.P);
  ok(smg::detail::check_table<S, 3>(points, points.rows(), 3, "points"));
  if (in.pq.defined()) {
    const smg::TableView<const S, 4> qv(cptr<S>(in.pq), in.P);
    ok(smg::detail::check_table<S, 4>(qv, qv.rows(), 4, "point_quats"));
    ok(smg::detail::check_quaternion_rows<S>(qv, "point_quats"));
  }
}

// sigma [N]: finite and > 0, by the library's validator on a host copy (a copy only on CUDA,
// where it synchronises: only with validate=True).
void check_sigma(const SkinInputs& in) {
  const at::Tensor host = in.sigma.cpu();
  dispatch(in.ref.st, false, [&](auto s, auto) {
    using S = decltype(s);
    ok(smg::validate_skin_sigma<S>(smg::TableView<const S, 1>(cptr<S>(host), in.N), in.N));
    return 0;
  });
}

// -> (positions [Q, P, 3], quaternions [Q, P, 4], drivers [P, D] int32, weights [P, D])
py::tuple dqb_forward(const at::Tensor& node_positions, const at::Tensor& node_quats,
                      const at::Tensor& indices, const at::Tensor& gweights,
                      const at::Tensor& points, const OptTensor& point_quats,
                      const at::Tensor& anchor, const at::Tensor& t_ref, const at::Tensor& t_query,
                      const at::Tensor& sigma, bool lbs, bool validate) {
  SkinInputs in = prepare(node_positions, node_quats, points, point_quats, t_ref, t_query);
  in.g = graph_input(indices, gweights, in.ref);
  if (in.g.n != in.N)
    value_error("graph.indices: expected shape [N=" + std::to_string(in.N) + ", K], got " +
                shape_of(indices));
  const at::Tensor anchor_in = index_input(anchor, "anchor", in.ref);
  if (anchor_in.numel() != in.P)
    value_error("anchor: expected shape [P=" + std::to_string(in.P) + "], got " + shape_of(anchor_in));
  in.anchor = anchor_in;
  in.sigma = float_input(sigma, "sigma", in.ref, 1, -1, "[N]");
  if (in.sigma.size(0) != in.N)
    value_error("sigma: expected shape [N=" + std::to_string(in.N) + "], got " + shape_of(in.sigma));
  // Outputs [Q, P, 3] + [Q, P, 4] and the drivers and weights [P, D] (as smg_cli's dqb).
  const int64_t D = in.g.k + 1;
  const double s = in.ref.st == at::kFloat ? 4 : 8;
  const std::string outputs = "t_query: Q = " + std::to_string(in.Q) + " query frames x P = " +
                              std::to_string(in.P) + " points of blended outputs [Q, P, 7]";
  check_memory(double(in.Q) * double(in.P) * 7 * s + double(in.P) * double(D) * (4 + s), outputs);
  if (!in.ref.cuda() || validate) {  // on CUDA tensors these read the device back
    check_index_ranges({{in.g.indices, "graph", -1, in.N, "N", true},
                        {in.anchor, "anchor", 0, in.N, "N"},
                        {in.t_ref, "t_ref", 0, in.T, "T"},
                        {in.t_query, "t_query", 0, in.T, "T"}});
    check_sigma(in);
  }
  int32_indices(in);
  at::Tensor drivers, weights, out_x, out_q;
  allocating(outputs, [&] {
    drivers = at::empty({in.P, D}, in.ref.int32());
    weights = at::empty({in.P, D}, in.ref.options());
    out_x = at::empty({in.Q, in.P, 3}, in.ref.options());
    out_q = at::empty({in.Q, in.P, 4}, in.ref.options());
  });
  smg::SkinOptions opt = skin_options(lbs);
  if (in.ref.cuda()) {
    if (!cuda_ops().dqb_forward) not_implemented(kNoCudaMessage);
    cuda_ops().dqb_forward(in, opt, drivers, weights, out_x, out_q);
    return py::make_tuple(out_x, out_q, drivers, weights);
  }
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto gv = graph_view<S, I>(in.g);
    const smg::SkinIndexView av(cptr<std::int32_t>(in.anchor), in.P);
    const smg::TableView<std::int32_t, Eigen::Dynamic> dv(mptr<std::int32_t>(drivers), in.P, D);
    ok(smg::validate_skin_drivers(gv, av, in.N, dv));
    const smg::TableView<const S, 1> sv(cptr<S>(in.sigma), in.N);
    const auto nodes = nodes_of<S>(in);
    const smg::SkinIndexView tr(cptr<std::int32_t>(in.t_ref), in.P);
    const smg::TableView<const S, 3> pv(cptr<S>(in.pts), in.P);
    const smg::TableView<S, Eigen::Dynamic> wv(mptr<S>(weights), in.P, D);
    // Drivers, then weights, then the blend: each validated against what it reads.
    {
      py::gil_scoped_release release;
      smg::skin_drivers(gv, av, dv, parallel_options());
    }
    // validate_skinning_weights / validate_skin_blend minus the driver table, which
    // skin_drivers just built from a validated graph and anchors: the library's check_drivers
    // builds an ostringstream per entry (~140 ms for 32768 x 17, 15x the blend itself).
    check_skin_inputs<S>(in);
    {
      py::gil_scoped_release release;
      smg::skinning_weights<S>(nodes.positions, dv, tr, pv, sv, wv, parallel_options());
    }
    const auto pts = points_of<S>(in, drivers, weights);
    smg::SkinBlendOutputs<S> o;
    o.positions = {mptr<S>(out_x), in.Q, in.P};
    o.quaternions = {mptr<S>(out_q), in.Q, in.P};
    const smg::SkinIndexView tq(cptr<std::int32_t>(in.t_query), in.Q);
    py::gil_scoped_release release;
    smg::skin_blend(nodes, pts, tq, o, opt, parallel_options());
    return 0;
  });
  return py::make_tuple(out_x, out_q, drivers, weights);
}

// -> (grad node_positions, grad node_quats (raw), grad points, grad point_quats (raw)); each
// None unless requested.
py::tuple dqb_backward(const at::Tensor& node_positions, const at::Tensor& node_quats,
                       const at::Tensor& points, const OptTensor& point_quats,
                       const at::Tensor& t_ref, const at::Tensor& t_query, const at::Tensor& drivers,
                       const at::Tensor& weights, const OptTensor& grad_positions,
                       const OptTensor& grad_quats, bool lbs, bool need_x, bool need_q,
                       bool need_p, bool need_pq, bool validate) {
  SkinInputs in = prepare(node_positions, node_quats, points, point_quats, t_ref, t_query);
  // drivers and weights are the forward's outputs (their contents are trusted).
  const at::Tensor drv = on_device(drivers, "drivers", in.ref);
  if (drv.scalar_type() != at::kInt || drv.dim() != 2 || drv.size(0) != in.P)
    value_error("drivers: expected an int32 tensor [P=" + std::to_string(in.P) + ", D], got " +
                shape_of(drv));
  const at::Tensor wts = float_input(weights, "weights", in.ref, 2, drv.size(1), "[P, D] like drivers");
  if (wts.size(0) != in.P)
    value_error("weights: expected shape " + shape_of(drv) + " like drivers, got " + shape_of(wts));
  at::Tensor gop, goq;
  if (grad_positions) {
    gop = float_input(*grad_positions, "grad_positions", in.ref, 3, 3, "[Q, P, 3]");
    if (gop.size(0) != in.Q || gop.size(1) != in.P)
      value_error("grad_positions: expected shape [Q, P, 3], got " + shape_of(gop));
  }
  if (grad_quats) {
    goq = float_input(*grad_quats, "grad_quats", in.ref, 3, 4, "[Q, P, 4]");
    if (goq.size(0) != in.Q || goq.size(1) != in.P)
      value_error("grad_quats: expected shape [Q, P, 4], got " + shape_of(goq));
  }
  // The contents: on CPU tensors always, on CUDA tensors only with validate (each check reads
  // the device back, which synchronises the stream).
  if (!in.ref.cuda() || validate) {
    if (gop.defined() && !at::isfinite(gop).all().item<bool>())
      value_error("grad_positions: has a value that is not finite");
    if (goq.defined() && !at::isfinite(goq).all().item<bool>())
      value_error("grad_quats: has a value that is not finite");
    check_index_ranges({{in.t_ref, "t_ref", 0, in.T, "T"}, {in.t_query, "t_query", 0, in.T, "T"}});
  }
  int32_indices(in);
  const auto o = in.ref.options();
  const at::Tensor gx = need_x ? at::zeros({in.T, in.N, 3}, o) : at::Tensor();
  const at::Tensor gq = need_q ? at::zeros({in.T, in.N, 4}, o) : at::Tensor();
  const at::Tensor gp = need_p ? at::zeros({in.P, 3}, o) : at::Tensor();
  const at::Tensor gpq = need_pq && in.pq.defined() ? at::zeros({in.P, 4}, o) : at::Tensor();
  smg::SkinOptions opt = skin_options(lbs);
  if (in.ref.cuda()) {
    if (!cuda_ops().dqb_backward) not_implemented(kNoCudaMessage);
    cuda_ops().dqb_backward(in, opt, drv, wts, gop, goq, gx, gq, gp, gpq);
  } else {
    dispatch(in.ref.st, false, [&](auto s, auto) {
      using S = decltype(s);
      const auto go = output_gradients<S>(in, gop, goq);
      auto gr = blend_gradients<S>(in, gx, gq, gp, gpq);
      py::gil_scoped_release release;
      smg::SkinWorkspace<S> ws;
      smg::skin_blend_backward(nodes_of<S>(in), points_of<S>(in, drv, wts),
                               smg::SkinIndexView(cptr<std::int32_t>(in.t_query), in.Q), go, gr, ws,
                               opt, parallel_options());
      return 0;
    });
  }
  auto opt_out = [](const at::Tensor& t) { return t.defined() ? py::cast(t) : py::none(); };
  return py::make_tuple(opt_out(gx), opt_out(gq), opt_out(gp), opt_out(gpq));
}

}  // namespace

void register_skin(py::module_& m) {
  using namespace pybind11::literals;
  m.def("dqb_forward", &dqb_forward, "node_positions"_a, "node_quats"_a, "indices"_a, "weights"_a,
        "points"_a, "point_quats"_a, "anchor"_a, "t_ref"_a, "t_query"_a, "sigma"_a, "lbs"_a,
        "validate"_a = false);
  m.def("dqb_backward", &dqb_backward, "node_positions"_a, "node_quats"_a, "points"_a,
        "point_quats"_a, "t_ref"_a, "t_query"_a, "drivers"_a, "weights"_a, "grad_positions"_a,
        "grad_quats"_a, "lbs"_a, "need_x"_a, "need_q"_a, "need_p"_a, "need_pq"_a,
        "validate"_a = false);
}

}  // namespace smg_torch
