// examples/torch/smg_torch_graph.cpp — the semantic motion graph for smg_torch (mirrors
// smg_cli's graph flags, examples/cli/graph_case.cpp): optional descriptors from feature samples
// (G1)-(G3), the exact trajectory KNN, the semantic gate, isolated policy and topology weights.
// No gradient (the graph is a constant of the energies). Indices come back as int64 (what
// PyTorch indexes with; converted from the library's int32 output, N×K values).
#include <limits>
#include <optional>
#include <string>

#include "smg/graph.hpp"
#include "smg_torch_common.hpp"

namespace smg_torch {

namespace {

// -> (indices int64 [N, K], weights [N, K], features [N, C] or None, distances [N, K])
py::tuple build_graph(const at::Tensor& positions, const OptTensor& visibility,
                      const OptTensor& feature_samples, const OptTensor& features,
                      const py::int_& k_arg, double tau, const std::string& aggregation,
                      const py::int_& m_arg, double rho, const py::int_& min_covisible_arg,
                      const std::string& isolated, const std::string& weighting, bool gate) {
  // The graph has no CUDA code: every tensor on the CPU.
  const std::pair<OptTensor, const char*> tensors[] = {{positions, "positions"},
                                                       {visibility, "visibility"},
                                                       {feature_samples, "feature_samples"},
                                                       {features, "features"}};
  for (const auto& [t, name] : tensors)
    if (t) require_cpu(*t, name);
  const Reference r = reference(positions, "positions");
  const at::ScalarType st = r.st;
  const at::Tensor x = float_input(positions, "positions", r, 3, 3, "[T, N, 3]");
  const int64_t T = x.size(0), N = x.size(1);
  at::Tensor vis, fs, f;
  if (visibility) vis = visibility_input(*visibility, r, true);
  if (features)
    f = float_input(*features, "features", r, 2, -1, "[N, C]");
  else if (feature_samples)
    fs = float_input(*feature_samples, "feature_samples", r, 3, -1, "[T, N, C]");
  // Integer arguments range-checked before they are narrowed to int.
  const int64_t k = int_arg(k_arg, "k", 1, 1 << 20);
  const int64_t m = int_arg(m_arg, "m", 1, 0x7fffffff);
  const int64_t min_covisible = int_arg(min_covisible_arg, "min_covisible", 0, 0x7fffffff);
  if (!(rho > 0 && rho <= 1)) value_error("rho: must be in (0, 1], got " + std::to_string(rho));
  if (aggregation != "paper" && aggregation != "robust_max")
    value_error("aggregation: must be 'paper' or 'robust_max', got '" + aggregation + "'");
  if (isolated != "keep_nearest" && isolated != "leave")
    value_error("isolated: must be 'keep_nearest' or 'leave', got '" + isolated + "'");
  if (weighting != "uniform" && weighting != "distance")
    value_error("weighting: must be 'uniform' or 'distance', got '" + weighting + "'");
  smg::GraphOptions o;
  o.knn.k = int(k);
  o.knn.distance.m = int(m);
  o.knn.distance.min_covisible = int(min_covisible);
  o.knn.distance.aggregation = aggregation == "paper" ? smg::Aggregation::paper : smg::Aggregation::robust_max;
  o.knn.parallel = parallel_options();
  o.tau = tau;
  o.isolated = isolated == "keep_nearest" ? smg::IsolatedPolicy::keep_nearest : smg::IsolatedPolicy::leave;
  o.weighting = weighting == "uniform" ? smg::TopologyWeighting::uniform : smg::TopologyWeighting::distance;
  smg::DescriptorOptions dopt;
  dopt.rho = rho;
  dopt.parallel = parallel_options();
  const int64_t C = f.defined() ? f.size(1) : fs.defined() ? fs.size(2) : 0;
  if ((f.defined() || fs.defined()) && C < 1)
    value_error(std::string(f.defined() ? "features" : "feature_samples") + ": needs at least one channel (C >= 1)");
  o.gate = gate && C > 0;
  // Outputs [N, k] (int32 indices and their int64 copy, weights, distances), the descriptors
  // [N, C] and the node-major trajectory copy [N, T, 3] (as smg_cli's graph).
  const double s = st == at::kFloat ? 4 : 8;
  const std::string what = "k: k = " + std::to_string(k) + " neighbours of N = " + std::to_string(N) +
                           " nodes";
  check_memory(double(N) * double(k) * (12 + 2 * s) + double(N) * double(C) * s +
                   double(N) * double(T) * 3 * s,
               what);
  at::Tensor feats = f, idx32, w, d;
  allocating(what, [&] {
    if (fs.defined()) feats = at::empty({N, C}, r.options());
    idx32 = at::empty({N, k}, r.int32());
    w = at::empty({N, k}, r.options());
    d = at::empty({N, k}, r.options());
  });
  dispatch(st, false, [&](auto s, auto) {
    using S = decltype(s);
    const smg::PositionsView<const S> xv(cptr<S>(x), T, N);
    const smg::VisibilityView<const std::uint8_t> vv =
        vis.defined() ? smg::VisibilityView<const std::uint8_t>(cptr<std::uint8_t>(vis), vis.size(0), vis.size(1))
                      : smg::VisibilityView<const std::uint8_t>();
    if (fs.defined()) {
      const smg::FeatureSamplesView<const S> sv(cptr<S>(fs), fs.size(0), fs.size(1), C);
      const smg::FeaturesView<S> out(mptr<S>(feats), N, C);
      ok(smg::validate_semantic_descriptors<S>(sv, vv, dopt, out));
      py::gil_scoped_release release;
      smg::semantic_descriptors<S>(sv, vv, dopt, out);
    }
    const smg::FeaturesView<const S> fv =
        o.gate ? smg::FeaturesView<const S>(cptr<S>(feats), feats.size(0), C) : smg::FeaturesView<const S>();
    const smg::TableView<std::int32_t, Eigen::Dynamic> iv(mptr<std::int32_t>(idx32), N, k);
    const smg::TableView<S, Eigen::Dynamic> wv(mptr<S>(w), N, k), dv(mptr<S>(d), N, k);
    ok(smg::validate_semantic_graph<S>(xv, vv, fv, o, iv, wv, dv));
    allocating(what, [&] {  // the KNN's workspace
      py::gil_scoped_release release;
      smg::build_semantic_graph<S>(xv, vv, fv, o, iv, wv, dv);
    });
    return 0;
  });
  const at::Tensor idx64 = allocating(what, [&] { return idx32.to(at::kLong); });
  return py::make_tuple(idx64, w, feats.defined() ? py::cast(feats) : py::none(), d);
}

// knn_points -> (squared distances [N, k] of points' dtype, indices int64 [N, k]) (G15):
// exact rows by (d², j), d² <= radius² (radius None = +inf), self included or not, padded +inf
// / -1. CPU: the tree search on torch's thread count, straight into torch's int64 (no copy);
// CUDA: the all-pairs kernel on the current stream. No gradient here (smg_torch.knn_points adds
// d²'s).
py::tuple knn_points(const at::Tensor& points, const py::int_& k_arg, const py::object& radius_arg,
                     bool include_self) {
  const Reference r = reference(points, "points");
  const at::Tensor p = float_input(points, "points", r, 2, 3, "[N, 3]");
  const int64_t N = p.size(0);
  const int64_t k = int_arg(k_arg, "K", 1, 1 << 20);
  double radius = std::numeric_limits<double>::infinity();
  if (!radius_arg.is_none()) {
    radius = py::cast<double>(radius_arg);
    if (!(radius >= 0)) value_error("radius: must be >= 0 (or None for no bound), got " + std::to_string(radius));
  }
  const std::string what = "K: K = " + std::to_string(k) + " neighbours of N = " + std::to_string(N) + " points";
  check_memory(double(N) * double(k) * (8 + (r.st == at::kFloat ? 4 : 8)) + double(N) * 40, what);
  at::Tensor idx, d2;
  allocating(what, [&] {
    idx = at::empty({N, k}, r.options().dtype(at::kLong));
    d2 = at::empty({N, k}, r.options());
  });
  if (r.cuda()) {
    cuda(cuda_ops().point_knn)(r, p, int(k), radius, include_self, idx, d2);
    return py::make_tuple(d2, idx);
  }
  dispatch(r.st, true, [&](auto s, auto) {
    using S = decltype(s);
    smg::PointKnnOptions o;
    o.k = int(k);
    o.radius = radius;
    o.include_self = include_self;
    o.parallel = parallel_options();
    const smg::TableView<const S, 3> pv(cptr<S>(p), N);
    const smg::TableView<std::int64_t, Eigen::Dynamic> iv(mptr<std::int64_t>(idx), N, k);
    const smg::TableView<S, Eigen::Dynamic> dv(mptr<S>(d2), N, k);
    ok(smg::validate_point_knn<S, std::int64_t>(pv, o, iv, dv));
    allocating(what, [&] {  // the tree
      py::gil_scoped_release release;
      smg::point_knn<S, std::int64_t>(pv, o, iv, dv);
    });
    return 0;
  });
  return py::make_tuple(d2, idx);
}

}  // namespace

void register_graph(py::module_& m) {
  using namespace pybind11::literals;
  m.def("build_graph", &build_graph, "positions"_a, "visibility"_a, "feature_samples"_a,
        "features"_a, "k"_a, "tau"_a, "aggregation"_a, "m"_a, "rho"_a, "min_covisible"_a,
        "isolated"_a, "weighting"_a, "gate"_a);
  m.def("knn_points", &knn_points, "points"_a, "K"_a, "radius"_a, "include_self"_a);
}

}  // namespace smg_torch
