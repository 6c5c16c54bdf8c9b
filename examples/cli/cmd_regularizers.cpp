// smg_cli regularizers CASE OUT — the fused regulariser step (smg::regularizers,
// docs/math/energy.md "The fused regulariser pass"): any subset of its terms with the gradient of
// their sum, in one pass (docs/interop.md).
//
// Its flags are generated from the library's term list (smg::for_each_term, smg::for_each_option
// in smg/energy/options.hpp): --terms names the terms that run, and every option of every term is
// a flag --<term>-<option> (underscores as dashes) with the library's default; a GapList is
// --<term>-gaps and --<term>-gap-weights, a Normalization the switch --<term>-normalize. So a
// term added to the list is a part of this subcommand with no edit here.
//
// Reads what `energies` reads (load_energy_case). Writes grad_positions.npy [T,N,3], with
// C-ARAP or ARAP grad_rotations.npy [T,N,3] (right tangent), with the confidences
// confidence.npy [T,N]; float64, or float32 with --float. The summary has every energy
// (RegularizerResult::each_energy, 0 for a term that is off) and their total.
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "graph_case.hpp"
#include "smg/energy.hpp"
#include "subcommand.hpp"

namespace cli {

namespace {

// "lambda_c" -> "lambda-c": the flags' spelling of the library's names.
std::string dashed(std::string s) {
  for (char& ch : s)
    if (ch == '_') ch = '-';
  return s;
}

// The flag "<term>-<name>" beside `flag` = "<term>-<option>" (a Normalization is read through the
// switch <term>-normalize, a GapList's weights through <term>-gap-weights; both options' names
// are one word, so the term is what precedes the last '-').
std::string sibling_flag(const std::string& flag, const char* name) {
  return flag.substr(0, flag.rfind('-')) + "-" + name;
}

// The flag(s) of one option, by the field's type; `flag` is "<term>-<option>".
void add_flags(std::vector<FlagSpec>& f, const std::string& flag, double v) {
  f.push_back({flag, format_number(v), "a number"});  // help completed by regularizer_flags
}
void add_flags(std::vector<FlagSpec>& f, const std::string& flag, bool v) {
  if (!v)
    f.push_back({flag, "", "a switch", true});
  else
    f.push_back({flag, "1", "1 or 0"});
}
void add_flags(std::vector<FlagSpec>& f, const std::string& flag, smg::Normalization) {
  // The library's field is `normalization`; its flag, like torch's key, is the switch
  // "normalize" (Normalization::mean), so the option's name is not used.
  f.push_back({sibling_flag(flag, "normalize"), "",
               "divide the energy (and gradient) by its number of terms", true});
}
void add_flags(std::vector<FlagSpec>& f, const std::string& flag, const smg::GapList& v) {
  std::string deltas, weights;
  for (const smg::Gap& g : v) {
    deltas += (deltas.empty() ? "" : ",") + format_number(g.delta);
    weights += (weights.empty() ? "" : ",") + format_number(g.weight);
  }
  f.push_back({flag, deltas, "temporal gaps (frames), comma separated"});
  f.push_back({sibling_flag(flag, "gap-weights"), weights, "one weight per gap"});
}
// A named enum (smg::enum_values: AccelForm, Penalty, ...): a choice of its values' names.
template <class E, class = decltype(smg::enum_values(E{}))>
void add_flags(std::vector<FlagSpec>& f, const std::string& flag, E v) {
  std::string names;
  for (const E a : smg::enum_values(E{})) names += std::string(names.empty() ? "" : " | ") + smg::to_string(a);
  f.push_back({flag, smg::to_string(v), names});
}

// The value of one option from its flag(s) (the inverse of add_flags).
void read_flag(const Args& a, const std::string& flag, double& v) { v = a.get_double(flag); }
void read_flag(const Args& a, const std::string& flag, bool& v) {
  // A switch reads "" (absent) or "1" (given); a flag whose default is true takes 0 or 1.
  const std::string s = a.get(flag);
  if (!s.empty() && s != "0" && s != "1") throw UsageError("--" + flag + ": must be 0 or 1, got '" + s + "'");
  v = s == "1";
}
void read_flag(const Args& a, const std::string& flag, smg::Normalization& v) {
  v = a.get_switch(sibling_flag(flag, "normalize")) ? smg::Normalization::mean
                                                                    : smg::Normalization::sum;
}
void read_flag(const Args& a, const std::string& flag, smg::GapList& v) {
  v = read_gap_list(a, flag, sibling_flag(flag, "gap-weights"));
}
template <class E, class = decltype(smg::enum_values(E{}))>
void read_flag(const Args& a, const std::string& flag, E& v) {
  std::vector<std::string> names;
  for (const E e : smg::enum_values(E{})) names.emplace_back(smg::to_string(e));
  const std::string s = a.get_choice(flag, names);
  for (const E e : smg::enum_values(E{}))
    if (s == smg::to_string(e)) v = e;
}

// The library's defaults, from which the flags and their defaults are generated.
const smg::RegularizerOptions kDefaults{};

// The terms on by default, comma separated.
std::string default_terms() {
  std::string on;
  smg::for_each_term(kDefaults, [&](const char* term, bool enabled, const auto&) {
    if (enabled) on += (on.empty() ? "" : ",") + std::string(term);
  });
  return on;
}

// Every term's name, comma separated.
std::string all_terms() {
  std::string all;
  smg::for_each_term(kDefaults, [&](const char* term, bool, const auto&) {
    all += (all.empty() ? "" : ", ") + std::string(term);
  });
  return all;
}

std::vector<FlagSpec> regularizer_flags() {
  std::vector<FlagSpec> f = {{"terms", default_terms(), "the terms that run, comma separated, of: " + all_terms()}};
  smg::for_each_term(kDefaults, [&](const char* term, bool, const auto& options) {
    smg::for_each_option(options, [&](const char* name, const auto& v) {
      const std::size_t first = f.size();
      add_flags(f, std::string(term) + "-" + dashed(name), v);
      // "carap.alpha: a number" names the library's field (docs/api.md, smg/energy/options.hpp).
      for (std::size_t k = first; k < f.size(); ++k)
        f[k].help = std::string(term) + "." + name + ": " + f[k].help;
    });
  });
  for (auto& g : graph_flags()) f.push_back(g);
  return f;
}

// RegularizerOptions from the flags; each term's options checked with messages naming its flags
// ("--carap-alpha: alpha must be in [0, 1], got 2").
smg::RegularizerOptions read_options(const Args& a) {
  smg::RegularizerOptions o;
  std::vector<std::string> terms = a.get_strings("terms");
  smg::for_each_term(o, [&](const char* term, bool& on, auto& options) {
    on = false;
    for (auto it = terms.begin(); it != terms.end(); ++it)
      if (*it == term) {
        on = true;
        terms.erase(it);
        break;
      }
    NameMap names;
    smg::for_each_option(options, [&](const char* name, auto& v) {
      const std::string flag = std::string(term) + "-" + dashed(name);
      read_flag(a, flag, v);
      names.push_back({name, "--" + flag});
    });
    if (on) check_mapped(smg::validate_options(options), names, "--" + std::string(term));
  });
  if (!terms.empty())
    throw UsageError("--terms: unknown term '" + terms.front() + "' (known: " + all_terms() + ")");
  return o;
}

template <class S>
void compute(const Invocation& inv, const smg::RegularizerOptions& o, const EnergyCase& c,
             JsonLine& summary) {
  const std::int64_t T = c.x.dim(0), N = c.x.dim(1);
  const bool rigid = smg::reads_rotations(o.terms);  // a term that reads the rotations is on
  const std::vector<S> x(c.x.data.begin(), c.x.data.end()), q(c.q.begin(), c.q.end()),
      w(c.g.weights.begin(), c.g.weights.end());
  const smg::PositionsView<const S> xv(x.data(), T, N);
  const smg::QuaternionsView<const S> qv(q.data(), T, N);
  const smg::VisibilityView<const std::uint8_t> vv(c.vis.data(), T, N);
  const smg::NeighborsView<S> graph(c.g.indices.data(), w.data(), N, c.g.k);
  const AllocContext ctx("regularizers of " + inv.case_dir.file("positions.npy"));
  const std::size_t tn = static_cast<std::size_t>(T * N);
  std::vector<S> conf(o.terms.confidence ? tn : 0), gx(3 * tn, S(0)), gr(rigid ? 3 * tn : 0, S(0));
  const smg::FrameScalarsView<S> cv = o.terms.confidence ? smg::FrameScalarsView<S>(conf.data(), T, N)
                                                         : smg::FrameScalarsView<S>();
  const smg::PositionsView<S> gxv(gx.data(), T, N);
  smg::RotationGradientView<S> grv;
  if (rigid) grv = smg::RotationGradientView<S>(gr.data(), T, N);
  const CaseDir& cd = inv.case_dir;
  const std::string graph_file = cd.file(c.g.built ? "positions.npy" : "graph_indices.npy");
  const NameMap names = {{"graph", graph_file},           {"neighbors", graph_file},
                         {"positions", cd.file("positions.npy")}, {"rotations", cd.file("quats.npy")},
                         {"quaternions", cd.file("quats.npy")},   {"visibility", cd.file("visibility.npy")}};
  check_mapped(smg::validate_regularizers<S>(xv, qv, vv, graph, o, cv, gxv, grv), names, cd.path().string());

  smg::ParallelOptions par;
  par.threads = inv.threads;
  const auto t0 = std::chrono::steady_clock::now();
  const smg::RegularizerResult<S> r =
      smg::regularizers<S>(xv, qv, vv, graph, o, cv, gxv, grv, nullptr, par);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  // Finite inputs must give finite results (docs/interop.md "Overflow").
  const std::string cause = cd.file("positions.npy") + ": coordinates too large: the energies overflow (non-finite ";
  smg::RegularizerResult<S>::each_energy(
      [&](const char* name, const auto& e) {
        if (!std::isfinite(double(e))) throw RunError(cause + name + " energy)");
      },
      r);
  require_finite(conf, cause + "confidence)");
  require_finite(gx, cause + "position gradient)");
  require_finite(gr, cause + "rotation gradient)");

  OutputSet out;
  if (o.terms.confidence) out.add("confidence.npy", conf, {T, N});
  out.add("grad_positions.npy", gx, {T, N, 3});
  if (rigid) out.add("grad_rotations.npy", gr, {T, N, 3});
  out.commit(inv.out_dir);
  summary.add("N", N)
      .add("T", T)
      .add("K", c.g.k)
      .add("edges", static_cast<std::int64_t>(smg::edge_count(graph)))
      .add("graph_built", c.g.built)
      .add("precision", sizeof(S) == 4 ? "float32" : "float64")
      .add("terms", inv.args.get("terms"));
  smg::RegularizerResult<S>::each_energy([&](const char* name, const auto& e) { summary.add(name, double(e)); }, r);
  summary.add("total", double(r.total())).add("seconds", seconds);
}

void run_regularizers(const Invocation& inv, JsonLine& summary) {
  const smg::RegularizerOptions o = read_options(inv.args);
  // Inputs in double (positions, quaternions, visibility), in the computation's precision
  // (positions, quaternions), the confidences and two gradients; the driver keeps its scratch
  // under the inputs' bytes.
  const double s = inv.use_float ? 4 : 8;
  const EnergyCase c = load_energy_case(inv, (3 * 8 + 4 * 8 + 1) + s * (3 + 4 + 1 + 3 + 3) * 2);
  if (inv.use_float)
    compute<float>(inv, o, c, summary);
  else
    compute<double>(inv, o, c, summary);
}

}  // namespace

Subcommand regularizers_subcommand() {
  return {"regularizers",
          "the fused regulariser step: any of its terms (--terms) with the gradient of their sum; flags from the term list",
          regularizer_flags(), /*writes_output=*/true, run_regularizers};
}

}  // namespace cli
