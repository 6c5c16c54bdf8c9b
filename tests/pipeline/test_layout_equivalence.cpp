// The procedural scene exported in our Dycheck + priors layout, in Shape-of-Motion's and in MoSca's
// (layouts.hpp) trains the same: the scenes read back agree (cameras, images, depth through the
// float32 disparity round trip, masks, tracks, features), stage 0 gives the same lifted tracks,
// nodes and graph, and a short run the same metrics within a stated tolerance. Also smg_trainer
// --export-layout som / mosca and --data on them, and both layouts'
// refusals through the CLI. The SoM export holds both of SoM's camera sets; the reader takes the
// refined COLMAP one, which must equal the original Nerfies one.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "npy.hpp"
#include "support/files.hpp"
#include "support/run_program.hpp"
#include "trainer/data_evaluate.hpp"
#include "trainer/data_export.hpp"
#include "trainer/data_queries.hpp"
#include "trainer/data_scene.hpp"
#include "trainer/dycheck.hpp"
#include "trainer/file_formats.hpp"
#include "trainer/layouts.hpp"
#include "trainer/pipeline.hpp"
#include "scene_on_disk.hpp"

namespace fs = std::filesystem;

namespace {

// The scene's tracks stable-sorted by query frame: the order the SoM layout keeps (one file per
// query frame), so that both layouts hand the pipeline the same track order.
void sort_tracks_by_query(trainer::DycheckScene& s) {
  trainer::DycheckTracks& tr = s.tracks;
  const std::size_t Q = static_cast<std::size_t>(tr.count), T = static_cast<std::size_t>(tr.frames);
  std::vector<std::size_t> order(Q);
  for (std::size_t k = 0; k < Q; ++k) order[k] = k;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return tr.query_t[a] < tr.query_t[b]; });
  trainer::DycheckTracks out = tr;
  for (std::size_t k = 0; k < Q; ++k) {
    out.query_t[k] = tr.query_t[order[k]];
    for (std::size_t t = 0; t < T; ++t) {
      out.visible[t * Q + k] = tr.visible[t * Q + order[k]];
      out.uv[2 * (t * Q + k)] = tr.uv[2 * (t * Q + order[k])];
      out.uv[2 * (t * Q + k) + 1] = tr.uv[2 * (t * Q + order[k]) + 1];
    }
  }
  tr = out;
}

const trainer::Progress& equivalence_silent() {
  static const trainer::Progress p(nullptr, true);
  return p;
}

// max |a - b| of two arrays of the same size.
double equivalence_max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  using Vec = Eigen::Map<const Eigen::VectorXd>;
  const Eigen::Index n = static_cast<Eigen::Index>(a.size());
  return n == 0 ? 0.0 : (Vec(a.data(), n) - Vec(b.data(), n)).cwiseAbs().maxCoeff();
}

// The Dycheck + priors layout's stage 0 and short run, which both comparisons read: made once.
struct EquivalenceReference {
  trainer::TrainerResult stage0;
  trainer::FrameScore final_mean;
};
EquivalenceReference equivalence_reference(const trainer::TrainerConfig& cfg, const trainer::DycheckScene& a) {
  EquivalenceReference r;
  r.stage0 = trainer::run_stage0(cfg, trainer::dataset_from_dycheck(trainer::DycheckScene(a)), equivalence_silent());
  r.final_mean = trainer::run_trainer(trainer::TrainerResult(r.stage0), equivalence_silent()).evaluation.frames_mean;
  return r;
}

// The same scene read back from two layouts (a: Dycheck + priors, whose runs are `ref`, b: another;
// `name` in the messages) trains the same: files, stage 0, a short run.
void equivalence_compare(const trainer::TrainerConfig& cfg, const trainer::DycheckScene& a,
                         const EquivalenceReference& ref, trainer::DycheckScene b, const std::string& name) {
  INFO("layout " << name);
  // The files: cameras to 1e-12 (JSON %.17g, the +-0.5 pixel-centre shift), images, masks,
  // visibility, query frames and features exactly; uv exactly except samples within 0.25 px of
  // the image's left or top edge (x - 0.5 rounded to float32); depth to 2 float32 ulps (1 / (1 / z)).
  REQUIRE(a.frames() == b.frames());
  REQUIRE(a.width == b.width);
  REQUIRE(a.height == b.height);
  for (std::size_t t = 0; t < a.train_cameras.size(); ++t) {
    const trainer::Camera &p = a.train_cameras[t], &q = b.train_cameras[t];
    CHECK((p.world_to_camera - q.world_to_camera).cwiseAbs().maxCoeff() < 1e-12);
    CHECK(std::abs(p.fx - q.fx) < 1e-12);
    CHECK(std::abs(p.cx - q.cx) < 1e-12);
    CHECK(std::abs(p.cy - q.cy) < 1e-12);
    CHECK(a.train_rgb[t].pixels == b.train_rgb[t].pixels);
  }
  CHECK(a.val.size() == b.val.size());
  CHECK(a.val_covisible == b.val_covisible);
  CHECK(a.dynamic_mask == b.dynamic_mask);
  CHECK(a.tracks.count == b.tracks.count);
  CHECK(a.tracks.query_t == b.tracks.query_t);
  // Visibility exactly, except that MoSca's reader clears it where the sample's pixel index is
  // outside the image (Saved2D), which the Dycheck reader allows within 64 px.
  REQUIRE(a.tracks.visible.size() == b.tracks.visible.size());
  std::size_t cleared = 0;
  for (std::size_t k = 0; k < a.tracks.visible.size(); ++k) {
    if (a.tracks.visible[k] == b.tracks.visible[k]) continue;
    const double x = a.tracks.uv[2 * k] - 0.5, y = a.tracks.uv[2 * k + 1] - 0.5;
    CHECK(b.tracks.visible[k] == 0);
    CHECK((x <= -1 || y <= -1 || x >= a.width || y >= a.height));
    ++cleared;
  }
  MESSAGE(name << ": " << cleared << " visible samples outside the image cleared");
  if (name != "mosca") CHECK(cleared == 0);
  CHECK(a.features == b.features);
  double uv_err = 0, depth_rel = 0;
  for (std::size_t k = 0; k < a.tracks.uv.size(); ++k) uv_err = std::max(uv_err, double(std::abs(a.tracks.uv[k] - b.tracks.uv[k])));
  for (std::size_t k = 0; k < a.depth.size(); ++k)
    if (a.depth[k] > 0) depth_rel = std::max(depth_rel, double(std::abs(a.depth[k] - b.depth[k])) / a.depth[k]);
    else CHECK(b.depth[k] == 0);
  MESSAGE(name << ": uv max |diff| " << uv_err << " px, depth max relative diff " << depth_rel);
  CHECK(uv_err < 1e-6);
  CHECK(depth_rel <= 2.4e-7);

  // Stage 0: lifted tracks to 1e-5 m (the depth's float32 round trip), the same nodes and graph.
  const trainer::TrainerResult& ra = ref.stage0;
  trainer::TrainerResult rb = trainer::run_stage0(cfg, trainer::dataset_from_dycheck(std::move(b)), equivalence_silent());
  REQUIRE(ra.lifted.count == rb.lifted.count);
  CHECK(ra.lifted.track == rb.lifted.track);
  CHECK(ra.lifted.visible == rb.lifted.visible);
  const double lifted_err = equivalence_max_diff(ra.lifted.positions, rb.lifted.positions);
  REQUIRE(ra.nodes.count == rb.nodes.count);
  CHECK(ra.nodes.track == rb.nodes.track);
  CHECK(ra.nodes.graph.indices == rb.nodes.graph.indices);
  const double weight_err = equivalence_max_diff(ra.nodes.graph.weights, rb.nodes.graph.weights);
  MESSAGE(name << ": lifted " << ra.lifted.count << " tracks, max |diff| " << lifted_err << " m; " << ra.nodes.count
                    << " nodes; graph weights max |diff| " << weight_err);
  CHECK(lifted_err < 1e-5);
  CHECK(weight_err < 1e-5);

  // A short run: mPSNR within 0.05 dB, mSSIM within 1e-3 (the same optimisation from inputs
  // that differ by float32 rounding; its chaotic growth stays far below these).
  const trainer::TrainerResult fb = trainer::run_trainer(std::move(rb), equivalence_silent());
  const trainer::FrameScore &ma = ref.final_mean, &mb = fb.evaluation.frames_mean;
  MESSAGE(name << ": mPSNR " << ma.mpsnr << " vs " << mb.mpsnr << ", mSSIM " << ma.mssim << " vs " << mb.mssim);
  CHECK(std::abs(ma.mpsnr - mb.mpsnr) < 0.05);
  CHECK(std::abs(ma.mssim - mb.mssim) < 1e-3);
}

}  // namespace

TEST_CASE("the procedural scene in the Dycheck, Shape-of-Motion and MoSca layouts: same data, stage 0, metrics") {
  const trainer::TrainerConfig cfg = smg::test::tiny_scene_config();
  const trainer::Dataset memory = trainer::make_dataset(cfg.dataset, smg::ParallelOptions{2, 0});
  trainer::DycheckScene scene = trainer::to_dycheck(memory);
  sort_tracks_by_query(scene);
  // MoSca's evaluation frames are the sorted stems of test_images/.
  std::sort(scene.val.begin(), scene.val.end(), [](const trainer::DycheckFrame& p, const trainer::DycheckFrame& q) { return p.name < q.name; });
  const fs::path dy = fs::temp_directory_path() / "smg_test_layout_eq_dycheck";
  const fs::path som = fs::temp_directory_path() / "smg_test_layout_eq_som";
  const fs::path mosca = fs::temp_directory_path() / "smg_test_layout_eq_mosca";
  for (const fs::path& p : {dy, som, mosca}) fs::remove_all(p);
  trainer::write_dycheck(dy.string(), scene);
  trainer::write_som(som.string(), scene);
  trainer::write_mosca(mosca.string(), scene);
  trainer::DataLayout ld = trainer::DataLayout::som, ls = trainer::DataLayout::dycheck, lm = trainer::DataLayout::dycheck;
  const trainer::DycheckScene a = trainer::read_data_scene(dy.string(), &ld);
  CHECK(ld == trainer::DataLayout::dycheck);
  const trainer::DycheckScene refined = trainer::read_data_scene(som.string(), &ls);
  const EquivalenceReference ref = equivalence_reference(cfg, a);
  equivalence_compare(cfg, a, ref, refined, "som");
  CHECK(ls == trainer::DataLayout::som);
  // The same SoM export read with its original cameras (camera/ and the lidar-aligned depth, once
  // the COLMAP model is gone): the same cameras to 1e-12 and the same depth, bit for bit (the
  // COLMAP scale is a power of two).
  fs::remove_all(som / "flow3d_preprocessed/colmap");
  const trainer::DycheckScene original = trainer::read_data_scene(som.string());
  REQUIRE(original.frames() == refined.frames());
  for (std::size_t t = 0; t < refined.train_cameras.size(); ++t) {
    const trainer::Camera &p = original.train_cameras[t], &q = refined.train_cameras[t];
    CHECK((p.world_to_camera - q.world_to_camera).cwiseAbs().maxCoeff() < 1e-12);
    CHECK(std::abs(p.fx - q.fx) + std::abs(p.fy - q.fy) + std::abs(p.cx - q.cx) + std::abs(p.cy - q.cy) < 1e-12);
  }
  CHECK(original.depth == refined.depth);
  equivalence_compare(cfg, a, ref, trainer::read_data_scene(mosca.string(), &lm), "mosca");
  CHECK(lm == trainer::DataLayout::mosca);
  for (const fs::path& p : {dy, som, mosca}) fs::remove_all(p);
}

#ifdef SMG_TRAINER_PATH
namespace {

const float kNoDep = 1.0f;  // the one value of an .npz whose array is not named dep

smg::test::ProgramRun layout_cli_run(const std::string& args) {
  return smg::test::run_program(SMG_TRAINER_PATH, args, "smg_test_layout_cli_io");
}

// smg_trainer --export-dycheck SCENE --export-layout LAYOUT (8 frames at 48 x 36, 300 tracks)
// writes `files`; --data SCENE names `detected` in its layout line and trains a short run into OUT.
void layout_cli_round_trip(const fs::path& scene, const fs::path& out, const std::string& layout,
                           const std::vector<std::string>& files, const std::string& detected) {
  for (const fs::path& p : {scene, out}) fs::remove_all(p);
  smg::test::ProgramRun r = layout_cli_run("--export-dycheck " + scene.string() + " --export-layout " + layout +
                                           " --frames 8 --width 48 --height 36 --tracks 300 --threads 2 --quiet");
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  for (const std::string& f : files) {
    CAPTURE(f);
    CHECK(fs::exists(scene / f));
  }
  r = layout_cli_run("--data " + scene.string() + " --quick --stage1-iters 30 --stage2-iters 20 --threads 2 --out " + out.string());
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  CHECK(r.err.find("layout: " + detected) != std::string::npos);
  CHECK(fs::exists(out / "metrics.json"));
  CHECK(fs::exists(out / "renders/1_00000.png"));
}

}  // namespace

TEST_CASE("smg_trainer --export-layout som, --data on it; the SoM layout's refusals: exit 2, one line, no OUT") {
  const fs::path scene = fs::temp_directory_path() / "smg_test_layout_cli_som";
  const fs::path out = fs::temp_directory_path() / "smg_test_layout_cli_out";
  const std::string pre = "flow3d_preprocessed/";
  layout_cli_round_trip(scene, out, "som",
                        {"splits/train.json", "camera/0_00000.json", "rgb/1x/0_00007.png", "extra.json",
                         pre + "aligned_depth_anything_lidar/1x/0_00007.npy", pre + "track_anything/1x/0_00000.png",
                         pre + "covisible/1x/val/1_00000.png", pre + "2d_tracks/1x/0_00003_0_00005.npy",
                         pre + "colmap/sparse/cameras.bin", pre + "colmap/sparse/images.bin", pre + "colmap/scale.npy",
                         pre + "aligned_depth_anything_colmap/1x/0_00007.npy"},
                        "Shape-of-Motion");
  auto run = layout_cli_run;
  const fs::path bad_out = fs::temp_directory_path() / "smg_test_layout_cli_bad_out";
  fs::remove_all(bad_out);
  // The export has SoM's refined cameras (read) beside the original ones.
  const std::string images = smg::test::slurp(scene / (pre + "colmap/sparse/images.bin"));
  smg::test::write_bytes(scene / (pre + "colmap/sparse/images.bin"), "xx");
  smg::test::write_bytes(scene / (pre + "2d_tracks/1x/0_00001_0_00002.npy"), "not a numpy file");
  const struct {
    std::string args, message;
  } cases[] = {
      {"--data " + scene.string(), pre + "colmap/sparse/images.bin: truncated at byte 0 (reading the image count)"},
      {"--export-layout som", "--export-layout needs --export-dycheck"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.args);
    smg::test::check_refused(run(c.args + " --out " + bad_out.string()), c.message, bad_out);
  }
  smg::test::write_bytes(scene / (pre + "colmap/sparse/images.bin"), images);
  smg::test::check_refused(run("--data " + scene.string() + " --out " + bad_out.string()),
                           pre + "2d_tracks/1x/0_00001_0_00002.npy: ", bad_out);
  fs::remove_all(scene);
  fs::remove_all(out);
}

TEST_CASE("smg_trainer --export-layout mosca, --data on it; the MoSca layout's refusals: exit 2, one line, no OUT") {
  const fs::path scene = fs::temp_directory_path() / "smg_test_layout_cli_mosca";
  const fs::path out = fs::temp_directory_path() / "smg_test_layout_cli_mosca_out";
  layout_cli_round_trip(scene, out, "mosca",
                        {"images/0_00007.png", "cameras/0_00000.json", "sensor_depth/0_00003.npz", "epi/error/0_00002.png.npy",
                         "test_images/1_00000.png", "test_cameras/1_00000.json", "test_covisible/1_00000.png",
                         "uniform_dep=sensor_bootstapir_tap.npz"},
                        "MoSca");
  auto run = layout_cli_run;
  const fs::path bad_out = fs::temp_directory_path() / "smg_test_layout_cli_mosca_bad_out";
  fs::remove_all(bad_out);
  fs::remove(scene / "test_cameras/1_00000.json");
  smg::test::check_refused(run("--data " + scene.string() + " --out " + bad_out.string()), "test_cameras/1_00000.json: ", bad_out);
  smg::test::write_bytes(scene / "sensor_depth/0_00005.npz", trainer::files::npz_bytes({{"depth", npy::to_bytes(&kNoDep, {1})}}));
  smg::test::check_refused(run("--data " + scene.string() + " --out " + bad_out.string()),
                           "sensor_depth/0_00005.npz: no array `dep`", bad_out);
  for (const fs::path& p : {scene, out}) fs::remove_all(p);
}
#endif
