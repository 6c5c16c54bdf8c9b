// smg_cli render (docs/interop.md): outputs and their shapes/dtypes, agreement with the library,
// the backward outputs with grad_image.npy, and one-line errors with exit code 2 and nothing
// written.
#include <doctest/doctest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "npy.hpp"
#include "splat_scene.hpp"
#include "support/run_program.hpp"

namespace fs = std::filesystem;
using namespace smg;
using namespace smg::splat;

#ifdef SMG_CLI_PATH
namespace {
using CliRun = smg::test::ProgramRun;
CliRun cli(const std::string& args) { return smg::test::run_program(SMG_CLI_PATH, args, "smg_test_splat_cli_io"); }

// Writes a case directory for `scene` seen by `cam`.
void write_case(const fs::path& dir, const test::SplatScene<double>& s, const Camera<double>& cam) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::int64_t G = s.G;
  npy::write((dir / "means.npy").string(), s.means, {G, 3});
  npy::write((dir / "quats.npy").string(), s.quats, {G, 4});
  npy::write((dir / "scales.npy").string(), s.log_scales, {G, 3});
  npy::write((dir / "opacities.npy").string(), s.logits, {G});
  npy::write((dir / "colors.npy").string(), s.colors, {G, std::int64_t(s.C)});
  std::vector<double> V(16), K = {cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1};
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) V[4 * std::size_t(r) + std::size_t(c)] = cam.viewmat(r, c);
  npy::write((dir / "viewmat.npy").string(), V, {4, 4});
  npy::write((dir / "K.npy").string(), K, {3, 3});
}
}  // namespace

TEST_CASE("smg_cli render: images and gradients match the library") {
  test::Rng rng(950);
  const auto cam = test::test_camera<double>(30, 20, 25.0, rng.rotation_with_angle(0.2));
  const auto scene = test::random_scene(rng, cam, 40, 3, 2.5);
  const fs::path dir = fs::temp_directory_path() / "smg_test_splat_cli_case";
  const fs::path out = fs::temp_directory_path() / "smg_test_splat_cli_out";
  fs::remove_all(out);
  write_case(dir, scene, cam);
  const auto w = test::random_weights(rng, 20, 30, 3, false, false);
  npy::write((dir / "grad_image.npy").string(), w.image, {20, 30, 3});

  CliRun r = cli("render " + dir.string() + " " + out.string() +
                 " --width 30 --height 20 --background 0.1,0.2,0.3 --threads 2");
  CHECK(r.code == 0);
  CHECK(r.err.empty());
  CHECK(r.out.rfind("{\"subcommand\":\"render\",\"G\":40,\"H\":20,\"W\":30,\"C\":3,", 0) == 0);
  CHECK(r.out.find("\"backward\":true,\"precision\":\"float64\",\"seconds\":") != std::string::npos);
  CHECK(r.out.find("\"seconds_forward\":") != std::string::npos);
  CHECK(r.out.find("\"seconds_backward\":") != std::string::npos);

  const double bg[3] = {0.1, 0.2, 0.3};
  SplatSettings<double> set;
  set.background = bg;
  RenderWorkspace<double> ws;
  const auto ref = test::render<3>(scene, cam, set, ws);
  const auto gref = test::backward<3>(scene, cam, set, ws, w);

  const npy::Array image = npy::read((out / "image.npy").string());
  CHECK(image.dtype == npy::DType::f64);
  CHECK(image.shape == std::vector<std::int64_t>{20, 30, 3});
  CHECK(image.as<double>() == ref.image);
  CHECK(npy::read((out / "alpha.npy").string()).as<double>() == ref.alpha);
  CHECK(npy::read((out / "depth.npy").string()).as<double>() == ref.depth);
  const auto radii = npy::read((out / "radii.npy").string());
  CHECK(radii.dtype == npy::DType::i32);
  for (std::size_t g = 0; g < 40; ++g) CHECK(radii.as<int>()[g] == int(ws.radii[g]));
  CHECK(npy::read((out / "grad_means.npy").string()).as<double>() == gref.means);
  CHECK(npy::read((out / "grad_quats.npy").string()).as<double>() == gref.quats);
  CHECK(npy::read((out / "grad_quats_tangent.npy").string()).as<double>() == gref.quats_tangent);
  CHECK(npy::read((out / "grad_scales.npy").string()).as<double>() == gref.log_scales);
  CHECK(npy::read((out / "grad_opacities.npy").string()).as<double>() == gref.logits);
  CHECK(npy::read((out / "grad_colors.npy").string()).as<double>() == gref.colors);
  CHECK(npy::read((out / "grad_opacities.npy").string()).shape == std::vector<std::int64_t>{40});

  // --float: float32 outputs close to the double ones
  fs::remove_all(out);
  r = cli("render " + dir.string() + " " + out.string() + " --width 30 --height 20 --float --background 0.1,0.2,0.3");
  CHECK(r.code == 0);
  const npy::Array imf = npy::read((out / "image.npy").string());
  CHECK(imf.dtype == npy::DType::f32);
  double err = 0;
  const auto vf = imf.as<double>();
  for (std::size_t k = 0; k < vf.size(); ++k) err = std::max(err, std::abs(vf[k] - ref.image[k]));
  CHECK(err < 1e-5);
  fs::remove_all(out);
  fs::remove_all(dir);
}

TEST_CASE("smg_cli render: errors are one line, exit code 2, nothing written") {
  test::Rng rng(951);
  const auto cam = test::test_camera<double>(16, 12, 15.0);
  auto scene = test::random_scene(rng, cam, 5, 3, 2.0);
  const fs::path dir = fs::temp_directory_path() / "smg_test_splat_cli_bad";
  const fs::path out = fs::temp_directory_path() / "smg_test_splat_cli_bad_out";
  fs::remove_all(out);
  const std::string args = " " + dir.string() + " " + out.string() + " --width 16 --height 12";

  write_case(dir, scene, cam);
  CliRun r = cli("render" + std::string(" ") + dir.string() + " " + out.string());
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli render: error: --width: must be between 1 and 65536, got 0\n");
  CHECK_FALSE(fs::exists(out));

  r = cli("render" + args + " --background 1,2");
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli render: error: --background: takes 1 or C = 3 comma-separated values\n");

  r = cli("render" + args + " --tile-size 12");
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli render: error: --tile-size: tile_size must be 8, 16 or 32, got 12\n");

  for (int k = 0; k < 4; ++k) scene.quats[8 + std::size_t(k)] = 0;
  write_case(dir, scene, cam);
  r = cli("render" + args);
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli render: error: " + (dir / "quats.npy").string() + ": element [2] is the zero quaternion\n");
  CHECK(r.out.empty());
  CHECK_FALSE(fs::exists(out));

  write_case(dir, test::random_scene(rng, cam, 5, 3, 2.0), cam);
  npy::write((dir / "grad_image.npy").string(), std::vector<double>(16 * 12 * 2, 0.0), {12, 16, 2});
  r = cli("render" + args);
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli render: error: " + (dir / "grad_image.npy").string() +
                     ": expected shape [H=12, W=16, C=3], got [12, 16, 2]\n");
  CHECK_FALSE(fs::exists(out));

  fs::remove(dir / "grad_image.npy");
  npy::write((dir / "K.npy").string(), std::vector<double>{15, 0.5, 8, 0, 15, 6, 0, 0, 1}, {3, 3});
  r = cli("render" + args);
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli render: error: " + (dir / "K.npy").string() +
                     ": nonzero skew K[0,1] is not supported\n");
  fs::remove(dir / "K.npy");
  r = cli("render" + args);
  CHECK(r.code == 2);
  CHECK(r.err == "smg_cli render: error: " + (dir / "K.npy").string() + ": missing required file\n");
  CHECK_FALSE(fs::exists(out));
  fs::remove_all(dir);
}
#endif
