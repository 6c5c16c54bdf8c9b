// Tests of `smg_cli dqb` (docs/interop.md): outputs against the library called in-process, --lbs,
// --float against double, thread counts, and one-line errors with exit code 2 and nothing
// written. Cases carry graph_indices.npy / graph_weights.npy (the graph is not rebuilt).
#include <doctest/doctest.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "npy.hpp"
#include "skin/skin_test_support.hpp"
#include "support/run_program.hpp"

#ifdef SMG_CLI_PATH
namespace fs = std::filesystem;

namespace {
using smg::Index;

using Run = smg::test::ProgramRun;
Run run_cli(const std::string& args) { return smg::test::run_program(SMG_CLI_PATH, args, "smg_test_skin_cli_io"); }

struct CliCase {
  smg::test::SkinScene s;
  std::vector<std::int32_t> t_query;
  fs::path dir;
};

CliCase write_case(const std::string& name) {
  smg::test::Rng rng(541);
  CliCase c;
  c.s = smg::test::random_scene(rng, 4, 10, 3, 25);
  c.t_query = {3, 0, 2};
  c.dir = fs::temp_directory_path() / name;
  fs::remove_all(c.dir);
  fs::create_directories(c.dir);
  const auto& s = c.s;
  npy::write((c.dir / "positions.npy").string(), s.positions, {s.T, s.N, 3});
  npy::write((c.dir / "quats.npy").string(), s.quats, {s.T, s.N, 4});
  npy::write((c.dir / "graph_indices.npy").string(), s.graph_idx, {s.N, s.K});
  npy::write((c.dir / "graph_weights.npy").string(), s.graph_w, {s.N, s.K});
  npy::write((c.dir / "points.npy").string(), s.points, {s.P, 3});
  npy::write((c.dir / "point_quats.npy").string(), s.point_quats, {s.P, 4});
  // anchor as int64 and t_ref as int32: both integer widths are accepted.
  npy::write((c.dir / "anchor.npy").string(),
             std::vector<std::int64_t>(s.anchor.begin(), s.anchor.end()), {s.P});
  npy::write((c.dir / "t_ref.npy").string(), s.t_ref, {s.P});
  npy::write((c.dir / "t_query.npy").string(), c.t_query, {Index(c.t_query.size())});
  npy::write((c.dir / "sigma.npy").string(), s.sigma, {s.N});
  return c;
}

// The library in-process: drivers, weights, blend (double).
std::pair<std::vector<double>, std::vector<double>> reference(const CliCase& c, smg::SkinMethod m) {
  const auto& s = c.s;
  const Index D = s.K + 1, Q = Index(c.t_query.size());
  std::vector<std::int32_t> drivers(s.P * D);
  smg::skin_drivers(smg::NeighborsView<double>(s.graph_idx.data(), s.graph_w.data(), s.N, s.K),
                    {s.anchor.data(), s.P}, {drivers.data(), s.P, D});
  std::vector<double> w(s.P * D);
  smg::skinning_weights<double>({s.positions.data(), s.T, s.N}, {drivers.data(), s.P, D},
                                {s.t_ref.data(), s.P}, {s.points.data(), s.P},
                                {s.sigma.data(), s.N}, {w.data(), s.P, D});
  smg::SkinPoints<double> pts;
  pts.drivers = {drivers.data(), s.P, D};
  pts.weights = {w.data(), s.P, D};
  pts.t_ref = {s.t_ref.data(), s.P};
  pts.positions = {s.points.data(), s.P};
  pts.quaternions = {s.point_quats.data(), s.P};
  std::vector<double> bp(Q * s.P * 3), bq(Q * s.P * 4);
  smg::SkinBlendOutputs<double> o;
  o.positions = {bp.data(), Q, s.P};
  o.quaternions = {bq.data(), Q, s.P};
  smg::SkinOptions opt;
  opt.method = m;
  smg::skin_blend(smg::SkinNodes<double>{{s.positions.data(), s.T, s.N}, {s.quats.data(), s.T, s.N}},
                  pts, {c.t_query.data(), Q}, o, opt);
  return {bp, bq};
}

double max_abs_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double m = a.size() == b.size() ? 0 : 1e300;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) m = std::max(m, std::abs(a[i] - b[i]));
  return m;
}
}  // namespace

TEST_CASE("smg_cli dqb writes the library's blend; --lbs, --float and --threads") {
  const CliCase c = write_case("smg_test_skin_cli_case");
  const fs::path out = fs::temp_directory_path() / "smg_test_skin_cli_out";
  fs::remove_all(out);
  const Index P = c.s.P, Q = Index(c.t_query.size());
  for (smg::SkinMethod m : {smg::SkinMethod::dqb, smg::SkinMethod::lbs}) {
    const std::string method = smg::to_string(m);
    CAPTURE(method);
    const std::string flag = m == smg::SkinMethod::lbs ? " --lbs" : "";
    Run r = run_cli("dqb " + c.dir.string() + " " + out.string() + flag + " --threads 3");
    REQUIRE(r.code == 0);
    CHECK(r.err.empty());
    CHECK(r.out.rfind("{\"subcommand\":\"dqb\",\"method\":\"" + method +
                          "\",\"T\":4,\"N\":10,\"K\":3,\"P\":25,\"Q\":3,\"graph_built\":false,"
                          "\"weight_fallbacks\":0,\"precision\":\"float64\",\"seconds\":",
                      0) == 0);
    const npy::Array bp = npy::read((out / "blended_points.npy").string());
    const npy::Array bq = npy::read((out / "blended_quats.npy").string());
    CHECK(bp.shape == std::vector<std::int64_t>{Q, P, 3});
    CHECK(bq.shape == std::vector<std::int64_t>{Q, P, 4});
    CHECK(bp.dtype == npy::DType::f64);
    const auto ref = reference(c, m);
    CHECK(bp.as<double>() == ref.first);  // same code, same inputs: bit-identical
    CHECK(bq.as<double>() == ref.second);

    // One thread gives the same files.
    const fs::path out1 = out.string() + "_1";
    r = run_cli("dqb " + c.dir.string() + " " + out1.string() + flag + " --threads 1");
    REQUIRE(r.code == 0);
    CHECK(npy::read((out1 / "blended_points.npy").string()).as<double>() == ref.first);
    fs::remove_all(out1);

    // Float against double.
    const fs::path outf = out.string() + "_f";
    r = run_cli("dqb " + c.dir.string() + " " + outf.string() + flag + " --float");
    REQUIRE(r.code == 0);
    CHECK(r.out.find("\"precision\":\"float32\"") != std::string::npos);
    const npy::Array fp = npy::read((outf / "blended_points.npy").string());
    CHECK(fp.dtype == npy::DType::f32);
    CHECK(max_abs_diff(fp.as<double>(), ref.first) < 1e-5);
    CHECK(max_abs_diff(npy::read((outf / "blended_quats.npy").string()).as<double>(), ref.second) < 1e-5);
    fs::remove_all(outf);
  }
  fs::remove_all(out);
  fs::remove_all(c.dir);
}

TEST_CASE("smg_cli dqb: bad inputs give one line on stderr, exit code 2, nothing written") {
  const CliCase c = write_case("smg_test_skin_cli_bad");
  const fs::path out = fs::temp_directory_path() / "smg_test_skin_cli_bad_out";
  fs::remove_all(out);
  auto expect_error = [&](const std::string& message) {
    const Run r = run_cli("dqb " + c.dir.string() + " " + out.string());
    CHECK(r.code == 2);
    CHECK(r.err == "smg_cli dqb: error: " + message + "\n");
    CHECK(r.out.empty());
    CHECK_FALSE(fs::exists(out));
  };
  const auto& s = c.s;
  const std::string anchor = (c.dir / "anchor.npy").string();
  std::vector<std::int64_t> bad(s.anchor.begin(), s.anchor.end());
  bad[7] = 10;
  npy::write(anchor, bad, {s.P});
  expect_error(anchor + ": element [7] = 10 is out of range [0, N=10)");
  bad[7] = std::int64_t(1) << 32;  // would wrap to 0 as int32
  npy::write(anchor, bad, {s.P});
  expect_error(anchor + ": element [7] = 4294967296 is out of range [0, N=10)");
  npy::write(anchor, std::vector<std::int64_t>(s.anchor.begin(), s.anchor.end()), {s.P});

  npy::write((c.dir / "t_query.npy").string(), std::vector<std::int32_t>{0, -1}, {2});
  expect_error((c.dir / "t_query.npy").string() + ": element [1] = -1 is out of range [0, T=4)");
  npy::write((c.dir / "t_query.npy").string(), c.t_query, {3});

  std::vector<std::int32_t> tr = s.t_ref;
  tr[2] = 4;
  npy::write((c.dir / "t_ref.npy").string(), tr, {s.P});
  expect_error((c.dir / "t_ref.npy").string() + ": element [2] = 4 is out of range [0, T=4)");
  npy::write((c.dir / "t_ref.npy").string(), s.t_ref, {s.P});

  std::vector<double> sig = s.sigma;
  sig[1] = 0;
  npy::write((c.dir / "sigma.npy").string(), sig, {s.N});
  expect_error((c.dir / "sigma.npy").string() + ": element [1] = 0 is not positive");
  npy::write((c.dir / "sigma.npy").string(), s.sigma, {s.N});

  std::vector<double> pq = s.point_quats;
  std::fill(pq.begin() + 8, pq.begin() + 12, 0.0);
  npy::write((c.dir / "point_quats.npy").string(), pq, {s.P, 4});
  expect_error((c.dir / "point_quats.npy").string() + ": element [2] is the zero quaternion");
  npy::write((c.dir / "point_quats.npy").string(), s.point_quats, {s.P, 4});

  npy::write((c.dir / "points.npy").string(),
             std::vector<double>(s.points.begin(), s.points.end() - 3), {s.P - 1, 3});
  expect_error((c.dir / "point_quats.npy").string() + ": expected shape [P=24, 4], got [25, 4]");
  npy::write((c.dir / "points.npy").string(), s.points, {s.P, 3});

  fs::remove(c.dir / "sigma.npy");
  expect_error((c.dir / "sigma.npy").string() + ": missing required file");

  // Without graph files the graph is built from the case (graph module); the missing sigma is
  // still the error, and nothing is written.
  fs::remove(c.dir / "graph_indices.npy");
  const Run r = run_cli("dqb " + c.dir.string() + " " + out.string());
  CHECK(r.code == 2);
  CHECK(r.err.find("sigma.npy: missing required file") != std::string::npos);
  CHECK_FALSE(fs::exists(out));
  npy::write((c.dir / "sigma.npy").string(), s.sigma, {s.N});
  const Run built = run_cli("dqb " + c.dir.string() + " " + out.string());
  CHECK(built.code == 0);
  CHECK(fs::exists(out / "blended_points.npy"));
  fs::remove_all(c.dir);
}
#endif
