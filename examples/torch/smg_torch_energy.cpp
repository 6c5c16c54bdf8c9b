// examples/torch/smg_torch_energy.cpp — node confidences, C-ARAP, plain ARAP and LRM for
// smg_torch: the library's validation, then the energy and its analytic gradient in one pass
// (the Python autograd.Function keeps the gradient and scales it by grad_output in backward).
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

using OptTensor = std::optional<at::Tensor>;

smg::GapList gap_list(const std::vector<int64_t>& gaps, const std::optional<std::vector<double>>& w) {
  if (gaps.empty()) value_error("gaps: needs at least one gap");
  if (w && w->size() != gaps.size())
    value_error("gap_weights: needs one weight per gap (" + std::to_string(gaps.size()) + "), got " +
                std::to_string(w->size()));
  smg::GapList list;
  for (std::size_t k = 0; k < gaps.size(); ++k) {
    if (gaps[k] < 1 || gaps[k] > 1000000) value_error("gaps: entries must be integers >= 1");
    list.push_back({static_cast<int>(gaps[k]), w ? (*w)[k] : 1.0});
  }
  return list;
}

smg::Normalization norm_of(bool normalize) {
  return normalize ? smg::Normalization::mean : smg::Normalization::sum;
}

struct Inputs {
  at::ScalarType st;
  at::Tensor x, q, c;
  GraphTensors g;
  int64_t T = 0, N = 0;
};

Inputs prepare(const at::Tensor& positions, const OptTensor& quats, const at::Tensor& indices,
               const at::Tensor& weights, const OptTensor& confidence) {
  Inputs in;
  in.st = float_type_of(positions, "positions");
  require_shape(positions, "positions", 3, 3, "[T, N, 3]");
  in.x = positions.contiguous();
  in.T = positions.size(0);
  in.N = positions.size(1);
  if (quats) {
    in.q = float_input<float>(*quats, "quats", in.st);
    require_shape(in.q, "quats", 3, 4, "[T, N, 4]");
  }
  if (confidence) {
    in.c = float_input<float>(*confidence, "confidence", in.st);
    require_shape(in.c, "confidence", 2, -1, "[T, N]");
  }
  in.g = graph_input(indices, weights, in.st);
  return in;
}

template <class S, class I>
smg::NeighborsView<S, I> graph_view(const GraphTensors& g) {
  return smg::NeighborsView<S, I>(cptr<I>(g.indices), cptr<S>(g.weights), g.n, g.k);
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

at::Tensor scalar_tensor(double v, at::ScalarType st) {
  return at::scalar_tensor(v, options_of(st));
}

py::object opt(const at::Tensor& t) { return t.defined() ? py::cast(t) : py::none(); }

// node_confidences(positions, indices, weights, visibility, kappa_m, kappa_r, lambda_m,
// lambda_r, eps) -> [T, N]
at::Tensor node_confidences(const at::Tensor& positions, const at::Tensor& indices,
                            const at::Tensor& weights, const OptTensor& visibility, double kappa_m,
                            double kappa_r, double lambda_m, double lambda_r, double eps) {
  Inputs in = prepare(positions, std::nullopt, indices, weights, std::nullopt);
  at::Tensor vis;
  if (visibility) vis = visibility_input(*visibility);
  smg::ConfidenceOptions o;
  o.kappa_m = kappa_m;
  o.kappa_r = kappa_r;
  o.lambda_m = lambda_m;
  o.lambda_r = lambda_r;
  o.eps = eps;
  at::Tensor out = at::empty({in.T, in.N}, options_of(in.st));
  dispatch(in.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const smg::VisibilityView<const std::uint8_t> vv =
        vis.defined() ? smg::VisibilityView<const std::uint8_t>(cptr<std::uint8_t>(vis), vis.size(0),
                                                                vis.size(1))
                      : smg::VisibilityView<const std::uint8_t>();
    const auto gv = graph_view<S, I>(in.g);
    const smg::FrameScalarsView<S> cv(mptr<S>(out), in.T, in.N);
    ok(smg::validate_confidence<S>(xv, vv, gv, o, cv));
    py::gil_scoped_release release;
    smg::node_confidences<S>(xv, vv, gv, o, cv, {}, {}, nullptr, parallel_options());
    return 0;
  });
  return out;
}

// carap / arap: -> (energy 0-dim, grad_positions or None, grad_quats or None)
py::tuple carap_impl(bool plain, const at::Tensor& positions, const at::Tensor& quats,
                     const at::Tensor& indices, const at::Tensor& weights,
                     const OptTensor& confidence, double alpha, double lambda_c, double lambda_l,
                     const std::vector<int64_t>& gaps,
                     const std::optional<std::vector<double>>& gap_weights, bool normalize,
                     bool grad_x, bool grad_q) {
  Inputs in = prepare(positions, quats, indices, weights, plain ? std::nullopt : confidence);
  smg::CarapOptions co;
  smg::ArapOptions ao;
  co.alpha = alpha;
  co.lambda_c = ao.lambda_c = lambda_c;
  co.lambda_l = ao.lambda_l = lambda_l;
  co.gaps = ao.gaps = gap_list(gaps, gap_weights);
  co.normalization = ao.normalization = norm_of(normalize);
  at::Tensor gx, gq;
  if (grad_x) gx = at::zeros({in.T, in.N, 3}, options_of(in.st));
  if (grad_q) gq = at::zeros({in.T, in.N, 4}, options_of(in.st));
  const double e = dispatch(in.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const auto qv = quat_view<S>(in.q);
    const auto gv = graph_view<S, I>(in.g);
    const smg::PositionsView<S> gxv = grad_x ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N)
                                             : smg::PositionsView<S>();
    smg::RotationGradientView<S> gqv;
    if (grad_q) gqv = smg::QuaternionsView<S>(mptr<S>(gq), in.T, in.N);
    if (plain) {
      ok(smg::validate_arap<S>(xv, qv, gv, ao, gxv, gqv));
      py::gil_scoped_release release;
      return double(smg::arap<S>(xv, qv, gv, ao, gxv, gqv, nullptr, parallel_options()));
    }
    const auto cv = conf_view<S>(in.c);
    ok(smg::validate_carap<S>(xv, qv, cv, gv, co, gxv, gqv));
    py::gil_scoped_release release;
    return double(smg::carap<S>(xv, qv, cv, gv, co, gxv, gqv, nullptr, parallel_options()));
  });
  return py::make_tuple(scalar_tensor(e, in.st), opt(gx), opt(gq));
}

py::tuple lrm_impl(const at::Tensor& positions, const at::Tensor& indices, const at::Tensor& weights,
                   const OptTensor& confidence, double alpha, double huber_delta, bool detach_omega,
                   bool normalize, bool grad_x) {
  Inputs in = prepare(positions, std::nullopt, indices, weights, confidence);
  smg::LrmOptions o;
  o.alpha = alpha;
  o.huber_delta = huber_delta;
  o.detach_omega = detach_omega;
  o.normalization = norm_of(normalize);
  at::Tensor gx;
  if (grad_x) gx = at::zeros({in.T, in.N, 3}, options_of(in.st));
  const double e = dispatch(in.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const auto gv = graph_view<S, I>(in.g);
    const auto cv = conf_view<S>(in.c);
    const smg::PositionsView<S> gxv = grad_x ? smg::PositionsView<S>(mptr<S>(gx), in.T, in.N)
                                             : smg::PositionsView<S>();
    ok(smg::validate_lrm<S>(xv, cv, gv, o, gxv));
    py::gil_scoped_release release;
    return double(smg::lrm<S>(xv, cv, gv, o, gxv, nullptr, parallel_options()));
  });
  return py::make_tuple(scalar_tensor(e, in.st), opt(gx));
}

// _library_seconds(op, positions, quats, indices, weights, confidence, repeat): the binding's
// overhead benchmark (bench/torch/bench_torch.py). Prepares the same inputs as the operators,
// then times, with std::chrono, best of `repeat`, the bare library call as a C++ caller would
// make it: zero the gradient buffers, then op "carap" = smg::carap (energy + gradients w.r.t.
// positions and raw quaternions) or "lrm" = smg::lrm (energy + position gradient), with the
// Python wrappers' defaults (alpha 0.6, gaps 1, 2, 4, lambda_c = lambda_l = 1, huber 0.01, sum)
// and no workspace (as the binding calls it), on torch's intra-op thread count.
double library_seconds(const std::string& op, const at::Tensor& positions, const OptTensor& quats,
                       const at::Tensor& indices, const at::Tensor& weights, const OptTensor& confidence,
                       int64_t repeat) {
  const bool carap_op = op == "carap";
  if (!carap_op && op != "lrm") value_error("_library_seconds: op must be 'carap' or 'lrm'");
  if (carap_op && !quats) value_error("_library_seconds: carap needs quats");
  if (repeat < 1) value_error("_library_seconds: repeat must be >= 1");
  Inputs in = prepare(positions, carap_op ? quats : std::nullopt, indices, weights, confidence);
  smg::CarapOptions co;
  co.alpha = 0.6;
  co.gaps = smg::default_gaps();
  smg::LrmOptions lo;
  lo.alpha = 0.6;
  lo.huber_delta = 0.01;
  at::Tensor gx = at::zeros({in.T, in.N, 3}, options_of(in.st));
  at::Tensor gq = at::zeros({in.T, in.N, 4}, options_of(in.st));
  return dispatch(in.st, in.g.int64, [&](auto s, auto i) {
    using S = decltype(s);
    using I = decltype(i);
    const smg::PositionsView<const S> xv(cptr<S>(in.x), in.T, in.N);
    const auto gv = graph_view<S, I>(in.g);
    const auto cv = conf_view<S>(in.c);
    const smg::PositionsView<S> gxv(mptr<S>(gx), in.T, in.N);
    smg::RotationGradientView<S> gqv;
    if (carap_op) {
      gqv = smg::QuaternionsView<S>(mptr<S>(gq), in.T, in.N);
      ok(smg::validate_carap<S>(xv, quat_view<S>(in.q), cv, gv, co, gxv, gqv));
    } else {
      ok(smg::validate_lrm<S>(xv, cv, gv, lo, gxv));
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
        sink += smg::carap<S>(xv, quat_view<S>(in.q), cv, gv, co, gxv, gqv, nullptr, par);
      } else {
        sink += smg::lrm<S>(xv, cv, gv, lo, gxv, nullptr, par);
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
  m.def("node_confidences", &node_confidences, "positions"_a, "indices"_a, "weights"_a,
        "visibility"_a, "kappa_m"_a, "kappa_r"_a, "lambda_m"_a, "lambda_r"_a, "eps"_a);
  m.def(
      "carap",
      [](const at::Tensor& x, const at::Tensor& q, const at::Tensor& idx, const at::Tensor& w,
         const OptTensor& c, double alpha, double lc, double ll, const std::vector<int64_t>& gaps,
         const std::optional<std::vector<double>>& gw, bool normalize, bool gx, bool gq) {
        return carap_impl(false, x, q, idx, w, c, alpha, lc, ll, gaps, gw, normalize, gx, gq);
      },
      "positions"_a, "quats"_a, "indices"_a, "weights"_a, "confidence"_a, "alpha"_a, "lambda_c"_a,
      "lambda_l"_a, "gaps"_a, "gap_weights"_a, "normalize"_a, "grad_positions"_a, "grad_quats"_a);
  m.def(
      "arap",
      [](const at::Tensor& x, const at::Tensor& q, const at::Tensor& idx, const at::Tensor& w,
         double lc, double ll, const std::vector<int64_t>& gaps,
         const std::optional<std::vector<double>>& gw, bool normalize, bool gx, bool gq) {
        return carap_impl(true, x, q, idx, w, std::nullopt, 1.0, lc, ll, gaps, gw, normalize, gx,
                          gq);
      },
      "positions"_a, "quats"_a, "indices"_a, "weights"_a, "lambda_c"_a, "lambda_l"_a, "gaps"_a,
      "gap_weights"_a, "normalize"_a, "grad_positions"_a, "grad_quats"_a);
  m.def("_library_seconds", &library_seconds, "op"_a, "positions"_a, "quats"_a, "indices"_a, "weights"_a,
        "confidence"_a, "repeat"_a);
  m.def("lrm", &lrm_impl, "positions"_a, "indices"_a, "weights"_a, "confidence"_a, "alpha"_a,
        "huber_delta"_a, "detach_omega"_a, "normalize"_a, "grad_positions"_a);
}

}  // namespace smg_torch
