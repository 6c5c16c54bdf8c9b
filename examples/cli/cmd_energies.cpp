// smg_cli energies CASE OUT — node confidences, C-ARAP, LRM and plain ARAP with their gradients
// (docs/interop.md; docs/design.md "Confidence", "C-ARAP", "LRM", "Plain ARAP").
//
// Reads positions.npy [T,N,3] (required), quats.npy [T,N,4] (optional: identity),
// visibility.npy [T,N] (optional: all visible) and the graph (graph_indices.npy +
// graph_weights.npy, or built from the graph flags once the graph module provides it). Writes
// confidence.npy [T,N], grad_positions_carap.npy, grad_rotations_carap.npy (right tangent),
// grad_positions_lrm.npy, grad_positions_arap.npy, grad_rotations_arap.npy (all [T,N,3]), in
// float64, or float32 with --float. Confidences are computed once and used by C-ARAP and LRM.
#include <chrono>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "graph_case.hpp"
#include "smg/energy.hpp"
#include "subcommand.hpp"

namespace cli {

namespace {

std::vector<FlagSpec> energy_flags() {
  std::vector<FlagSpec> f = {
      {"alpha", "0.6", "confidence floor of the edge weights (C-ARAP and LRM), in [0, 1]"},
      {"kappa-m", "2.5", "confidence: soft threshold of the motion factor"},
      {"kappa-r", "2.5", "confidence: soft threshold of the rigidity factor"},
      {"lambda-m", "1", "confidence: exponent of the motion factor"},
      {"lambda-r", "1", "confidence: exponent of the rigidity factor"},
      {"eps", "1e-4", "confidence: epsilon of the normalisers (a length per frame)"},
      {"lambda-c", "1", "C-ARAP/ARAP: weight of the vector-consistency term"},
      {"lambda-l", "1", "C-ARAP/ARAP: weight of the length-preservation term"},
      {"gaps", "1,2,4", "C-ARAP/ARAP: temporal gaps (frames), comma separated"},
      {"gap-weights", "1,1,1", "C-ARAP/ARAP: one weight per gap"},
      {"huber-delta", "0.01", "LRM: Huber threshold (a velocity, length per frame)"},
      {"detach-omega", "", "LRM: hold omega constant in the gradient", true},
      {"normalize", "", "divide each energy (and gradient) by its number of terms", true}};
  for (auto& g : graph_flags()) f.push_back(g);
  return f;
}

void require(bool ok, const std::string& message) {
  if (!ok) throw UsageError(message);
}

struct Params {
  smg::ConfidenceOptions conf;
  smg::CarapOptions carap;
  smg::LrmOptions lrm;
  smg::ArapOptions arap;
};

Params read_params(const Args& a) {
  Params p;
  p.conf.kappa_m = a.get_double("kappa-m");
  p.conf.kappa_r = a.get_double("kappa-r");
  p.conf.lambda_m = a.get_double("lambda-m");
  p.conf.lambda_r = a.get_double("lambda-r");
  p.conf.eps = a.get_double("eps");
  require(p.conf.kappa_m > 0, "--kappa-m must be > 0");
  require(p.conf.kappa_r > 0, "--kappa-r must be > 0");
  require(p.conf.lambda_m >= 0, "--lambda-m must be >= 0");
  require(p.conf.lambda_r >= 0, "--lambda-r must be >= 0");
  require(p.conf.eps > 0, "--eps must be > 0");
  const double alpha = a.get_double("alpha");
  require(alpha >= 0 && alpha <= 1, "--alpha must be in [0, 1]");
  const double lc = a.get_double("lambda-c"), ll = a.get_double("lambda-l");
  require(lc >= 0, "--lambda-c must be >= 0");
  require(ll >= 0, "--lambda-l must be >= 0");
  const auto gaps = a.get_ints("gaps");
  const auto weights = a.get_doubles("gap-weights");
  require(!gaps.empty(), "--gaps needs at least one gap");
  require(weights.size() == gaps.size(), "--gap-weights needs one weight per gap (" +
                                             std::to_string(gaps.size()) + "), got " +
                                             std::to_string(weights.size()));
  std::vector<smg::Gap> g;
  for (std::size_t k = 0; k < gaps.size(); ++k) {
    require(gaps[k] >= 1 && gaps[k] <= 1000000, "--gaps entries must be integers >= 1");
    require(weights[k] >= 0, "--gap-weights entries must be >= 0");
    g.push_back({static_cast<int>(gaps[k]), weights[k]});
  }
  const double huber = a.get_double("huber-delta");
  require(huber > 0, "--huber-delta must be > 0");
  const auto norm = a.get_switch("normalize") ? smg::Normalization::mean : smg::Normalization::sum;
  p.carap.alpha = alpha;
  p.carap.lambda_c = lc;
  p.carap.lambda_l = ll;
  p.carap.gaps = smg::GapList(g.begin(), g.end());
  p.carap.normalization = norm;
  p.arap.lambda_c = lc;
  p.arap.lambda_l = ll;
  p.arap.gaps = smg::GapList(g.begin(), g.end());
  p.arap.normalization = norm;
  p.lrm.alpha = alpha;
  p.lrm.huber_delta = huber;
  p.lrm.detach_omega = a.get_switch("detach-omega");
  p.lrm.normalization = norm;
  return p;
}

void ok(const smg::Status& s) {
  if (!s) throw RunError(s.message());
}

template <class S>
void compute(const Invocation& inv, const Params& prm, const Tensor<double>& x_d,
             const std::vector<double>& q_d, const std::vector<std::uint8_t>& vis,
             const CaseGraph& g, JsonLine& summary) {
  const std::int64_t T = x_d.dim(0), N = x_d.dim(1);
  const std::vector<S> x(x_d.data.begin(), x_d.data.end()), q(q_d.begin(), q_d.end()),
      w(g.weights.begin(), g.weights.end());
  const smg::PositionsView<const S> xv(x.data(), T, N);
  const smg::QuaternionsView<const S> qv(q.data(), T, N);
  const smg::VisibilityView<const std::uint8_t> vv(vis.data(), T, N);
  const smg::NeighborsView<S> graph(g.indices.data(), w.data(), N, g.k);
  std::vector<S> conf(static_cast<std::size_t>(T * N)), gxc(x.size(), S(0)), grc(x.size(), S(0)),
      gxl(x.size(), S(0)), gxa(x.size(), S(0)), gra(x.size(), S(0));
  const smg::FrameScalarsView<const S> cv(conf.data(), T, N);
  ok(smg::validate_confidence<S>(xv, vv, graph, prm.conf, {conf.data(), T, N}));
  ok(smg::validate_carap<S>(xv, qv, {}, graph, prm.carap));
  ok(smg::validate_lrm<S>(xv, {}, graph, prm.lrm));
  ok(smg::validate_arap<S>(xv, qv, graph, prm.arap));

  smg::ParallelOptions par;
  par.threads = inv.threads;
  smg::EnergyWorkspace<S> ws;
  const auto t0 = std::chrono::steady_clock::now();
  smg::node_confidences<S>(xv, vv, graph, prm.conf, {conf.data(), T, N}, {}, {}, &ws, par);
  const double e_carap = double(smg::carap<S>(xv, qv, cv, graph, prm.carap, {gxc.data(), T, N},
                                              {grc.data(), T, N}, &ws, par));
  const double e_lrm = double(smg::lrm<S>(xv, cv, graph, prm.lrm, {gxl.data(), T, N}, &ws, par));
  const double e_arap = double(smg::arap<S>(xv, qv, graph, prm.arap, {gxa.data(), T, N},
                                            {gra.data(), T, N}, &ws, par));
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  OutputSet out;
  out.add("confidence.npy", conf, {T, N});
  out.add("grad_positions_carap.npy", gxc, {T, N, 3});
  out.add("grad_rotations_carap.npy", grc, {T, N, 3});
  out.add("grad_positions_lrm.npy", gxl, {T, N, 3});
  out.add("grad_positions_arap.npy", gxa, {T, N, 3});
  out.add("grad_rotations_arap.npy", gra, {T, N, 3});
  out.commit(inv.out_dir);
  summary.add("N", N)
      .add("T", T)
      .add("K", g.k)
      .add("edges", static_cast<std::int64_t>(smg::edge_count(graph)))
      .add("graph_built", g.built)
      .add("precision", sizeof(S) == 4 ? "float32" : "float64")
      .add("carap", e_carap)
      .add("lrm", e_lrm)
      .add("arap", e_arap)
      .add("seconds", seconds);
}

void run_energies(const Invocation& inv, JsonLine& summary) {
  const Params prm = read_params(inv.args);
  const CaseDir& c = inv.case_dir;
  const auto x = c.load<double>("positions.npy", {{"T"}, {"N"}, {"", 3}});
  const std::int64_t T = x.dim(0), N = x.dim(1);
  ok(smg::validate_positions<double>({x.ptr(), T, N}, T, N, "positions.npy"));
  std::vector<double> q;
  if (auto qs = c.load_optional<double>("quats.npy", {{"T", T}, {"N", N}, {"", 4}})) {
    ok(smg::validate_quaternions<double>({qs->ptr(), T, N}, T, N,
                                         smg::QuaternionNorm::normalize_on_entry, "quats.npy"));
    q = std::move(qs->data);
  } else {
    q.assign(static_cast<std::size_t>(T * N * 4), 0.0);
    for (std::int64_t k = 0; k < T * N; ++k) q[static_cast<std::size_t>(4 * k)] = 1.0;
  }
  std::vector<std::uint8_t> vis;
  if (auto v = c.load_optional<std::uint8_t>("visibility.npy", {{"T", T}, {"N", N}}))
    vis = std::move(v->data);
  else
    vis.assign(static_cast<std::size_t>(T * N), 1);
  const CaseGraph g = load_or_build_graph(inv, x);
  if (inv.use_float)
    compute<float>(inv, prm, x, q, vis, g, summary);
  else
    compute<double>(inv, prm, x, q, vis, g, summary);
}

}  // namespace

Subcommand energies_subcommand() {
  Subcommand s;
  s.name = "energies";
  s.summary = "node confidences, C-ARAP, LRM and plain ARAP energies with their gradients";
  s.flags = energy_flags();
  s.run = run_energies;
  return s;
}

}  // namespace cli
