// Tests of examples/trainer/layouts.hpp on files others wrote: the Shape-of-Motion fixture
// tests/data/som_small (made by make_fixture.py there with numpy and zlib, following SoM's loader)
// read with every conversion checked against the values the script wrote; one broken file at a
// time, each an error naming that file; the layout detection.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "npy.hpp"
#include "support/files.hpp"
#include "layout_fixture.hpp"
#include "trainer/colmap_model.hpp"
#include "trainer/layouts.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kSomFixture = fs::path(SMG_TEST_DATA_DIR) / "som_small";

fs::path som_copy(const std::string& name) { return trainer::test::layout_fixture_copy("som_small", name); }
std::string som_error(const fs::path& dir) { return trainer::test::layout_read_error(dir); }

// tests/data/som_colmap (written by som_small/make_fixture.py) copied over a copy of som_small:
// the scene with SoM's default refined COLMAP cameras and the depth aligned to them.
void overlay_colmap(const fs::path& d) {
  fs::copy(fs::path(SMG_TEST_DATA_DIR) / "som_colmap", d, fs::copy_options::recursive | fs::copy_options::overwrite_existing);
}

}  // namespace

TEST_CASE("read_som: the numpy-written Shape-of-Motion fixture, every conversion") {
  trainer::DataLayout layout = trainer::DataLayout::dycheck;
  const trainer::DycheckScene s = trainer::read_data_scene(kSomFixture.string(), &layout);
  CHECK(layout == trainer::DataLayout::som);
  REQUIRE(s.frames() == 3);
  CHECK(s.width == 16);
  CHECK(s.height == 12);
  // Cameras at 1x; SoM's integer-centred principal point (7.5, 5.5) + 0.5.
  for (const trainer::Camera& c : s.train_cameras) {
    CHECK(c.fx == 20.0);
    CHECK(c.fy == 20.0);
    CHECK(c.cx == 8.0);
    CHECK(c.cy == 6.0);
  }
  REQUIRE(s.val.size() == 1);
  CHECK(s.val_cameras[0].center().x() == doctest::Approx(0.1));
  // Covisible: columns < 12.
  CHECK(s.val_covisible[0][11] == 1);
  CHECK(s.val_covisible[0][12] == 0);
  // Depth = 1 / disparity: 1 m on the square, 2 m elsewhere (frame 1's file is Fortran order).
  const std::size_t HW = 16 * 12;
  for (std::size_t t = 0; t < 3; ++t) {
    CAPTURE(t);
    CHECK(s.depth[t * HW + 5 * 16 + 5 + t] == 1.0f);  // inside the square (columns 4+t .. 7+t)
    CHECK(s.depth[t * HW + 0] == 2.0f);
    CHECK(s.dynamic_mask[t * HW + 5 * 16 + 5 + t] == 1);
    CHECK(s.dynamic_mask[t * HW + 5 * 16 + 3 + t] == 0);
  }
  // Tracks: 18 per query frame, grouped by query frame; x, y + 0.5.
  const trainer::DycheckTracks& tr = s.tracks;
  REQUIRE(tr.count == 54);
  CHECK(tr.query_t[0] == 0);
  CHECK(tr.query_t[18] == 1);
  CHECK(tr.query_t[53] == 2);
  auto uv = [&](int t, int q, int c) { return tr.uv[(static_cast<std::size_t>(t) * 54 + static_cast<std::size_t>(q)) * 2 + static_cast<std::size_t>(c)]; };
  auto vis = [&](int t, int q) { return tr.visible[static_cast<std::size_t>(t) * 54 + static_cast<std::size_t>(q)]; };
  for (int t = 0; t < 3; ++t) {
    CAPTURE(t);
    // Track 18 (query frame 1, the square's first pixel (5, 4)) moves one column per frame.
    CHECK(uv(t, 18, 0) == doctest::Approx(5.5 + (t - 1)));
    CHECK(uv(t, 18, 1) == doctest::Approx(4.5));
    // parse_tapir_track_info: uncertain (dist logit +5) and occluded (occ logit +5) samples off
    // the query frame are not visible; logits (-5, -5) are.
    CHECK(vis(t, 18) == (t == 1 ? 1 : 0));
    CHECK(vis(t, 35) == (t == 1 ? 1 : 0));
    CHECK(vis(t, 34) == 1);
    CHECK(vis(t, 19) == 1);
  }
  CHECK(uv(0, 35, 0) == doctest::Approx(15.5));
  CHECK(s.feature_dim == 0);  // no priors/features: a geometric graph
}

TEST_CASE("read_som: at most max_tracks tracks, spread over the query frames and their rows") {
  trainer::DycheckReadOptions options;
  options.max_tracks = 7;  // 3 + 2 + 2 of 18 per frame: rows 0, 6, 12 | 0, 9 | 0, 9
  const trainer::DycheckScene s = trainer::read_som(kSomFixture.string(), options);
  const trainer::DycheckTracks& tr = s.tracks;
  REQUIRE(tr.count == 7);
  CHECK(tr.query_t == std::vector<std::int32_t>{0, 0, 0, 1, 1, 2, 2});
  auto uv = [&](int t, int q, int c) { return tr.uv[(static_cast<std::size_t>(t) * 7 + static_cast<std::size_t>(q)) * 2 + static_cast<std::size_t>(c)]; };
  CHECK(uv(0, 3, 0) == doctest::Approx(4.5));  // frame 1's row 0, (5, 4), one column back at t = 0
  CHECK(uv(2, 1, 0) == doctest::Approx(8.5));  // frame 0's row 6, (6, 5), two columns on at t = 2
  CHECK(uv(2, 1, 1) == doctest::Approx(5.5));
  CHECK(uv(1, 6, 0) == doctest::Approx(6.5));  // frame 2's row 9, (7, 6), one column back at t = 1
  CHECK(uv(1, 6, 1) == doctest::Approx(6.5));
}

TEST_CASE("read_som: one broken file at a time names that file") {
  const std::string pre = "flow3d_preprocessed/";
  SUBCASE("a track file with 3 columns") {
    const fs::path d = som_copy("track_shape");
    std::vector<float> v(18 * 3, 0.0f);
    smg::test::write_bytes(d / (pre + "2d_tracks/1x/0_00000_0_00001.npy"), npy::to_bytes(v.data(), {18, 3}));
    CHECK(som_error(d) == pre + "2d_tracks/1x/0_00000_0_00001.npy: shape [18, 3], expected [18, 4] (the rows of " + pre +
                              "2d_tracks/1x/0_00000_0_00000.npy)");
  }
  SUBCASE("a NaN in a track file") {
    const fs::path d = som_copy("track_nan");
    std::vector<float> v(18 * 4, 1.0f);
    v[4 * 2 + 1] = std::nanf("");
    smg::test::write_bytes(d / (pre + "2d_tracks/1x/0_00002_0_00001.npy"), npy::to_bytes(v.data(), {18, 4}));
    CHECK(som_error(d) == pre + "2d_tracks/1x/0_00002_0_00001.npy: row 2 column 1 is not finite");
  }
  SUBCASE("a missing track file, camera JSON, mask") {
    trainer::test::check_missing_files("som_small", {pre + "2d_tracks/1x/0_00001_0_00002.npy", "camera/0_00002.json",
                                                     pre + "track_anything/1x/0_00001.png"});
  }
  SUBCASE("COLMAP cameras without the depth aligned to them, and no camera/ JSON") {
    const fs::path d = som_copy("colmap");
    fs::remove_all(d / "camera");
    overlay_colmap(d);
    fs::remove_all(d / (pre + "aligned_depth_anything_colmap"));
    CHECK(som_error(d) == "camera/0_00000.json: missing; the COLMAP cameras (flow3d_preprocessed/colmap/sparse) go with "
                          "the depth aligned to them, flow3d_preprocessed/aligned_depth_anything_colmap/1x/, which is "
                          "missing too");
  }
  SUBCASE("a disparity file of the wrong size") {
    const fs::path d = som_copy("disparity_size");
    std::vector<float> v(12 * 15, 1.0f);
    smg::test::write_bytes(d / (pre + "aligned_depth_anything_lidar/1x/0_00001.npy"), npy::to_bytes(v.data(), {12, 15}));
    CHECK(som_error(d) == pre + "aligned_depth_anything_lidar/1x/0_00001.npy: shape [12, 15], expected [12, 16] (the 1x image size)");
  }
  SUBCASE("no depth at all; COLMAP-scaled depth only") {
    const fs::path d = som_copy("depth_colmap");
    fs::rename(d / (pre + "aligned_depth_anything_lidar"), d / (pre + "aligned_depth_anything_colmap"));
    CHECK(som_error(d) == pre + "aligned_depth_anything_colmap: in COLMAP's scale, which needs the COLMAP cameras "
                                "(flow3d_preprocessed/colmap/sparse/cameras.bin, missing); add them, or "
                                "aligned_depth_anything_lidar/1x or depth/1x");
  }
  SUBCASE("a validation camera JSON without orientation") {
    const fs::path d = som_copy("val_camera");
    smg::test::write_bytes(d / "camera/1_00001.json", "{}");
    CHECK(som_error(d) == "camera/1_00001.json: missing key 'orientation'");
  }
  SUBCASE("an RGB mask") {
    const fs::path d = som_copy("mask_rgb");
    fs::copy_file(d / "rgb/1x/0_00000.png", d / (pre + "track_anything/1x/0_00002.png"), fs::copy_options::overwrite_existing);
    CHECK(som_error(d) == pre + "track_anything/1x/0_00002.png: expected a one-channel mask, found 4 channels");
  }
}

TEST_CASE("detect_data_layout: by the folder's contents; ambiguous or unknown folders are refused") {
  const fs::path d = fs::temp_directory_path() / "smg_test_layout_detect";
  fs::remove_all(d);
  CHECK(som_error(d) == d.string() + ": not a folder");
  fs::create_directories(d / "other");
  CHECK(som_error(d) == d.string() + ": not a scene folder: looked for flow3d_preprocessed/ (Shape-of-Motion), "
                                     "sensor_depth/ + cameras/ + *bootstapir*.npz (MoSca), and priors/, splits/ or "
                                     "camera/ (Dycheck + priors)");
  fs::create_directories(d / "splits");
  CHECK(trainer::detect_data_layout(d.string()) == trainer::DataLayout::dycheck);
  fs::create_directories(d / "flow3d_preprocessed");
  CHECK(trainer::detect_data_layout(d.string()) == trainer::DataLayout::som);
  fs::create_directories(d / "priors");
  smg::test::write_bytes(d / "priors/tracks.npz", "x");
  CHECK(som_error(d) == d.string() + ": ambiguous scene folder: it holds priors/tracks.npz (Dycheck + priors) and "
                                     "flow3d_preprocessed/ (Shape-of-Motion)");
  fs::remove_all(d / "priors");
  fs::create_directories(d / "sensor_depth");
  fs::create_directories(d / "cameras");
  smg::test::write_bytes(d / "uniform_dep=sensor_bootstapir_tap.npz", "x");
  CHECK(som_error(d) == d.string() + ": ambiguous scene folder: it holds both flow3d_preprocessed/ (Shape-of-Motion) "
                                     "and sensor_depth/ + cameras/ + *bootstapir*.npz (MoSca)");
  fs::remove_all(d / "flow3d_preprocessed");
  CHECK(trainer::detect_data_layout(d.string()) == trainer::DataLayout::mosca);
  CHECK(som_error(d) == "images: no images (*.png, *.jpg, *.jpeg)");  // read as MoSca (tests/trainer/test_layout_mosca.cpp)
  fs::remove_all(d);
}

TEST_CASE("read_som: SoM's default, refined COLMAP cameras and COLMAP-aligned depth (numpy/struct-written overlay)") {
  const std::string pre = "flow3d_preprocessed/";
  const fs::path d = som_copy("refined");
  overlay_colmap(d);
  trainer::DataLayout layout = trainer::DataLayout::dycheck;
  const trainer::DycheckScene s = trainer::read_data_scene(d.string(), &layout);
  CHECK(layout == trainer::DataLayout::som);
  REQUIRE(s.frames() == 3);
  CHECK(s.width == 16);
  CHECK(s.height == 12);
  // The refined cameras, not camera/<frame>.json (f 20, identity): SIMPLE_RADIAL f 22, (7, 5)
  // + 0.5, distortion ignored; Ry(10 deg); translation (0.2, -0.1, 0.05) units x 0.5 m per unit.
  const Eigen::Matrix3d ry = Eigen::AngleAxisd(10.0 * EIGEN_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  for (const trainer::Camera& c : s.train_cameras) {
    CHECK(c.fx == 22.0);
    CHECK(c.fy == 22.0);
    CHECK(c.cx == 7.5);
    CHECK(c.cy == 5.5);
    CHECK(c.width == 16);
    CHECK((c.rotation() - ry).cwiseAbs().maxCoeff() < 1e-15);
    CHECK((c.translation() - Eigen::Vector3d(0.1, -0.05, 0.025)).cwiseAbs().maxCoeff() < 1e-15);
  }
  // The validation frame's PINHOLE camera 2, found by name among images listed out of order.
  REQUIRE(s.val_cameras.size() == 1);
  const trainer::Camera& v = s.val_cameras[0];
  CHECK(v.fx == 21.0);
  CHECK(v.fy == 19.0);
  CHECK(v.cx == 7.75);
  CHECK(v.cy == 6.25);
  CHECK(v.rotation().isIdentity(0.0));
  CHECK(v.translation().isZero(0.0));
  // Depth: 1 / (COLMAP disparity 0.5 / depth) in units, x 0.5: the metric 1 m / 2 m again.
  const std::size_t HW = 16 * 12;
  for (std::size_t t = 0; t < 3; ++t) {
    CAPTURE(t);
    CHECK(s.depth[t * HW + 5 * 16 + 5 + t] == 1.0f);
    CHECK(s.depth[t * HW + 0] == 2.0f);
  }
  SUBCASE("without scale.npy: COLMAP's own units") {
    fs::remove(d / (pre + "colmap/scale.npy"));
    const trainer::DycheckScene u = trainer::read_data_scene(d.string());
    CHECK((u.train_cameras[1].translation() - Eigen::Vector3d(0.2, -0.1, 0.05)).cwiseAbs().maxCoeff() < 1e-15);
    CHECK(u.depth[0] == 4.0f);
  }
  SUBCASE("without the aligned depth: the original cameras and the lidar-aligned depth") {
    fs::remove_all(d / (pre + "aligned_depth_anything_colmap"));
    const trainer::DycheckScene o = trainer::read_data_scene(d.string());
    CHECK(o.train_cameras[0].fx == 20.0);
    CHECK(o.train_cameras[0].rotation().isIdentity(0.0));
  }
}

TEST_CASE("read_som: broken COLMAP files, each named with its problem") {
  namespace colmap = trainer::colmap;
  const std::string sparse = "flow3d_preprocessed/colmap/sparse/";
  const auto refined = [](const std::string& name) {
    const fs::path d = som_copy("colmap_" + name);
    overlay_colmap(d);
    return d;
  };
  const std::vector<colmap::CameraRecord> cams = {{1, 1, 16, 12, {20.0, 20.0, 7.5, 5.5}}};
  const auto image = [](int id, const std::string& name, int camera, double qw = 1.0) {
    colmap::ImageRecord im;
    im.id = id;
    im.name = name;
    im.camera_id = camera;
    im.qvec[0] = qw;
    return im;
  };
  const std::vector<colmap::ImageRecord> all = {image(1, "0_00000.png", 1), image(2, "0_00001.png", 1),
                                                image(3, "0_00002.png", 1), image(4, "1_00001.png", 1)};
  SUBCASE("truncated cameras.bin") {
    const fs::path d = refined("truncated");
    const std::string b = smg::test::slurp(d / (sparse + "cameras.bin"));
    REQUIRE(b.size() == 120);  // 8 + (24 + 4 x 8) x 2
    smg::test::write_bytes(d / (sparse + "cameras.bin"), b.substr(0, b.size() - 4));
    CHECK(som_error(d) == sparse + "cameras.bin: truncated at byte 112 (reading params)");
  }
  SUBCASE("bytes after the last image") {
    const fs::path d = refined("padded");
    smg::test::write_bytes(d / (sparse + "images.bin"), colmap::images_bytes(all) + "xy");
    CHECK(som_error(d) == sparse + "images.bin: 2 bytes after the last record");
  }
  SUBCASE("an unknown camera model and one SoM does not read") {
    const fs::path d = refined("model");
    smg::test::write_bytes(d / (sparse + "cameras.bin"), colmap::cameras_bytes({{1, 42, 16, 12, {}}}));
    CHECK(som_error(d) == sparse + "cameras.bin: camera 1: unknown camera model id 42");
    smg::test::write_bytes(d / (sparse + "cameras.bin"), colmap::cameras_bytes({{1, 7, 16, 12, {20, 8, 6, 0.1, 0}}}));
    CHECK(som_error(d) == sparse + "cameras.bin: camera 1: model FOV is not supported (Shape-of-Motion reads "
                                   "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE and FULL_OPENCV)");
  }
  SUBCASE("a frame of the splits missing from images.bin; an image of an unknown camera") {
    const fs::path d = refined("frames");
    smg::test::write_bytes(d / (sparse + "cameras.bin"), colmap::cameras_bytes(cams));
    smg::test::write_bytes(d / (sparse + "images.bin"), colmap::images_bytes({all[0], all[2], all[3]}));
    CHECK(som_error(d) == sparse + "images.bin: no image named '0_00001.png' (a frame of the splits)");
    smg::test::write_bytes(d / (sparse + "images.bin"), colmap::images_bytes({all[0], all[1], all[2], image(4, "1_00001.png", 5)}));
    CHECK(som_error(d) == sparse + "images.bin: image '1_00001.png': camera 5 is not in cameras.bin");
  }
  SUBCASE("a quaternion that is not a rotation") {
    const fs::path d = refined("qvec");
    smg::test::write_bytes(d / (sparse + "cameras.bin"), colmap::cameras_bytes(cams));
    smg::test::write_bytes(d / (sparse + "images.bin"), colmap::images_bytes({all[0], all[1], image(3, "0_00002.png", 1, 2.0), all[3]}));
    CHECK(som_error(d).rfind(sparse + "images.bin: image '0_00002.png': qvec is not a unit quaternion (norm 2", 0) == 0);
  }
  SUBCASE("a scale.npy of two values, or negative") {
    const fs::path d = refined("scale");
    const double two[2] = {1.0, 2.0};
    smg::test::write_bytes(d / "flow3d_preprocessed/colmap/scale.npy", npy::to_bytes(two, {2}));
    CHECK(som_error(d) == "flow3d_preprocessed/colmap/scale.npy: expected one value, found shape [2]");
    const double neg = -1.0;
    smg::test::write_bytes(d / "flow3d_preprocessed/colmap/scale.npy", npy::to_bytes(&neg, {}));
    CHECK(som_error(d) == "flow3d_preprocessed/colmap/scale.npy: the scale must be finite and > 0");
  }
  SUBCASE("images.bin missing") {
    const fs::path d = refined("missing");
    fs::remove(d / (sparse + "images.bin"));
    CHECK(som_error(d).rfind(sparse + "images.bin: ", 0) == 0);
  }
}
