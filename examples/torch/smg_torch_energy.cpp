// examples/torch/smg_torch_energy.cpp — node confidences, C-ARAP, plain ARAP, LRM and their
// fused step (regularizers) for smg_torch: the library's validation, then the energy and its
// analytic gradient in one pass (the Python autograd.Function keeps the gradient and scales it
// by grad_output in backward).
#include <algorithm>
#include <chrono>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "smg/energy.hpp"
#include "smg_torch_common.hpp"

namespace smg_torch {

namespace {

// Checks positions [T, N, 3] (the reference), quats [T, N, 4], confidence [T, N], visibility
// [T, N] and the graph on positions' device.
EnergyInputs prepare(const at::Tensor& positions, const OptTensor& quats, const at::Tensor& indices,
                     const at::Tensor& weights, const OptTensor& confidence,
                     const OptTensor& visibility = std::nullopt, bool validate = false) {
  EnergyInputs in;
  in.ref = reference(positions, "positions");
  in.x = float_input(positions, "positions", in.ref, 3, 3, "[T, N, 3]");
  in.T = in.x.size(0);
  in.N = in.x.size(1);
  if (quats) in.q = float_input(*quats, "quats", in.ref, 3, 4, "[T, N, 4]");
  if (confidence) in.c = float_input(*confidence, "confidence", in.ref, 2, -1, "[T, N]");
  in.g = graph_input(indices, weights, in.ref);
  if (visibility) in.vis = visibility_input(*visibility, in.ref, validate);
  return in;
}

template <class S>
smg::PositionsView<const S> positions_view(const EnergyInputs& in) {
  return {cptr<S>(in.x), in.T, in.N};
}

template <class S>
smg::FrameScalarsView<const S> conf_view(const at::Tensor& c) {
  if (!c.defined()) return {};
  return smg::FrameScalarsView<const S>(cptr<S>(c), c.size(0), c.size(1));
}

template <class S>
smg::QuaternionsView<const S> quat_view(const at::Tensor& q) {
  return smg::QuaternionsView<const S>(cptr<S>(q), q.size(0), q.size(1));
}

// Gradient buffers [T, N, 3] / [T, N, 4] on positions' device, zero, when requested.
at::Tensor zeros_if(bool need, const EnergyInputs& in, int64_t last) {
  return need ? at::zeros({in.T, in.N, last}, in.ref.options()) : at::Tensor();
}

py::object opt(const at::Tensor& t) { return t.defined() ? py::cast(t) : py::none(); }

// This thread's workspace of S, kept between calls (one per thread and dtype, as a trainer keeps
// one: smg/energy/workspace.hpp), for every CPU operator of the binding: without it each call
// allocates and zero-fills the driver's scratch anew (at Shape of Motion's T = 3, N = 320 000 about
// 7 times the input, 75 % of the call). It only grows; ops run one at a time per thread (the GIL
// is released only inside the call).
template <class S>
smg::EnergyWorkspace<S>* thread_workspace() {
  thread_local smg::EnergyWorkspace<S> workspace;
  return &workspace;
}

// node_confidences(positions, indices, weights, visibility, kappa_m, kappa_r, lambda_m,
// lambda_r, eps, validate) -> [T, N]
at::Tensor node_confidences(const at::Tensor& positions, const at::Tensor& indices,
                            const at::Tensor& weights, const OptTensor& visibility, double kappa_m,
                            double kappa_r, double lambda_m, double lambda_r, double eps,
                            bool validate) {
  const EnergyInputs in =
      prepare(positions, std::nullopt, indices, weights, std::nullopt, visibility, validate);
  const smg::ConfidenceOptions o = confidence_options(kappa_m, kappa_r, lambda_m, lambda_r, eps);
  at::Tensor out = at::empty({in.T, in.N}, in.ref.options());
  if (in.ref.cuda()) {
    cuda(cuda_ops().node_confidences)(in, o, validate, out);
    return out;
  }
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto xv = positions_view<S>(in);
    const smg::VisibilityView<const std::uint8_t> vv =
        in.vis.defined() ? smg::VisibilityView<const std::uint8_t>(cptr<std::uint8_t>(in.vis),
                                                                   in.vis.size(0), in.vis.size(1))
                         : smg::VisibilityView<const std::uint8_t>();
    const auto gv = graph_view<S, I>(in.g);
    const smg::FrameScalarsView<S> cv(mptr<S>(out), in.T, in.N);
    ok(smg::validate_confidence<S>(xv, vv, gv, o, cv), kEnergyNames);
    py::gil_scoped_release release;
    smg::node_confidences<S>(xv, vv, gv, o, cv, {}, {}, thread_workspace<S>(), parallel_options());
    return 0;
  });
  return out;
}

// carap / arap: -> (energy 0-dim, grad_positions or None, grad_quats or None)
py::tuple carap_impl(const CarapCall& call, const at::Tensor& positions, const at::Tensor& quats,
                     const at::Tensor& indices, const at::Tensor& weights,
                     const OptTensor& confidence, bool grad_x, bool grad_q, bool validate) {
  const EnergyInputs in =
      prepare(positions, quats, indices, weights, call.plain ? std::nullopt : confidence);
  const at::Tensor gx = zeros_if(grad_x, in, 3), gq = zeros_if(grad_q, in, 4);
  if (in.ref.cuda())
    return py::make_tuple(cuda(cuda_ops().carap)(in, call, validate, gx, gq), opt(gx), opt(gq));
  const double e = dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto xv = positions_view<S>(in);
    const auto qv = quat_view<S>(in.q);
    const auto gv = graph_view<S, I>(in.g);
    const smg::PositionsView<S> gxv = grad_x ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N)
                                             : smg::PositionsView<S>();
    smg::RotationGradientView<S> gqv;
    if (grad_q) gqv = smg::QuaternionsView<S>(mptr<S>(gq), in.T, in.N);
    if (call.plain) {
      ok(smg::validate_arap<S>(xv, qv, gv, call.arap, gxv, gqv), kEnergyNames);
      py::gil_scoped_release release;
      return double(smg::arap<S>(xv, qv, gv, call.arap, gxv, gqv, thread_workspace<S>(), parallel_options()));
    }
    const auto cv = conf_view<S>(in.c);
    ok(smg::validate_carap<S>(xv, qv, cv, gv, call.carap, gxv, gqv), kEnergyNames);
    py::gil_scoped_release release;
    return double(smg::carap<S>(xv, qv, cv, gv, call.carap, gxv, gqv, thread_workspace<S>(), parallel_options()));
  });
  return py::make_tuple(at::scalar_tensor(e, in.ref.options()), opt(gx), opt(gq));
}

py::tuple lrm_impl(const at::Tensor& positions, const at::Tensor& indices, const at::Tensor& weights,
                   const OptTensor& confidence, double alpha, double huber_delta, bool detach_omega,
                   bool normalize, bool grad_x, bool validate) {
  const EnergyInputs in = prepare(positions, std::nullopt, indices, weights, confidence);
  const smg::LrmOptions o = lrm_options(alpha, huber_delta, detach_omega, normalize);
  const at::Tensor gx = zeros_if(grad_x, in, 3);
  if (in.ref.cuda()) return py::make_tuple(cuda(cuda_ops().lrm)(in, o, validate, gx), opt(gx));
  const double e = dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto xv = positions_view<S>(in);
    const auto gv = graph_view<S, I>(in.g);
    const auto cv = conf_view<S>(in.c);
    const smg::PositionsView<S> gxv = grad_x ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N)
                                             : smg::PositionsView<S>();
    ok(smg::validate_lrm<S>(xv, cv, gv, o, gxv), kEnergyNames);
    py::gil_scoped_release release;
    return double(smg::lrm<S>(xv, cv, gv, o, gxv, thread_workspace<S>(), parallel_options()));
  });
  return py::make_tuple(at::scalar_tensor(e, in.ref.options()), opt(gx));
}

// regularizers(positions, quats or None, indices, weights, visibility or None, terms, options,
// grad_positions, grad_quats, validate) -> (energies [E] of positions' dtype, in energy_names()'s
// order; confidence [T, N] or None; grad_positions or None; grad_quats or None):
// smg::regularizers, the fused step. `terms` maps each term of smg::for_each_term to a bool,
// `options` each term to the dict of all its options (the Python wrapper fills the defaults,
// option_defaults()). Each term's options are checked on their own first, so that a message
// names the term ("carap.alpha: ..."). CUDA tensors run smg::cuda::regularizers
// (smg/cuda/regularizers.cuh) on the tensors' current stream.
py::tuple regularizers_impl(const at::Tensor& positions, const OptTensor& quats,
                            const at::Tensor& indices, const at::Tensor& weights,
                            const OptTensor& visibility, const py::dict& terms,
                            const py::dict& options, bool grad_x, bool grad_q, bool validate) {
  smg::RegularizerOptions o;
  smg::for_each_term(o, [&](const char* term, bool& on, auto& opts) {
    on = terms[term].cast<bool>();
    read_term_options(options[term].cast<py::dict>(), term, opts);
    if (on)
      if (const smg::Status st = smg::validate_options(opts); !st)
        value_error(std::string(term) + "." + python_message(st.message(), {}));
  });
  const bool rigid = smg::reads_rotations(o.terms);  // a term that reads the rotations is on
  if (rigid && !quats) value_error("quats: needed for carap, arap or angle");
  const EnergyInputs in = prepare(positions, rigid ? quats : std::nullopt, indices, weights,
                                  std::nullopt, visibility, validate);
  const at::Tensor gx = zeros_if(grad_x, in, 3), gq = zeros_if(grad_q && rigid, in, 4);
  const at::Tensor c = o.terms.confidence ? at::empty({in.T, in.N}, in.ref.options()) : at::Tensor();
  // The energies' count, from the list once (not a vector of names per training step).
  static const int64_t kEnergies = static_cast<int64_t>(energy_names().size());
  at::Tensor energies = at::zeros({kEnergies}, in.ref.options().dtype(at::kDouble));
  if (in.ref.cuda()) {
    cuda(cuda_ops().regularizers)(in, o, validate, energies, c, gx, gq);
    return py::make_tuple(energies.to(in.ref.options().dtype()), opt(c), opt(gx), opt(gq));
  }
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto xv = positions_view<S>(in);
    const smg::QuaternionsView<const S> qv = rigid ? quat_view<S>(in.q) : smg::QuaternionsView<const S>();
    const smg::VisibilityView<const std::uint8_t> vv =
        in.vis.defined() ? smg::VisibilityView<const std::uint8_t>(cptr<std::uint8_t>(in.vis),
                                                                   in.vis.size(0), in.vis.size(1))
                         : smg::VisibilityView<const std::uint8_t>();
    const auto gv = graph_view<S, I>(in.g);
    const smg::FrameScalarsView<S> cv =
        c.defined() ? smg::FrameScalarsView<S>(mptr<S>(c), in.T, in.N) : smg::FrameScalarsView<S>();
    const smg::PositionsView<S> gxv = gx.defined() ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N)
                                                   : smg::PositionsView<S>();
    smg::RotationGradientView<S> gqv;
    if (gq.defined()) gqv = smg::QuaternionsView<S>(mptr<S>(gq), in.T, in.N);
    ok(smg::validate_regularizers<S>(xv, qv, vv, gv, o, cv, gxv, gqv), kEnergyNames);
    smg::RegularizerResult<S> r;
    {
      py::gil_scoped_release release;
      r = smg::regularizers<S>(xv, qv, vv, gv, o, cv, gxv, gqv, thread_workspace<S>(), parallel_options());
    }
    double* e = energies.data_ptr<double>();
    smg::RegularizerResult<S>::each_energy([&](const char*, const auto& v) { *e++ = double(v); }, r);
    return 0;
  });
  return py::make_tuple(energies.to(in.ref.options().dtype()), opt(c), opt(gx), opt(gq));
}

// _accel_windows(x, options, grad_x) -> (energy 0-dim, grad [G, T, B, 3] or None): smg::accel_windows
// on a CPU tensor x [G, T, B, 3] (trajectory-major windows: Shape of Motion's transls reshaped,
// a view), the gradient in x's own layout, so smg_torch.compat.som_accel makes no [T, N, 3] copy
// of its input and autograd none of the gradient. `options`: the accel term's dict (smg_torch.REGULARIZER_DEFAULTS["accel"] and its
// changes; messages "accel.<option>: ..."). Not public API.
py::tuple accel_windows_impl(const at::Tensor& positions, const py::dict& options, bool grad_x) {
  require_cpu(positions, "positions");
  smg::AccelOptions o;
  read_term_options(options, "accel", o);
  if (const smg::Status st = smg::validate_options(o); !st)
    value_error("accel." + python_message(st.message(), {}));
  const Reference ref = reference(positions, "positions");
  const at::Tensor x = float_input(positions, "positions", ref, 4, 3, "[G, T, B, 3]");
  const int64_t G = x.size(0), T = x.size(1), B = x.size(2);
  const at::Tensor gx = grad_x ? at::zeros({G, T, B, 3}, ref.options()) : at::Tensor();
  double e = 0;
  dispatch(ref.st, false, [&](auto s, auto) {
    using S = decltype(s);
    ok(smg::validate_accel_windows<S>(cptr<S>(x), G, T, B, o), kEnergyNames);
    py::gil_scoped_release release;
    e = double(smg::accel_windows<S>(cptr<S>(x), G, T, B, o, gx.defined() ? mptr<S>(gx) : nullptr,
                                     parallel_options()));
    return 0;
  });
  return py::make_tuple(at::scalar_tensor(e, ref.options()), opt(gx));
}

// _edge_isometry(positions [T, N, 3], indices [N, K], weights [N, K], rest [N, K], penalty,
// penalty_eps, length_eps, weight, grad_positions) -> (energy 0-dim, grad [T, N, 3] or None): (E26),
// smg::edge_isometry on CPU tensors (compat.d3dgs_losses' iso). rest in positions' dtype.
py::tuple edge_isometry_impl(const at::Tensor& positions, const at::Tensor& indices, const at::Tensor& weights,
                             const at::Tensor& rest, const std::string& penalty, double penalty_eps,
                             double length_eps, double weight, bool grad_x) {
  require_cpu(positions, "positions");
  const EnergyInputs in = prepare(positions, std::nullopt, indices, weights, std::nullopt);
  const at::Tensor r = float_input(rest, "rest", in.ref, 2, -1, "[N, K]");
  smg::EdgeIsometryOptions o;
  {
    py::dict d;
    d["penalty"] = penalty;
    read_option(d, "penalty", o.penalty);
  }
  o.penalty_eps = penalty_eps;
  o.length_eps = length_eps;
  o.weight = weight;
  o.parallel = parallel_options();
  const at::Tensor gx = zeros_if(grad_x, in, 3);
  double e = 0;
  dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto xv = positions_view<S>(in);
    const auto gv = graph_view<S, I>(in.g);
    const smg::TableView<const S, Eigen::Dynamic> rv(cptr<S>(r), r.size(0), r.size(1));
    const smg::PositionsView<S> gxv = grad_x ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N) : smg::PositionsView<S>();
    ok(smg::validate_edge_isometry<S, I>(xv, gv, rv, o, gxv), kEnergyNames);
    py::gil_scoped_release release;
    e = double(smg::edge_isometry<S, I>(xv, gv, rv, o, gxv));
    return 0;
  });
  return py::make_tuple(at::scalar_tensor(e, in.ref.options()), opt(gx));
}

// _library_seconds(op, positions, quats, indices, weights, confidence, repeat): the binding's
// overhead benchmark (bench/torch/bench_torch.py). Prepares the same inputs as the operators,
// then times, with std::chrono, best of `repeat`, the bare library call as a C++ caller would
// make it: zero the gradient buffers, then op "carap" = smg::carap (energy + gradients w.r.t.
// positions and raw quaternions) or "lrm" = smg::lrm (energy + position gradient), with the
// Python wrappers' defaults (alpha 0.6, gaps 1, 2, 4, lambda_c = lambda_l = 1, huber 0.01, sum)
// and this thread's workspace (as the binding calls it), on torch's intra-op thread count.
double library_seconds(const std::string& op, const at::Tensor& positions, const OptTensor& quats,
                       const at::Tensor& indices, const at::Tensor& weights, const OptTensor& confidence,
                       const py::int_& repeat_arg) {
  const bool carap_op = op == "carap";
  if (!carap_op && op != "lrm") value_error("_library_seconds: op must be 'carap' or 'lrm'");
  if (carap_op && !quats) value_error("_library_seconds: carap needs quats");
  const int64_t repeat = int_arg(repeat_arg, "repeat", 1, 1000000);
  const std::pair<OptTensor, const char*> tensors[] = {
      {positions, "positions"}, {quats, "quats"}, {indices, "indices"}, {weights, "weights"},
      {confidence, "confidence"}};
  for (const auto& [t, name] : tensors)
    if (t) require_cpu(*t, name);
  const EnergyInputs in = prepare(positions, carap_op ? quats : std::nullopt, indices, weights, confidence);
  smg::CarapOptions co;
  co.alpha = 0.6;
  co.gaps = smg::default_gaps();
  smg::LrmOptions lo;
  lo.alpha = 0.6;
  lo.huber_delta = 0.01;
  at::Tensor gx = at::zeros({in.T, in.N, 3}, in.ref.options());
  at::Tensor gq = at::zeros({in.T, in.N, 4}, in.ref.options());
  return dispatch(in.ref.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const auto xv = positions_view<S>(in);
    const auto gv = graph_view<S, I>(in.g);
    const auto cv = conf_view<S>(in.c);
    const smg::PositionsView<S> gxv(mptr<S>(gx), in.T, in.N);
    smg::RotationGradientView<S> gqv;
    if (carap_op) {
      gqv = smg::QuaternionsView<S>(mptr<S>(gq), in.T, in.N);
      ok(smg::validate_carap<S>(xv, quat_view<S>(in.q), cv, gv, co, gxv, gqv), kEnergyNames);
    } else {
      ok(smg::validate_lrm<S>(xv, cv, gv, lo, gxv), kEnergyNames);
    }
    const smg::ParallelOptions par = parallel_options();
    S* const gxp = mptr<S>(gx);
    S* const gqp = mptr<S>(gq);
    const std::size_t nx = static_cast<std::size_t>(in.T * in.N * 3), nq = static_cast<std::size_t>(in.T * in.N * 4);
    py::gil_scoped_release release;
    double best = std::numeric_limits<double>::infinity();
    S sink = 0;
    for (int64_t r = 0; r < repeat; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      std::fill(gxp, gxp + nx, S(0));
      if (carap_op) {
        std::fill(gqp, gqp + nq, S(0));
        sink += smg::carap<S>(xv, quat_view<S>(in.q), cv, gv, co, gxv, gqv, thread_workspace<S>(), par);
      } else {
        sink += smg::lrm<S>(xv, cv, gv, lo, gxv, thread_workspace<S>(), par);
      }
      best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    if (!(sink == sink)) best = -best;  // keep the calls observable; a NaN energy shows as a negative time
    return best;
  });
}

}  // namespace

void register_energy(py::module_& m) {
  using namespace pybind11::literals;
  // Each operator takes CPU or CUDA tensors (the device of positions decides); `validate`
  // concerns CUDA tensors only (CPU tensors are always validated).
  m.def("node_confidences", &node_confidences, "positions"_a, "indices"_a, "weights"_a,
        "visibility"_a, "kappa_m"_a, "kappa_r"_a, "lambda_m"_a, "lambda_r"_a, "eps"_a, "validate"_a);
  m.def(
      "carap",
      [](const at::Tensor& x, const at::Tensor& q, const at::Tensor& idx, const at::Tensor& w,
         const OptTensor& c, double alpha, double lc, double ll, const py::sequence& gaps,
         const std::optional<std::vector<double>>& gw, bool normalize, bool gx, bool gq,
         bool validate) {
        return carap_impl(carap_options(false, alpha, lc, ll, gaps, gw, normalize), x, q, idx, w, c,
                          gx, gq, validate);
      },
      "positions"_a, "quats"_a, "indices"_a, "weights"_a, "confidence"_a, "alpha"_a, "lambda_c"_a,
      "lambda_l"_a, "gaps"_a, "gap_weights"_a, "normalize"_a, "grad_positions"_a, "grad_quats"_a,
      "validate"_a);
  m.def(
      "arap",
      [](const at::Tensor& x, const at::Tensor& q, const at::Tensor& idx, const at::Tensor& w,
         double lc, double ll, const py::sequence& gaps, const std::optional<std::vector<double>>& gw,
         bool normalize, bool gx, bool gq, bool validate) {
        return carap_impl(carap_options(true, 1.0, lc, ll, gaps, gw, normalize), x, q, idx, w,
                          std::nullopt, gx, gq, validate);
      },
      "positions"_a, "quats"_a, "indices"_a, "weights"_a, "lambda_c"_a, "lambda_l"_a, "gaps"_a,
      "gap_weights"_a, "normalize"_a, "grad_positions"_a, "grad_quats"_a, "validate"_a);
  m.def("regularizers", &regularizers_impl, "positions"_a, "quats"_a, "indices"_a, "weights"_a,
        "visibility"_a, "terms"_a, "options"_a, "grad_positions"_a, "grad_quats"_a, "validate"_a);
  // The fused step's term list (smg::for_each_term), which the Python wrapper is built from:
  // {term: on by default}, {term: {option: default}} and the energies' names in order.
  m.def("_regularizer_terms", &term_defaults);
  m.def("_regularizer_options", &option_defaults);
  m.def("_regularizer_energies", &energy_names);
  m.def("_library_seconds", &library_seconds, "op"_a, "positions"_a, "quats"_a, "indices"_a, "weights"_a,
        "confidence"_a, "repeat"_a);
  m.def("_accel_windows", &accel_windows_impl, "positions"_a, "options"_a, "grad_positions"_a);
  m.def("_edge_isometry", &edge_isometry_impl, "positions"_a, "indices"_a, "weights"_a, "rest"_a, "penalty"_a,
        "penalty_eps"_a, "length_eps"_a, "weight"_a, "grad_positions"_a);
  m.def("lrm", &lrm_impl, "positions"_a, "indices"_a, "weights"_a, "confidence"_a, "alpha"_a,
        "huber_delta"_a, "detach_omega"_a, "normalize"_a, "grad_positions"_a, "validate"_a);
  m.def("set_memory_limit", [](double bytes) {
    if (!(bytes > 0 && bytes <= 1048576 * kGiB))
      value_error("set_memory_limit: bytes must be in (0, 2^50], got " + std::string(py::str(py::float_(bytes))));
    memory_limit() = bytes;
  }, "bytes"_a);
  m.def("memory_limit", [] { return memory_limit(); });
}

}  // namespace smg_torch
