// Tests of `smg_cli energies` (docs/interop.md): outputs and summary match direct library calls,
// --float writes float32, optional inputs default as documented, graph flags are accepted, and
// errors give one line, exit code 2 and no output.
#include <doctest/doctest.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "energy/scene.hpp"
#include "npy.hpp"
#include "smg/energy.hpp"
#include "support/random.hpp"
#include "support/run_program.hpp"

#ifdef SMG_CLI_PATH

namespace fs = std::filesystem;
using smg::Index;
using smg::test::Scene;

namespace {

using Run = smg::test::ProgramRun;
Run run_cli(const std::string& args) { return smg::test::run_program(SMG_CLI_PATH, args, "smg_test_cli_energies_io"); }
double json_number(const std::string& line, const std::string& key) {
  const auto p = line.find("\"" + key + "\":");
  REQUIRE(p != std::string::npos);
  return std::stod(line.substr(p + key.size() + 3));
}
void write_case(const fs::path& dir, const Scene<double>& s, bool quats, bool vis) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  npy::write((dir / "positions.npy").string(), s.x, {s.T, s.N, 3});
  if (quats) npy::write((dir / "quats.npy").string(), s.q, {s.T, s.N, 4});
  if (vis) npy::write((dir / "visibility.npy").string(), s.v, {s.T, s.N});
  npy::write((dir / "graph_indices.npy").string(), s.idx, {s.N, s.K});
  npy::write((dir / "graph_weights.npy").string(), s.w, {s.N, s.K});
}
// The case folder smg_test_energies_case<tag> written from s (write_case), and the output
// folder smg_test_energies_out<tag>, removed.
std::pair<fs::path, fs::path> case_and_output(const std::string& tag, const Scene<double>& s, bool quats, bool vis) {
  const fs::path c = fs::temp_directory_path() / ("smg_test_energies_case" + tag);
  const fs::path o = fs::temp_directory_path() / ("smg_test_energies_out" + tag);
  write_case(c, s, quats, vis);
  fs::remove_all(o);
  return {c, o};
}
std::vector<double> load(const fs::path& p, npy::DType want, const std::vector<std::int64_t>& shape) {
  const npy::Array a = npy::read(p.string());
  CHECK(a.dtype == want);
  CHECK(a.shape == shape);
  return a.as<double>();
}
double max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double d = 0;
  for (std::size_t k = 0; k < a.size(); ++k) d = std::max(d, std::abs(a[k] - b[k]));
  return d;
}
double max_abs(const std::vector<double>& a) {
  double d = 0;
  for (double v : a) d = std::max(d, std::abs(v));
  return d;
}

}  // namespace

TEST_CASE("smg_cli energies: outputs and summary match the library") {
  smg::test::Rng rng(901);
  const Scene<double> s = smg::test::random_scene(7, 25, 5, rng, true);
  const auto [c, o] = case_and_output("", s, true, true);
  Run r = run_cli("energies " + c.string() + " " + o.string() +
                  " --gaps 1,3 --gap-weights 1,0.5 --huber-delta 0.02 --alpha 0.5 --k 8 --tau 0.8");
  REQUIRE(r.code == 0);
  CHECK(r.err.empty());
  CHECK(r.out.rfind("{\"subcommand\":\"energies\",\"N\":25,\"T\":7,\"K\":5,", 0) == 0);

  // The same computation through the library.
  std::vector<double> conf(s.v.size());
  smg::node_confidences<double>(s.positions(), s.visibility(), s.graph(), {},
                                {conf.data(), s.T, s.N});
  smg::CarapOptions co;
  co.gaps = {{1, 1.0}, {3, 0.5}};
  co.alpha = 0.5;
  smg::LrmOptions lo;
  lo.huber_delta = 0.02;
  lo.alpha = 0.5;
  smg::ArapOptions ao;
  ao.gaps = co.gaps;
  const smg::FrameScalarsView<const double> cv(conf.data(), s.T, s.N);
  std::vector<double> gxc(s.x.size()), grc(s.x.size()), gxl(s.x.size()), gxa(s.x.size()),
      gra(s.x.size());
  const double ec = smg::carap<double>(s.positions(), s.rotations(), cv, s.graph(), co,
                                       {gxc.data(), s.T, s.N}, {grc.data(), s.T, s.N});
  const double el = smg::lrm<double>(s.positions(), cv, s.graph(), lo, {gxl.data(), s.T, s.N});
  const double ea = smg::arap<double>(s.positions(), s.rotations(), s.graph(), ao,
                                      {gxa.data(), s.T, s.N}, {gra.data(), s.T, s.N});
  CHECK(json_number(r.out, "carap") == doctest::Approx(ec).epsilon(1e-9));
  CHECK(json_number(r.out, "lrm") == doctest::Approx(el).epsilon(1e-9));
  CHECK(json_number(r.out, "arap") == doctest::Approx(ea).epsilon(1e-9));
  // Per-part timings (each >= 0) and their sum.
  const double s_conf = json_number(r.out, "seconds_confidence"), s_carap = json_number(r.out, "seconds_carap"),
               s_lrm = json_number(r.out, "seconds_lrm"), s_arap = json_number(r.out, "seconds_arap");
  CHECK(s_conf >= 0);
  CHECK(s_carap >= 0);
  CHECK(s_lrm >= 0);
  CHECK(s_arap >= 0);
  CHECK(json_number(r.out, "seconds") == doctest::Approx(s_conf + s_carap + s_lrm + s_arap).epsilon(1e-6));
  CHECK(r.out.find("\"precision\":\"float64\"") != std::string::npos);
  const std::vector<std::int64_t> tn = {s.T, s.N}, tn3 = {s.T, s.N, 3};
  CHECK(max_diff(load(o / "confidence.npy", npy::DType::f64, tn), conf) == 0.0);
  CHECK(max_diff(load(o / "grad_positions_carap.npy", npy::DType::f64, tn3), gxc) == 0.0);
  CHECK(max_diff(load(o / "grad_rotations_carap.npy", npy::DType::f64, tn3), grc) == 0.0);
  CHECK(max_diff(load(o / "grad_positions_lrm.npy", npy::DType::f64, tn3), gxl) == 0.0);
  CHECK(max_diff(load(o / "grad_positions_arap.npy", npy::DType::f64, tn3), gxa) == 0.0);
  CHECK(max_diff(load(o / "grad_rotations_arap.npy", npy::DType::f64, tn3), gra) == 0.0);

  // --float: float32 files, values close to double; --threads does not change them.
  const fs::path of = fs::temp_directory_path() / "smg_test_energies_out_f";
  fs::remove_all(of);
  r = run_cli("energies " + c.string() + " " + of.string() +
              " --gaps 1,3 --gap-weights 1,0.5 --huber-delta 0.02 --alpha 0.5 --float --threads 2");
  REQUIRE(r.code == 0);
  CHECK(r.out.find("\"precision\":\"float32\"") != std::string::npos);
  const auto f = load(of / "grad_positions_carap.npy", npy::DType::f32, tn3);
  CHECK(max_diff(f, gxc) <= 1e-4 * max_abs(gxc));
  CHECK(json_number(r.out, "lrm") == doctest::Approx(el).epsilon(1e-4));
  fs::remove_all(o);
  fs::remove_all(of);
  fs::remove_all(c);
}

TEST_CASE("smg_cli energies: optional quats and visibility; --detach-omega and --normalize") {
  smg::test::Rng rng(902);
  Scene<double> s = smg::test::random_scene(5, 12, 4, rng, true);
  const auto [c, o] = case_and_output("2", s, false, false);
  Run r = run_cli("energies " + c.string() + " " + o.string() + " --detach-omega --normalize");
  REQUIRE(r.code == 0);
  // Identity rotations and all-visible nodes.
  for (Index k = 0; k < s.T * s.N; ++k) {
    s.q[4 * k] = 1;
    s.q[4 * k + 1] = s.q[4 * k + 2] = s.q[4 * k + 3] = 0;
    s.v[k] = 1;
  }
  std::vector<double> conf(s.v.size());
  smg::node_confidences<double>(s.positions(), {}, s.graph(), {}, {conf.data(), s.T, s.N});
  smg::LrmOptions lo;
  lo.detach_omega = true;
  lo.normalization = smg::Normalization::mean;
  smg::CarapOptions co;
  co.normalization = smg::Normalization::mean;
  const smg::FrameScalarsView<const double> cv(conf.data(), s.T, s.N);
  CHECK(json_number(r.out, "lrm") ==
        doctest::Approx(smg::lrm<double>(s.positions(), cv, s.graph(), lo)).epsilon(1e-9));
  CHECK(json_number(r.out, "carap") ==
        doctest::Approx(smg::carap<double>(s.positions(), s.rotations(), cv, s.graph(), co))
            .epsilon(1e-9));
  fs::remove_all(o);
  fs::remove_all(c);
}

TEST_CASE("smg_cli energies: errors are one line, exit code 2, nothing written") {
  smg::test::Rng rng(903);
  Scene<double> s = smg::test::random_scene(4, 6, 3, rng, true);
  const auto [c, o] = case_and_output("3", s, true, true);
  Run r = run_cli("energies " + c.string() + " " + o.string() + " --gaps 1,2 --gap-weights 1");
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli energies: error: --gap-weights: needs one weight per gap (2), got 1\n");
  r = run_cli("energies " + c.string() + " " + o.string() + " --alpha 1.5");
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli energies: error: --alpha: alpha must be in [0, 1], got 1.5\n");
  r = run_cli("energies " + c.string() + " " + o.string() + " --huber-delta 0");
  CHECK(r.err == "smg_cli energies: error: --huber-delta: huber_delta must be finite and > 0, got 0\n");
  CHECK(!fs::exists(o));
  // A zero quaternion.
  s.q[0] = s.q[1] = s.q[2] = s.q[3] = 0;
  write_case(c, s, true, true);
  r = run_cli("energies " + c.string() + " " + o.string());
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli energies: error: " + (c / "quats.npy").string() + ": element [t=0][i=0] is the zero quaternion\n");
  CHECK(r.out.empty());
  // No graph files: the graph is built from the case with the graph flags (graph module), and
  // the energies are computed on it.
  s.q[0] = 1;
  write_case(c, s, true, true);
  fs::remove(c / "graph_indices.npy");
  fs::remove(c / "graph_weights.npy");
  r = run_cli("energies " + c.string() + " " + o.string() + " --k 4");
  CHECK(r.code == 0);
  CHECK(r.err.empty());
  CHECK(fs::exists(o / "grad_positions_lrm.npy"));
  fs::remove_all(o);
  // Help lists the energy and graph flags.
  r = run_cli("energies --help");
  CHECK(r.code == 0);
  for (const char* flag : {"--alpha", "--kappa-m", "--gaps", "--gap-weights", "--huber-delta",
                           "--detach-omega", "--normalize", "--k", "--tau", "--isolated"})
    CHECK(r.out.find(flag) != std::string::npos);
  fs::remove_all(c);
}

// `smg_cli regularizers` is generated from the library's term list (smg::for_each_term,
// smg::for_each_option): every term and option of the list must be reachable by its flag, and
// the outputs must be smg::regularizers' own, bitwise.
TEST_CASE("smg_cli regularizers: flags from the term list, outputs bitwise the library's") {
  smg::test::Rng rng(904);
  const Scene<double> s = smg::test::random_scene(7, 20, 5, rng, true);
  const auto [c, o] = case_and_output("4", s, true, true);

  // Every term and every option of the list has its flag in --help.
  Run r = run_cli("regularizers --help");
  REQUIRE(r.code == 0);
  const smg::RegularizerOptions defaults;
  int terms = 0;
  smg::for_each_term(defaults, [&](const char* term, bool, const auto& options) {
    ++terms;
    CHECK(r.out.find(std::string(term)) != std::string::npos);
    smg::for_each_option(options, [&](const char* name, const auto&) {
      std::string flag = std::string("--") + term + "-" + name;
      for (char& ch : flag)
        if (ch == '_') ch = '-';
      if (flag.find("-normalization") != std::string::npos) flag.replace(flag.find("-normalization"), 14, "-normalize");
      INFO(flag);
      CHECK(r.out.find(flag) != std::string::npos);
    });
  });
  // The list has every flag of RegularizerTerms (a struct of bools).
  CHECK(static_cast<std::size_t>(terms) * sizeof(bool) == sizeof(smg::RegularizerTerms));

  // One term at a time, then all with options off their defaults: energies and gradients equal
  // the library call's.
  std::vector<std::pair<std::string, smg::RegularizerOptions>> runs;
  smg::for_each_term(defaults, [&](const char* term, bool, const auto&) {
    smg::RegularizerOptions one;
    smg::for_each_term(one, [&](const char* t, bool& on, const auto&) { on = std::string(t) == term; });
    runs.push_back({std::string("--terms ") + term, one});
  });
  // Smoothness with each penalty of the library's list (E22), by its name.
  for (const smg::Penalty p : smg::kPenalties) {
    smg::RegularizerOptions one;
    smg::for_each_term(one, [&](const char* t, bool& on, const auto&) { on = std::string(t) == "accel"; });
    one.accel.penalty = p;
    runs.push_back({std::string("--terms accel --accel-penalty ") + smg::to_string(p), one});
  }
  // Every term of the list, by name, as `--terms` and the "known" list of the error below.
  std::string every_term, known_terms;
  smg::for_each_term(defaults, [&](const char* term, bool, const auto&) {
    if (!every_term.empty()) {
      every_term += ',';
      known_terms += ", ";
    }
    every_term += term;
    known_terms += term;
  });
  smg::RegularizerOptions all;
  smg::for_each_term(all, [](const char*, bool& on, const auto&) { on = true; });
  all.carap.alpha = 0.5;
  all.arap.gaps = {{1, 1.0}, {3, 0.5}};
  all.lrm.huber_delta = 0.02;
  all.lrm.detach_omega = true;
  all.accel.form = smg::AccelForm::velocity;
  all.accel.confidence_weighted = true;
  all.accel.normalization = smg::Normalization::mean;
  all.accel.penalty = smg::Penalty::sqrt_weighted;
  all.accel.penalty_eps = 0.25;
  all.confidence.kappa_m = 1.5;
  runs.push_back({"--terms " + every_term + " --carap-alpha 0.5 --arap-gaps 1,3 "
                  "--arap-gap-weights 1,0.5 --lrm-huber-delta 0.02 --lrm-detach-omega --accel-form velocity "
                  "--accel-confidence-weighted --accel-normalize --accel-penalty sqrt_weighted "
                  "--accel-penalty-eps 0.25 --confidence-kappa-m 1.5",
                  all});
  for (const auto& run : runs) {
    // Not a structured binding: Clang's C++17 cannot capture one in INFO's lambda.
    const std::string& flags = run.first;
    const smg::RegularizerOptions& opts = run.second;
    INFO(flags);
    fs::remove_all(o);
    r = run_cli("regularizers " + c.string() + " " + o.string() + " " + flags);
    REQUIRE(r.code == 0);
    CHECK(r.err.empty());
    const std::size_t tn = static_cast<std::size_t>(s.T * s.N);
    std::vector<double> conf(tn), gx(3 * tn, 0.0), gr(3 * tn, 0.0);
    const bool rigid = smg::reads_rotations(opts.terms);
    const smg::RegularizerResult<double> e = smg::regularizers<double>(
        s.positions(), s.rotations(), s.visibility(), s.graph(), opts,
        opts.terms.confidence ? smg::FrameScalarsView<double>(conf.data(), s.T, s.N) : smg::FrameScalarsView<double>(),
        {gx.data(), s.T, s.N},
        rigid ? smg::RotationGradientView<double>(gr.data(), s.T, s.N) : smg::RotationGradientView<double>());
    smg::RegularizerResult<double>::each_energy(
        [&](const char* name, const double& v) { CHECK(json_number(r.out, name) == doctest::Approx(v).epsilon(1e-9)); },
        e);
    CHECK(json_number(r.out, "total") == doctest::Approx(double(e.total())).epsilon(1e-9));
    const std::vector<std::int64_t> tn2 = {s.T, s.N}, tn3 = {s.T, s.N, 3};
    CHECK(max_diff(load(o / "grad_positions.npy", npy::DType::f64, tn3), gx) == 0.0);
    CHECK(fs::exists(o / "grad_rotations.npy") == rigid);
    if (rigid) CHECK(max_diff(load(o / "grad_rotations.npy", npy::DType::f64, tn3), gr) == 0.0);
    CHECK(fs::exists(o / "confidence.npy") == opts.terms.confidence);
    if (opts.terms.confidence) CHECK(max_diff(load(o / "confidence.npy", npy::DType::f64, tn2), conf) == 0.0);
  }

  // Errors name the flag; nothing is written.
  fs::remove_all(o);
  r = run_cli("regularizers " + c.string() + " " + o.string() + " --terms carap,jerk");
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli regularizers: error: --terms: unknown term 'jerk' (known: " + known_terms + ")\n");
  r = run_cli("regularizers " + c.string() + " " + o.string() + " --lrm-alpha 1.5");
  CHECK(r.err == "smg_cli regularizers: error: --lrm-alpha: alpha must be in [0, 1], got 1.5\n");
  r = run_cli("regularizers " + c.string() + " " + o.string() + " --terms accel --accel-form jerk");
  CHECK(r.err == "smg_cli regularizers: error: --accel-form: must be one of acceleration | velocity, got 'jerk'\n");
  r = run_cli("regularizers " + c.string() + " " + o.string() + " --terms accel --accel-penalty cube");
  CHECK(r.err == "smg_cli regularizers: error: --accel-penalty: must be one of squared | norm | sqrt_weighted, got 'cube'\n");
  r = run_cli("regularizers " + c.string() + " " + o.string() + " --terms accel --accel-penalty-eps 0");
  CHECK(r.err == "smg_cli regularizers: error: --accel-penalty-eps: penalty_eps must be finite and > 0, got 0\n");
  CHECK(!fs::exists(o));
  fs::remove_all(c);
}

#endif
