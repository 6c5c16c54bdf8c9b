// examples/torch/smg_torch_graph.cpp — the semantic motion graph for smg_torch (mirrors
// smg_cli's graph flags, examples/cli/graph_case.cpp): optional descriptors from feature samples
// (G1)-(G3), the exact trajectory KNN, the semantic gate, isolated policy and topology weights.
// No gradient (the graph is a constant of the energies). Indices come back as int64 (what
// PyTorch indexes with; converted from the library's int32 output, N×K values).
#include <optional>
#include <string>

#include "smg/graph.hpp"
#include "smg_torch_common.hpp"

namespace smg_torch {

namespace {

using OptTensor = std::optional<at::Tensor>;

// -> (indices int64 [N, K], weights [N, K], features [N, C] or None, distances [N, K])
py::tuple build_graph(const at::Tensor& positions, const OptTensor& visibility,
                      const OptTensor& feature_samples, const OptTensor& features, int64_t k,
                      double tau, const std::string& aggregation, int64_t m, double rho,
                      int64_t min_covisible, const std::string& isolated,
                      const std::string& weighting, bool gate) {
  const at::ScalarType st = float_type_of(positions, "positions");
  require_shape(positions, "positions", 3, 3, "[T, N, 3]");
  const at::Tensor x = positions.contiguous();
  const int64_t T = x.size(0), N = x.size(1);
  at::Tensor vis, fs, f;
  if (visibility) vis = visibility_input(*visibility);
  if (features) {
    f = float_input<float>(*features, "features", st);
    require_shape(f, "features", 2, -1, "[N, C]");
  } else if (feature_samples) {
    fs = float_input<float>(*feature_samples, "feature_samples", st);
    require_shape(fs, "feature_samples", 3, -1, "[T, N, C]");
  }
  if (k < 1 || k > (1 << 20)) value_error("k: must be in [1, 2^20], got " + std::to_string(k));
  if (m < 1 || m > 0x7fffffff) value_error("m: must be >= 1, got " + std::to_string(m));
  if (min_covisible < 0 || min_covisible > 0x7fffffff)
    value_error("min_covisible: must be >= 0, got " + std::to_string(min_covisible));
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
  at::Tensor feats = f;
  if (fs.defined()) feats = at::empty({N, C}, options_of(st));
  at::Tensor idx32 = at::empty({N, k}, at::TensorOptions().dtype(at::kInt));
  at::Tensor w = at::empty({N, k}, options_of(st)), d = at::empty({N, k}, options_of(st));
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
    py::gil_scoped_release release;
    smg::build_semantic_graph<S>(xv, vv, fv, o, iv, wv, dv);
    return 0;
  });
  return py::make_tuple(idx32.to(at::kLong), w, feats.defined() ? py::cast(feats) : py::none(), d);
}

}  // namespace

void register_graph(py::module_& m) {
  using namespace pybind11::literals;
  m.def("build_graph", &build_graph, "positions"_a, "visibility"_a, "feature_samples"_a,
        "features"_a, "k"_a, "tau"_a, "aggregation"_a, "m"_a, "rho"_a, "min_covisible"_a,
        "isolated"_a, "weighting"_a, "gate"_a);
}

}  // namespace smg_torch
