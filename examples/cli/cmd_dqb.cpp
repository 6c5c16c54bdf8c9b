// smg_cli dqb CASE OUT — dual-quaternion blending (or LBS with --lbs) of points driven by the
// node trajectories of a case (docs/interop.md, `dqb`).
//
// Reads positions.npy [T,N,3], quats.npy [T,N,4] (optional: identity), the graph
// (graph_indices.npy/graph_weights.npy, or built from the case with the graph flags),
// points.npy [P,3], point_quats.npy [P,4] (optional: identity), anchor.npy [P] int,
// t_ref.npy [P] int, t_query.npy [Q] int, sigma.npy [N]. Each point is driven by its anchor
// and the anchor's graph neighbours with the distance-aware weights of docs/design.md; writes
// blended_points.npy [Q,P,3] and blended_quats.npy [Q,P,4] (float64, or float32 with --float).
#include <chrono>
#include <cstdint>
#include <vector>

#include "graph_case.hpp"
#include "smg/skin.hpp"
#include "subcommand.hpp"

namespace cli {

namespace {

// Library view names -> the case's files.
NameMap skin_names(const CaseDir& c) {
  NameMap n;
  for (const char* f : {"anchor", "t_ref", "t_query", "points", "point_quats", "sigma", "positions", "quats"})
    n.push_back({f, c.file(std::string(f) + ".npy")});
  n.push_back({"quaternions", c.file("quats.npy")});
  n.push_back({"graph", c.file("graph_indices.npy")});
  return n;
}

// An index array, loaded as int64 (so that an int64 value beyond int32 cannot wrap into a
// valid index) and checked against [0, bound) before narrowing.
std::vector<std::int32_t> load_index(const CaseDir& cd, const std::string& file,
                                     const std::vector<Dim>& dims, std::int64_t bound,
                                     const char* bound_name) {
  const auto t = cd.load<std::int64_t>(file, dims);
  for (std::size_t i = 0; i < t.data.size(); ++i)
    if (t.data[i] < 0 || t.data[i] >= bound)
      throw RunError(cd.file(file) + ": element [" + std::to_string(i) + "] = " + std::to_string(t.data[i]) +
                     " is out of range [0, " + bound_name + "=" + std::to_string(bound) + ")");
  return std::vector<std::int32_t>(t.data.begin(), t.data.end());
}

struct DqbCase {
  std::int64_t T = 0, N = 0, P = 0, Q = 0, K = 0;
  std::vector<double> positions, quats, points, point_quats, sigma;
  std::vector<std::int32_t> anchor, t_ref, t_query;
  CaseGraph graph;
};

template <class S>
void blend(const Invocation& inv, const DqbCase& c, smg::SkinMethod method, OutputSet& out,
           std::int64_t& fallbacks) {
  const std::vector<S> positions = cast<S>(c.positions), quats = cast<S>(c.quats),
                       points = cast<S>(c.points), point_quats = cast<S>(c.point_quats),
                       sigma = cast<S>(c.sigma), graph_w = cast<S>(c.graph.weights);
  const smg::Index T = c.T, N = c.N, P = c.P, Q = c.Q, D = c.K + 1;
  smg::ParallelOptions par;
  par.threads = inv.threads;
  const smg::NeighborsView<S> graph(c.graph.indices.data(), graph_w.data(), N, c.K);
  const NameMap names = skin_names(inv.case_dir);
  const std::string fallback = inv.case_dir.path().string();
  auto ok = [&](const smg::Status& s) { check_mapped(s, names, fallback); };
  const AllocContext ctx("blend of " + inv.case_dir.file("points.npy") + " at " + inv.case_dir.file("t_query.npy"));
  std::vector<std::int32_t> drivers(static_cast<std::size_t>(P * D));
  const smg::TableView<std::int32_t, Eigen::Dynamic> drivers_out(drivers.data(), P, D);
  ok(smg::validate_skin_drivers(graph, {c.anchor.data(), P}, N, drivers_out));
  smg::skin_drivers(graph, {c.anchor.data(), P}, drivers_out, par);

  std::vector<S> weights(static_cast<std::size_t>(P * D));
  const smg::PositionsView<const S> x(positions.data(), T, N);
  const smg::TableView<S, Eigen::Dynamic> weights_out(weights.data(), P, D);
  ok(smg::validate_skinning_weights<S>(x, {drivers.data(), P, D}, {c.t_ref.data(), P},
                                       {points.data(), P}, {sigma.data(), N}, weights_out));
  fallbacks = smg::skinning_weights<S>(x, {drivers.data(), P, D}, {c.t_ref.data(), P},
                                       {points.data(), P}, {sigma.data(), N}, weights_out, par);

  smg::SkinPoints<S> pts;
  pts.drivers = {drivers.data(), P, D};
  pts.weights = {weights.data(), P, D};
  pts.t_ref = {c.t_ref.data(), P};
  pts.positions = {points.data(), P};
  pts.quaternions = {point_quats.data(), P};
  const smg::SkinNodes<S> nodes{x, {quats.data(), T, N}};
  std::vector<S> blended_points(static_cast<std::size_t>(Q * P * 3)),
      blended_quats(static_cast<std::size_t>(Q * P * 4));
  smg::SkinBlendOutputs<S> o;
  o.positions = {blended_points.data(), Q, P};
  o.quaternions = {blended_quats.data(), Q, P};
  ok(smg::validate_skin_blend(nodes, pts, {c.t_query.data(), Q}, o));
  smg::SkinOptions opt;
  opt.method = method;
  smg::skin_blend(nodes, pts, {c.t_query.data(), Q}, o, opt, par);
  // Finite inputs must give finite results (docs/interop.md "Overflow").
  const std::string cause = inv.case_dir.file("positions.npy") + ": coordinates too large: the blend overflows (non-finite ";
  require_finite(weights, cause + "skinning weight)");
  require_finite(blended_points, cause + "blended point)");
  require_finite(blended_quats, cause + "blended rotation)");
  out.add("blended_points.npy", std::move(blended_points), {Q, P, 3});
  out.add("blended_quats.npy", std::move(blended_quats), {Q, P, 4});
}

void run_dqb(const Invocation& inv, JsonLine& summary) {
  const CaseDir& cd = inv.case_dir;
  DqbCase c;
  auto x = cd.load<double>("positions.npy", {{"T"}, {"N"}, {"", 3}});
  c.T = x.dim(0);
  c.N = x.dim(1);
  ok(smg::validate_positions<double>({x.ptr(), c.T, c.N}, c.T, c.N, cd.file("positions.npy")));
  if (inv.use_float)
    require_coordinates<float>(x.data, cd.file("positions.npy"));
  else
    require_coordinates<double>(x.data, cd.file("positions.npy"));
  if (auto q = cd.load_optional<double>("quats.npy", {{"T", c.T}, {"N", c.N}, {"", 4}})) {
    ok(smg::validate_quaternions<double>({q->ptr(), c.T, c.N}, c.T, c.N,
                                         smg::QuaternionNorm::normalize_on_entry, cd.file("quats.npy")));
    c.quats = std::move(q->data);
  } else {
    c.quats.assign(static_cast<std::size_t>(c.T * c.N * 4), 0.0);
    for (std::int64_t i = 0; i < c.T * c.N; ++i) c.quats[i * 4] = 1.0;
  }
  c.graph = load_or_build_graph(inv, x);
  c.K = c.graph.k;
  c.positions = std::move(x.data);

  auto pts = cd.load<double>("points.npy", {{"P"}, {"", 3}});
  c.P = pts.dim(0);
  if (inv.use_float)
    require_coordinates<float>(pts.data, cd.file("points.npy"));
  else
    require_coordinates<double>(pts.data, cd.file("points.npy"));
  c.points = std::move(pts.data);
  if (auto pq = cd.load_optional<double>("point_quats.npy", {{"P", c.P}, {"", 4}})) {
    for (std::int64_t p = 0; p < c.P; ++p)
      if (!(smg::Vector4<double>::Map(&pq->data[p * 4]).norm() > 0))
        throw RunError(cd.file("point_quats.npy") + ": element [" + std::to_string(p) + "] is the zero quaternion");
    c.point_quats = std::move(pq->data);
  } else {
    c.point_quats.assign(static_cast<std::size_t>(c.P * 4), 0.0);
    for (std::int64_t p = 0; p < c.P; ++p) c.point_quats[p * 4] = 1.0;
  }
  c.anchor = load_index(cd, "anchor.npy", {{"P", c.P}}, c.N, "N");
  c.t_ref = load_index(cd, "t_ref.npy", {{"P", c.P}}, c.T, "T");
  c.t_query = load_index(cd, "t_query.npy", {{"Q"}}, c.T, "T");
  c.Q = static_cast<std::int64_t>(c.t_query.size());
  c.sigma = cd.load<double>("sigma.npy", {{"N", c.N}}).data;
  ok(smg::validate_skin_sigma<double>({c.sigma.data(), c.N}, c.N, cd.file("sigma.npy")));
  {
    // Outputs [Q,P,3] + [Q,P,4] in the computation's precision (the output set holds them until
    // written) + per-point drivers and weights + the converted inputs.
    const double s = inv.use_float ? 4 : 8, D = double(c.K + 1);
    const double bytes = double(c.Q) * double(c.P) * 7 * s + double(c.P) * D * (4 + s) +
                         double(c.T) * double(c.N) * 7 * s + double(c.P) * 7 * s;
    check_memory(bytes, inv.max_bytes,
                 cd.file("t_query.npy") + ": Q = " + std::to_string(c.Q) + " query frames x P = " + std::to_string(c.P) +
                     " points (points.npy) of blended outputs [Q,P,7]");
  }

  const smg::SkinMethod method = inv.args.get_switch("lbs") ? smg::SkinMethod::lbs
                                                            : smg::SkinMethod::dqb;
  OutputSet out;
  std::int64_t fallbacks = 0;
  // seconds: the drivers, weights and blend (loading, conversion and writing are not timed).
  const auto t0 = std::chrono::steady_clock::now();
  if (inv.use_float)
    blend<float>(inv, c, method, out, fallbacks);
  else
    blend<double>(inv, c, method, out, fallbacks);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  out.commit(inv.out_dir);
  summary.add("method", smg::to_string(method))
      .add("T", c.T)
      .add("N", c.N)
      .add("K", c.K)
      .add("P", c.P)
      .add("Q", c.Q)
      .add("graph_built", c.graph.built)
      .add("weight_fallbacks", fallbacks)
      .add("precision", inv.use_float ? "float32" : "float64")
      .add("seconds", seconds);
}

}  // namespace

Subcommand dqb_subcommand() {
  Subcommand s;
  s.name = "dqb";
  s.summary = "dual-quaternion blending (or LBS) of points and rotations driven by the graph nodes";
  s.flags = graph_flags();  // used only when the case has no graph_indices.npy
  s.flags.push_back({"lbs", "", "linear blend skinning instead of DQB (for comparison)", true});
  s.run = run_dqb;
  return s;
}

}  // namespace cli
