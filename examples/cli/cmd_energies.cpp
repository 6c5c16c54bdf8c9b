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
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "graph_case.hpp"
#include "smg/energy.hpp"
#include "subcommand.hpp"

namespace cli {

namespace {

// Comma-separated list of the default gaps' deltas or weights.
std::string gap_list(bool weights) {
  std::string out;
  for (const smg::Gap& g : smg::CarapOptions{}.gaps)
    out += (out.empty() ? "" : ",") + (weights ? format_number(g.weight) : format_number(g.delta));
  return out;
}

std::vector<FlagSpec> energy_flags() {
  // Defaults come from the library's option structs, so each exists once.
  const smg::ConfidenceOptions conf{};
  const smg::CarapOptions carap{};
  const smg::LrmOptions lrm{};
  std::vector<FlagSpec> f = {
      {"alpha", format_number(carap.alpha), "confidence floor of the edge weights (C-ARAP and LRM), in [0, 1]"},
      {"kappa-m", format_number(conf.kappa_m), "confidence: soft threshold of the motion factor"},
      {"kappa-r", format_number(conf.kappa_r), "confidence: soft threshold of the rigidity factor"},
      {"lambda-m", format_number(conf.lambda_m), "confidence: exponent of the motion factor"},
      {"lambda-r", format_number(conf.lambda_r), "confidence: exponent of the rigidity factor"},
      {"eps", format_number(conf.eps), "confidence: epsilon of the normalisers (a length per frame)"},
      {"lambda-c", format_number(carap.lambda_c), "C-ARAP/ARAP: weight of the vector-consistency term"},
      {"lambda-l", format_number(carap.lambda_l), "C-ARAP/ARAP: weight of the length-preservation term"},
      {"gaps", gap_list(false), "C-ARAP/ARAP: temporal gaps (frames), comma separated"},
      {"gap-weights", gap_list(true), "C-ARAP/ARAP: one weight per gap"},
      {"huber-delta", format_number(lrm.huber_delta), "LRM: Huber threshold (a velocity, length per frame)"},
      {"detach-omega", "", "LRM: hold omega constant in the gradient", true},
      {"normalize", "", "divide each energy (and gradient) by its number of terms", true}};
  for (auto& g : graph_flags()) f.push_back(g);
  return f;
}

struct Params {
  smg::ConfidenceOptions conf;
  smg::CarapOptions carap;
  smg::LrmOptions lrm;
  smg::ArapOptions arap;
};

// Library option names -> flags (for the messages of smg::validate_options).
const NameMap& energy_flag_names() {
  static const NameMap names = {{"alpha", "--alpha"},         {"kappa_m", "--kappa-m"},
                                {"kappa_r", "--kappa-r"},     {"lambda_m", "--lambda-m"},
                                {"lambda_r", "--lambda-r"},   {"eps", "--eps"},
                                {"lambda_c", "--lambda-c"},   {"lambda_l", "--lambda-l"},
                                {"gaps", "--gaps"},           {"huber_delta", "--huber-delta"}};
  return names;
}

Params read_params(const Args& a) {
  Params p;
  p.conf.kappa_m = a.get_double("kappa-m");
  p.conf.kappa_r = a.get_double("kappa-r");
  p.conf.lambda_m = a.get_double("lambda-m");
  p.conf.lambda_r = a.get_double("lambda-r");
  p.conf.eps = a.get_double("eps");
  const smg::GapList gaps = read_gap_list(a, "gaps", "gap-weights");
  const auto norm = a.get_switch("normalize") ? smg::Normalization::mean : smg::Normalization::sum;
  p.carap.alpha = a.get_double("alpha");
  p.carap.lambda_c = a.get_double("lambda-c");
  p.carap.lambda_l = a.get_double("lambda-l");
  p.carap.gaps = gaps;
  p.carap.normalization = norm;
  p.arap.lambda_c = p.carap.lambda_c;
  p.arap.lambda_l = p.carap.lambda_l;
  p.arap.gaps = p.carap.gaps;
  p.arap.normalization = norm;
  p.lrm.alpha = p.carap.alpha;
  p.lrm.huber_delta = a.get_double("huber-delta");
  p.lrm.detach_omega = a.get_switch("detach-omega");
  p.lrm.normalization = norm;
  NameMap names = energy_flag_names();
  // A gap weight message names "gaps[k].weight": that value came from --gap-weights.
  for (std::size_t k = 0; k < gaps.size(); ++k) names.push_back({"gaps[" + std::to_string(k) + "].weight", "--gap-weights"});
  check_mapped(smg::validate_options(p.conf), names, "energy options");
  check_mapped(smg::validate_options(p.carap), names, "energy options");
  check_mapped(smg::validate_options(p.lrm), names, "energy options");
  check_mapped(smg::validate_options(p.arap), names, "energy options");
  return p;
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
  const AllocContext ctx("energies of " + inv.case_dir.file("positions.npy"));
  std::vector<S> conf(static_cast<std::size_t>(T * N)), gxc(x.size(), S(0)), grc(x.size(), S(0)),
      gxl(x.size(), S(0)), gxa(x.size(), S(0)), gra(x.size(), S(0));
  const smg::FrameScalarsView<const S> cv(conf.data(), T, N);
  // Library messages name views ("graph: entry [i=..]"); report them under the case's files.
  const CaseDir& cd = inv.case_dir;
  const std::string graph_file = cd.file(g.built ? "positions.npy" : "graph_indices.npy");
  const NameMap names = {{"graph", graph_file},           {"neighbors", graph_file},
                         {"positions", cd.file("positions.npy")}, {"x", cd.file("positions.npy")},
                         {"quaternions", cd.file("quats.npy")},   {"quats", cd.file("quats.npy")},
                         {"q", cd.file("quats.npy")},             {"visibility", cd.file("visibility.npy")}};
  auto checked = [&](const smg::Status& st) { check_mapped(st, names, cd.path().string()); };
  checked(smg::validate_confidence<S>(xv, vv, graph, prm.conf, {conf.data(), T, N}));
  checked(smg::validate_carap<S>(xv, qv, {}, graph, prm.carap));
  checked(smg::validate_lrm<S>(xv, {}, graph, prm.lrm));
  checked(smg::validate_arap<S>(xv, qv, graph, prm.arap));

  smg::ParallelOptions par;
  par.threads = inv.threads;
  smg::EnergyWorkspace<S> ws;
  // Each part timed on its own (value and gradient together; the workspace is shared, so the
  // first part also pays for growing it); seconds is their sum.
  using Clock = std::chrono::steady_clock;
  auto since = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
  auto t0 = Clock::now();
  smg::node_confidences<S>(xv, vv, graph, prm.conf, {conf.data(), T, N}, {}, {}, &ws, par);
  const double s_conf = since(t0);
  t0 = Clock::now();
  const double e_carap = double(smg::carap<S>(xv, qv, cv, graph, prm.carap, {gxc.data(), T, N},
                                              {grc.data(), T, N}, &ws, par));
  const double s_carap = since(t0);
  t0 = Clock::now();
  const double e_lrm = double(smg::lrm<S>(xv, cv, graph, prm.lrm, {gxl.data(), T, N}, &ws, par));
  const double s_lrm = since(t0);
  t0 = Clock::now();
  const double e_arap = double(smg::arap<S>(xv, qv, graph, prm.arap, {gxa.data(), T, N},
                                            {gra.data(), T, N}, &ws, par));
  const double s_arap = since(t0);

  // Finite inputs must give finite results (docs/interop.md "Overflow").
  const std::string cause = inv.case_dir.file("positions.npy") + ": coordinates too large: the energies overflow (non-finite ";
  if (!std::isfinite(e_carap)) throw RunError(cause + "C-ARAP energy)");
  if (!std::isfinite(e_lrm)) throw RunError(cause + "LRM energy)");
  if (!std::isfinite(e_arap)) throw RunError(cause + "ARAP energy)");
  require_finite(conf, cause + "confidence)");
  require_finite(gxc, cause + "C-ARAP position gradient)");
  require_finite(grc, cause + "C-ARAP rotation gradient)");
  require_finite(gxl, cause + "LRM gradient)");
  require_finite(gxa, cause + "ARAP position gradient)");
  require_finite(gra, cause + "ARAP rotation gradient)");

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
      .add("seconds", s_conf + s_carap + s_lrm + s_arap)
      .add("seconds_confidence", s_conf)
      .add("seconds_carap", s_carap)
      .add("seconds_lrm", s_lrm)
      .add("seconds_arap", s_arap);
}

void run_energies(const Invocation& inv, JsonLine& summary) {
  const Params prm = read_params(inv.args);
  // Inputs in the computation's precision, confidences, 5 gradients, the workspace (~4 per-node
  // frame tables) and the graph's per-edge work.
  const double s = inv.use_float ? 4 : 8;
  const EnergyCase c = load_energy_case(inv, (3 * 8 + 4 * 8 + 1) + s * (3 + 4 + 1 + 15 + 12));
  if (inv.use_float)
    compute<float>(inv, prm, c.x, c.q, c.vis, c.g, summary);
  else
    compute<double>(inv, prm, c.x, c.q, c.vis, c.g, summary);
}

}  // namespace

Subcommand energies_subcommand() {
  return {"energies", "node confidences, C-ARAP, LRM and plain ARAP energies with their gradients", energy_flags(),
          /*writes_output=*/true, run_energies};
}

}  // namespace cli
