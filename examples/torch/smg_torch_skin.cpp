// examples/torch/smg_torch_skin.cpp — dual-quaternion blending (or LBS) for smg_torch:
// drivers (S1) and distance-aware weights (S2)-(S4) — constants for the gradient — then the
// blend (S6)-(S13) forward, and its analytic backward (S14)-(S18) w.r.t. the node positions, the
// raw node quaternions, the points and the raw point quaternions.
//
// Copies: anchor, t_ref and t_query are narrowed to int32 (after a range check in int64), the
// driver table [P, K+1] int32 and the weights [P, K+1] are new tensors (saved for backward).
#include <optional>
#include <string>

#include "smg/skin.hpp"
#include "smg_torch_common.hpp"

namespace smg_torch {

namespace {

using OptTensor = std::optional<at::Tensor>;

// An index vector [n] (any integer dtype) as int32 after checking [0, bound).
at::Tensor index_input(const at::Tensor& a, const char* name, int64_t bound, const char* bound_name) {
  require_cpu(a, name);
  if (a.dim() != 1) value_error(std::string(name) + ": expected shape [n], got " + shape_of(a));
  if (at::isFloatingType(a.scalar_type()) || a.scalar_type() == at::kBool)
    value_error(std::string(name) + ": dtype must be an integer type, got " + dtype_name(a));
  const at::Tensor l = a.to(at::kLong).contiguous();
  const int64_t* p = l.data_ptr<int64_t>();
  for (int64_t i = 0; i < l.numel(); ++i)
    if (p[i] < 0 || p[i] >= bound)
      value_error(std::string(name) + ": element [" + std::to_string(i) + "] = " + std::to_string(p[i]) +
                  " is out of range [0, " + bound_name + "=" + std::to_string(bound) + ")");
  return l.to(at::kInt).contiguous();
}

template <class S>
smg::TableView<const S, 4> point_quat_view(const at::Tensor& pq) {
  if (!pq.defined()) return {};
  return smg::TableView<const S, 4>(cptr<S>(pq), pq.size(0));
}

struct SkinInputs {
  at::ScalarType st;
  at::Tensor x, q, pts, pq, sigma, anchor, t_ref, t_query;
  GraphTensors g;
  int64_t T = 0, N = 0, P = 0, Q = 0;
};

SkinInputs prepare(const at::Tensor& node_positions, const at::Tensor& node_quats,
                   const at::Tensor& points, const OptTensor& point_quats, const at::Tensor& t_ref,
                   const at::Tensor& t_query) {
  SkinInputs in;
  in.st = float_type_of(node_positions, "node_positions");
  require_shape(node_positions, "node_positions", 3, 3, "[T, N, 3]");
  in.x = node_positions.contiguous();
  in.T = node_positions.size(0);
  in.N = node_positions.size(1);
  in.q = float_input<float>(node_quats, "node_quats", in.st);
  require_shape(in.q, "node_quats", 3, 4, "[T, N, 4]");
  if (in.q.size(0) != in.T || in.q.size(1) != in.N)
    value_error("node_quats: expected shape [T=" + std::to_string(in.T) + ", N=" +
                std::to_string(in.N) + ", 4] like node_positions, got " + shape_of(in.q));
  in.pts = float_input<float>(points, "points", in.st);
  require_shape(in.pts, "points", 2, 3, "[P, 3]");
  in.P = points.size(0);
  if (point_quats) {
    in.pq = float_input<float>(*point_quats, "point_quats", in.st);
    require_shape(in.pq, "point_quats", 2, 4, "[P, 4]");
    if (in.pq.size(0) != in.P)
      value_error("point_quats: expected shape [P=" + std::to_string(in.P) + ", 4], got " +
                  shape_of(in.pq));
  }
  in.t_ref = index_input(t_ref, "t_ref", in.T, "T");
  if (in.t_ref.numel() != in.P)
    value_error("t_ref: expected shape [P=" + std::to_string(in.P) + "], got " + shape_of(t_ref));
  in.t_query = index_input(t_query, "t_query", in.T, "T");
  in.Q = in.t_query.numel();
  return in;
}

template <class S>
smg::SkinNodes<S> nodes_of(const SkinInputs& in) {
  return {smg::PositionsView<const S>(cptr<S>(in.x), in.T, in.N),
          smg::QuaternionsView<const S>(cptr<S>(in.q), in.T, in.N)};
}

template <class S>
smg::SkinPoints<S> points_of(const SkinInputs& in, const at::Tensor& drivers,
                             const at::Tensor& weights) {
  smg::SkinPoints<S> p;
  p.drivers = smg::SkinDriversView(cptr<std::int32_t>(drivers), in.P, drivers.size(1));
  p.weights = smg::TableView<const S, Eigen::Dynamic>(cptr<S>(weights), in.P, weights.size(1));
  p.t_ref = smg::SkinIndexView(cptr<std::int32_t>(in.t_ref), in.P);
  p.positions = smg::TableView<const S, 3>(cptr<S>(in.pts), in.P);
  p.quaternions = point_quat_view<S>(in.pq);
  return p;
}

// The checks of validate_skinning_weights and validate_skin_blend on everything except the
// driver table (built by skin_drivers) and the weights (built by skinning_weights): node
// positions and quaternions, points, point quaternions, sigma (t_ref, t_query and anchor were
// range-checked by index_input).
template <class S>
void check_skin_inputs(const smg::SkinNodes<S>& nodes, smg::TableView<const S, 3> points,
                       const at::Tensor& pq, smg::TableView<const S, 1> sigma, int64_t N) {
  ok(smg::validate_positions<S>(nodes.positions, -1, -1, "node_positions"));
  ok(smg::validate_quaternions<S>(nodes.quaternions, nodes.frames(), nodes.nodes(),
                                  smg::QuaternionNorm::normalize_on_entry, "node_quats"));
  ok(smg::detail::check_table<S, 3>(points, points.rows(), 3, "points"));
  if (pq.defined()) {
    const smg::TableView<const S, 4> qv(cptr<S>(pq), pq.size(0));
    ok(smg::detail::check_table<S, 4>(qv, qv.rows(), 4, "point_quats"));
    ok(smg::detail::check_quaternion_rows<S>(qv, "point_quats"));
  }
  ok(smg::validate_skin_sigma<S>(sigma, N));
}

// -> (positions [Q, P, 3], quaternions [Q, P, 4], drivers [P, D] int32, weights [P, D])
py::tuple dqb_forward(const at::Tensor& node_positions, const at::Tensor& node_quats,
                      const at::Tensor& indices, const at::Tensor& gweights,
                      const at::Tensor& points, const OptTensor& point_quats,
                      const at::Tensor& anchor, const at::Tensor& t_ref, const at::Tensor& t_query,
                      const at::Tensor& sigma, bool lbs) {
  SkinInputs in = prepare(node_positions, node_quats, points, point_quats, t_ref, t_query);
  in.g = graph_input(indices, gweights, in.st);
  in.anchor = index_input(anchor, "anchor", in.N, "N");
  if (in.anchor.numel() != in.P)
    value_error("anchor: expected shape [P=" + std::to_string(in.P) + "], got " + shape_of(anchor));
  in.sigma = float_input<float>(sigma, "sigma", in.st);
  require_shape(in.sigma, "sigma", 1, -1, "[N]");
  const int64_t D = in.g.k + 1;
  at::Tensor drivers = at::empty({in.P, D}, at::TensorOptions().dtype(at::kInt));
  at::Tensor weights = at::empty({in.P, D}, options_of(in.st));
  at::Tensor out_x = at::empty({in.Q, in.P, 3}, options_of(in.st));
  at::Tensor out_q = at::empty({in.Q, in.P, 4}, options_of(in.st));
  dispatch(in.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const smg::NeighborsView<S, I> gv(cptr<I>(in.g.indices), cptr<S>(in.g.weights), in.g.n, in.g.k);
    const smg::SkinIndexView av(cptr<std::int32_t>(in.anchor), in.P);
    const smg::TableView<std::int32_t, Eigen::Dynamic> dv(mptr<std::int32_t>(drivers), in.P, D);
    ok(smg::validate_skin_drivers(gv, av, in.N, dv));
    const smg::TableView<const S, 1> sv(cptr<S>(in.sigma), in.sigma.size(0));
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
    check_skin_inputs<S>(nodes, pv, in.pq, sv, in.N);
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
    smg::SkinOptions opt;
    opt.method = lbs ? smg::SkinMethod::lbs : smg::SkinMethod::dqb;
    opt.parallel = parallel_options();
    smg::skin_blend(nodes, pts, tq, o, opt);
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
                       bool need_p, bool need_pq) {
  SkinInputs in = prepare(node_positions, node_quats, points, point_quats, t_ref, t_query);
  at::Tensor gop, goq;
  if (grad_positions) {
    gop = float_input<float>(*grad_positions, "grad_positions", in.st);
    require_shape(gop, "grad_positions", 3, 3, "[Q, P, 3]");
  }
  if (grad_quats) {
    goq = float_input<float>(*grad_quats, "grad_quats", in.st);
    require_shape(goq, "grad_quats", 3, 4, "[Q, P, 4]");
  }
  at::Tensor gx, gq, gp, gpq;
  if (need_x) gx = at::zeros({in.T, in.N, 3}, options_of(in.st));
  if (need_q) gq = at::zeros({in.T, in.N, 4}, options_of(in.st));
  if (need_p) gp = at::zeros({in.P, 3}, options_of(in.st));
  if (need_pq && in.pq.defined()) gpq = at::zeros({in.P, 4}, options_of(in.st));
  dispatch(in.st, false, [&](auto s, auto) {
    using S = decltype(s);
    const auto nodes = nodes_of<S>(in);
    const auto pts = points_of<S>(in, drivers, weights);
    const smg::SkinIndexView tq(cptr<std::int32_t>(in.t_query), in.Q);
    smg::SkinBlendOutputGradients<S> go;
    if (gop.defined()) go.positions = {cptr<S>(gop), in.Q, in.P};
    if (goq.defined()) go.quaternions = {cptr<S>(goq), in.Q, in.P};
    smg::SkinBlendGradients<S> gr;
    if (gx.defined()) gr.node_positions = {mptr<S>(gx), in.T, in.N};
    if (gq.defined()) gr.node_quaternions = {mptr<S>(gq), in.T, in.N};
    if (gp.defined()) gr.points = {mptr<S>(gp), in.P};
    if (gpq.defined()) gr.point_quaternions = {mptr<S>(gpq), in.P};
    // Inputs, drivers and weights were validated (or built) by the forward; only the incoming
    // gradients are new (shapes checked above, finiteness here).
    if (gop.defined() && !at::isfinite(gop).all().item<bool>())
      value_error("grad_positions: has a value that is not finite");
    if (goq.defined() && !at::isfinite(goq).all().item<bool>())
      value_error("grad_quats: has a value that is not finite");
    if (gop.defined() && (gop.size(0) != in.Q || gop.size(1) != in.P))
      value_error("grad_positions: expected shape [Q, P, 3], got " + shape_of(gop));
    if (goq.defined() && (goq.size(0) != in.Q || goq.size(1) != in.P))
      value_error("grad_quats: expected shape [Q, P, 4], got " + shape_of(goq));
    py::gil_scoped_release release;
    smg::SkinWorkspace<S> ws;
    smg::SkinOptions opt;
    opt.method = lbs ? smg::SkinMethod::lbs : smg::SkinMethod::dqb;
    opt.parallel = parallel_options();
    smg::skin_blend_backward(nodes, pts, tq, go, gr, ws, opt);
    return 0;
  });
  auto opt = [](const at::Tensor& t) { return t.defined() ? py::cast(t) : py::none(); };
  return py::make_tuple(opt(gx), opt(gq), opt(gp), opt(gpq));
}

}  // namespace

void register_skin(py::module_& m) {
  using namespace pybind11::literals;
  m.def("dqb_forward", &dqb_forward, "node_positions"_a, "node_quats"_a, "indices"_a, "weights"_a,
        "points"_a, "point_quats"_a, "anchor"_a, "t_ref"_a, "t_query"_a, "sigma"_a, "lbs"_a);
  m.def("dqb_backward", &dqb_backward, "node_positions"_a, "node_quats"_a, "points"_a,
        "point_quats"_a, "t_ref"_a, "t_query"_a, "drivers"_a, "weights"_a, "grad_positions"_a,
        "grad_quats"_a, "lbs"_a, "need_x"_a, "need_q"_a, "need_p"_a, "need_pq"_a);
}

}  // namespace smg_torch
