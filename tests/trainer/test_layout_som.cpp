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
#include "trainer/layouts.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kSomFixture = fs::path(SMG_TEST_DATA_DIR) / "som_small";

fs::path som_copy(const std::string& name) { return trainer::test::layout_fixture_copy("som_small", name); }
std::string som_error(const fs::path& dir) { return trainer::test::layout_read_error(dir); }

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
  SUBCASE("COLMAP cameras only") {
    const fs::path d = som_copy("colmap");
    fs::remove_all(d / "camera");
    fs::create_directories(d / (pre + "colmap/sparse"));
    CHECK(som_error(d) == "camera/0_00000.json: missing; COLMAP cameras (flow3d_preprocessed/colmap/sparse) are not "
                          "supported, the Nerfies camera/ JSON files are needed");
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
    CHECK(som_error(d) == pre + "aligned_depth_anything_colmap: in COLMAP's scale, which needs COLMAP cameras (not "
                                "supported); add aligned_depth_anything_lidar/1x or depth/1x");
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
  CHECK(som_error(d) == "images: no PNG images");  // read as MoSca (tests/trainer/test_layout_mosca.cpp)
  fs::remove_all(d);
}
