// Tests of `smg_cli graph` (docs/interop.md): outputs equal the library's, the three feature
// sources (feature_samples.npy, features.npy, none -> purely geometric graph), flags,
// --float, --threads, and one-line errors with exit code 2 and nothing written.
#include <doctest/doctest.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "graph/synthetic_scene.hpp"
#include "npy.hpp"
#include "smg/graph.hpp"
#include "support/run_program.hpp"

#ifdef SMG_CLI_PATH

namespace fs = std::filesystem;
using smg::Index;

namespace {

using Run = smg::test::ProgramRun;
Run run_cli(const std::string& args) { return smg::test::run_program(SMG_CLI_PATH, args, "smg_test_cli_graph_io"); }

struct Case {
  fs::path dir;
  smg::test::GraphScene<double> scene;
};

// A small scene of moving objects; the feature file written is chosen by `features`:
// "samples" (feature_samples.npy), "features" (features.npy: the object's direction) or "none".
Case make_case(const std::string& name, const std::string& features, bool visibility = true) {
  Case c;
  c.dir = fs::temp_directory_path() / ("smg_test_cli_graph_" + name);
  fs::remove_all(c.dir);
  fs::create_directories(c.dir);
  smg::test::SceneOptions so;
  so.nodes = 150;
  so.frames = 12;
  so.channels = 4;
  so.seed = 17;
  c.scene = smg::test::make_scene<double>(so);
  const auto& s = c.scene;
  npy::write((c.dir / "positions.npy").string(), s.positions, {s.T, s.N, 3});
  if (visibility) npy::write((c.dir / "visibility.npy").string(), s.visibility, {s.T, s.N});
  if (features == "samples") npy::write((c.dir / "feature_samples.npy").string(), s.samples, {s.T, s.N, s.C});
  if (features == "features") {
    std::vector<double> f(static_cast<std::size_t>(s.N * s.C));
    for (Index i = 0; i < s.N; ++i)
      for (Index k = 0; k < s.C; ++k)
        f[static_cast<std::size_t>(i * s.C + k)] =
            s.object_features[static_cast<std::size_t>(s.object[static_cast<std::size_t>(i)] * s.C + k)];
    npy::write((c.dir / "features.npy").string(), f, {s.N, s.C});
  }
  return c;
}

template <class T>
std::vector<T> load(const fs::path& p, std::vector<std::int64_t> shape, npy::DType dtype) {
  const npy::Array a = npy::read(p.string());
  CHECK(a.shape == shape);
  CHECK(a.dtype == dtype);
  return a.as<T>(p.string());
}

// The library's graph for the case, in S.
template <class S>
struct Expected {
  std::vector<std::int32_t> idx;
  std::vector<S> w, d, f;
  smg::GraphStats stats;
};

template <class S>
Expected<S> expected(const Case& c, smg::GraphOptions o, bool samples, const std::vector<double>* given = nullptr,
                     bool with_visibility = true) {
  const auto& s = c.scene;
  const std::vector<S> x(s.positions.begin(), s.positions.end());
  const smg::VisibilityView<const std::uint8_t> v =
      with_visibility ? smg::VisibilityView<const std::uint8_t>(s.visibility.data(), s.T, s.N)
                      : smg::VisibilityView<const std::uint8_t>();
  Expected<S> e;
  if (samples) {
    const std::vector<S> g(s.samples.begin(), s.samples.end());
    e.f.resize(static_cast<std::size_t>(s.N * s.C));
    smg::semantic_descriptors<S>({g.data(), s.T, s.N, s.C}, v, {}, {e.f.data(), s.N, s.C});
  } else if (given) {
    e.f.assign(given->begin(), given->end());
  }
  const Index K = o.knn.k;
  e.idx.resize(static_cast<std::size_t>(s.N * K));
  e.w.resize(e.idx.size());
  e.d.resize(e.idx.size());
  const smg::FeaturesView<const S> fv =
      o.gate ? smg::FeaturesView<const S>(e.f.data(), s.N, s.C) : smg::FeaturesView<const S>();
  e.stats = smg::build_semantic_graph<S>({x.data(), s.T, s.N}, v, fv, o, {e.idx.data(), s.N, K}, {e.w.data(), s.N, K},
                                         {e.d.data(), s.N, K});
  return e;
}

bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

}  // namespace

TEST_CASE("smg_cli graph: feature samples, outputs equal the library, --threads") {
  const auto c = make_case("samples", "samples");
  const fs::path out = c.dir / "out";
  const auto& s = c.scene;
  Run r = run_cli("graph " + c.dir.string() + " " + out.string());
  REQUIRE(r.code == 0);
  CHECK(r.err.empty());
  CHECK(r.out.rfind("{\"subcommand\":\"graph\",\"N\":150,\"T\":12,\"C\":4,\"K\":16,\"gated\":true,"
                    "\"features\":\"feature_samples.npy\",\"aggregation\":\"paper\",",
                    0) == 0);
  const auto e = expected<double>(c, {}, true);
  CHECK(load<std::int32_t>(out / "graph_indices.npy", {s.N, 16}, npy::DType::i32) == e.idx);
  CHECK(load<double>(out / "graph_weights.npy", {s.N, 16}, npy::DType::f64) == e.w);
  CHECK(load<double>(out / "distances.npy", {s.N, 16}, npy::DType::f64) == e.d);
  CHECK(load<double>(out / "features.npy", {s.N, s.C}, npy::DType::f64) == e.f);
  CHECK(has(r.out, "\"edges\":" + std::to_string(e.stats.edges) + ","));
  CHECK(has(r.out, "\"gate_removed_edges\":" + std::to_string(e.stats.gate_removed_edges) + ","));
  CHECK(has(r.out, "\"isolated_nodes\":" + std::to_string(e.stats.isolated_nodes) + ","));
  CHECK(has(r.out, "\"seconds\":"));
  // Any thread count writes the same files.
  const fs::path out1 = c.dir / "out1";
  REQUIRE(run_cli("graph " + c.dir.string() + " " + out1.string() + " --threads 1").code == 0);
  for (const char* f : {"graph_indices.npy", "graph_weights.npy", "distances.npy", "features.npy"})
    CHECK(smg::test::slurp(out / f) == smg::test::slurp(out1 / f));
}

TEST_CASE("smg_cli graph: flags reach the library; --float writes float32") {
  const auto c = make_case("flags", "samples");
  const fs::path out = c.dir / "out";
  const auto& s = c.scene;
  Run r = run_cli("graph " + c.dir.string() + " " + out.string() +
                  " --k 5 --aggregation robust_max --m 2 --min-covisible 2 --isolated leave --tau 0.9"
                  " --weighting distance --rho 0.75 --segment-frames 3 --float");
  REQUIRE(r.code == 0);
  CHECK(has(r.out, "\"K\":5,"));
  CHECK(has(r.out, "\"aggregation\":\"robust_max\""));
  CHECK(has(r.out, "\"segment_frames\":3,"));
  CHECK(has(r.out, "\"precision\":\"float32\",\"seconds\":"));
  smg::GraphOptions o;
  o.knn.k = 5;
  o.knn.distance.aggregation = smg::Aggregation::robust_max;
  o.knn.distance.m = 2;
  o.knn.distance.min_covisible = 2;
  o.knn.segment_frames = 3;
  o.isolated = smg::IsolatedPolicy::leave;
  o.tau = 0.9;
  o.weighting = smg::TopologyWeighting::distance;
  // rho = 0.75 for the descriptors.
  const std::vector<float> g(s.samples.begin(), s.samples.end());
  std::vector<float> f(static_cast<std::size_t>(s.N * s.C));
  smg::DescriptorOptions dopt;
  dopt.rho = 0.75;
  smg::semantic_descriptors<float>({g.data(), s.T, s.N, s.C}, {s.visibility.data(), s.T, s.N}, dopt,
                                   {f.data(), s.N, s.C});
  const std::vector<double> fd(f.begin(), f.end());
  const auto e = expected<float>(c, o, false, &fd);
  CHECK(load<std::int32_t>(out / "graph_indices.npy", {s.N, 5}, npy::DType::i32) == e.idx);
  CHECK(load<float>(out / "graph_weights.npy", {s.N, 5}, npy::DType::f32) == e.w);
  CHECK(load<float>(out / "distances.npy", {s.N, 5}, npy::DType::f32) == e.d);
  CHECK(load<float>(out / "features.npy", {s.N, s.C}, npy::DType::f32) == f);
}

TEST_CASE("smg_cli graph: features.npy is used as given; no features or --no-gate: geometric graph") {
  auto c = make_case("given", "features");
  const auto& s = c.scene;
  fs::path out = c.dir / "out";
  Run r = run_cli("graph " + c.dir.string() + " " + out.string());
  REQUIRE(r.code == 0);
  CHECK(has(r.out, "\"gated\":true,\"features\":\"features.npy\""));
  const auto given = npy::read((c.dir / "features.npy").string()).as<double>();
  CHECK(load<double>(out / "features.npy", {s.N, s.C}, npy::DType::f64) == given);
  auto e = expected<double>(c, {}, false, &given);
  CHECK(load<std::int32_t>(out / "graph_indices.npy", {s.N, 16}, npy::DType::i32) == e.idx);

  // --no-gate: the same case, ungated.
  out = c.dir / "out_nogate";
  r = run_cli("graph " + c.dir.string() + " " + out.string() + " --no-gate");
  REQUIRE(r.code == 0);
  CHECK(has(r.out, "\"gated\":false,\"features\":\"features.npy\""));
  CHECK(has(r.out, "\"gate_removed_edges\":0,"));
  smg::GraphOptions o;
  o.gate = false;
  e = expected<double>(c, o, false);
  CHECK(load<std::int32_t>(out / "graph_indices.npy", {s.N, 16}, npy::DType::i32) == e.idx);
  CHECK(load<double>(out / "graph_weights.npy", {s.N, 16}, npy::DType::f64) == e.w);

  // No feature file and no visibility file: geometric graph over all-visible trajectories.
  c = make_case("none", "none", false);
  out = c.dir / "out";
  r = run_cli("graph " + c.dir.string() + " " + out.string());
  REQUIRE(r.code == 0);
  CHECK(has(r.out, "\"C\":0,\"K\":16,\"gated\":false,\"features\":\"none\""));
  e = expected<double>(c, o, false, nullptr, false);
  CHECK(load<std::int32_t>(out / "graph_indices.npy", {s.N, 16}, npy::DType::i32) == e.idx);
  CHECK(load<double>(out / "distances.npy", {s.N, 16}, npy::DType::f64) == e.d);
  CHECK(load<double>(out / "features.npy", {s.N, 0}, npy::DType::f64).empty());
}

TEST_CASE("smg_cli graph: errors are one line, exit code 2, nothing written") {
  const auto c = make_case("errors", "samples");
  const fs::path out = c.dir / "out";
  auto fails = [&](const std::string& flags, const std::string& message) {
    fs::remove_all(out);
    const Run r = run_cli("graph " + c.dir.string() + " " + out.string() + flags);
    CHECK(r.code == 2);
    CHECK(r.out.empty());
    CHECK(r.err == "smg_cli graph: error: " + message + "\n");
    CHECK(!fs::exists(out));
  };
  fails(" --k 0", "--k: must be between 1 and 2147483647, got 0");
  fails(" --m 0", "--m: must be >= 1, got 0");
  fails(" --min-covisible -1", "--min-covisible: must be >= 0, got -1");
  fails(" --aggregation mean", "--aggregation: must be one of paper | robust_max, got 'mean'");
  fails(" --isolated drop", "--isolated: must be one of keep_nearest | leave, got 'drop'");
  fails(" --weighting inverse", "--weighting: must be one of uniform | distance, got 'inverse'");
  fails(" --rho 0", "--rho: must be in (0, 1], got 0");
  fails(" --tau nan", "--tau: expects a finite number, got 'nan'");
  // Bad files.
  const auto& s = c.scene;
  npy::write((c.dir / "visibility.npy").string(), std::vector<std::uint8_t>(static_cast<std::size_t>(s.N * 2), 1),
             {2, s.N});
  fails("", (c.dir / "visibility.npy").string() + ": expected shape [T=12, N=150], got [2, 150]");
  npy::write((c.dir / "visibility.npy").string(), s.visibility, {s.T, s.N});
  auto x = s.positions;
  x[5] = std::numeric_limits<double>::quiet_NaN();
  npy::write((c.dir / "positions.npy").string(), x, {s.T, s.N, 3});
  fails("", (c.dir / "positions.npy").string() + ": NaN at index [0, 1, 2]");
  npy::write((c.dir / "positions.npy").string(), s.positions, {s.T, s.N, 3});
  npy::write((c.dir / "feature_samples.npy").string(), std::vector<double>(static_cast<std::size_t>(s.T * (s.N + 1) * 2)),
             {s.T, s.N + 1, 2});
  fails("", (c.dir / "feature_samples.npy").string() + ": expected shape [T=12, N=150, C=any], got [12, 151, 2]");
}

#endif
