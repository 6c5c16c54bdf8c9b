// Tests of examples/trainer/layout_mosca.cpp on files others wrote: the MoSca fixture
// tests/data/mosca_small (made by make_fixture.py there with numpy's savez_compressed, following
// MoSca's Saved2D) read with every conversion checked against the values the script wrote; one
// broken file at a time, each an error naming that file.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <unistd.h>  // dup, dup2: the stderr of one read

#include "npy.hpp"
#include "support/files.hpp"
#include "trainer/file_formats.hpp"
#include "layout_fixture.hpp"
#include "trainer/layouts.hpp"

namespace fs = std::filesystem;

using trainer::test::layout_read_error;

// A fresh copy of tests/data/mosca_small, to break one file of.
static fs::path mosca_copy(const std::string& name) { return trainer::test::layout_fixture_copy("mosca_small", name); }

TEST_CASE("read_mosca: the numpy-written MoSca fixture, every conversion") {
  const fs::path fixture = fs::path(SMG_TEST_DATA_DIR) / "mosca_small";
  CHECK(trainer::detect_data_layout(fixture.string()) == trainer::DataLayout::mosca);
  const trainer::DycheckScene s = trainer::read_mosca(fixture.string());
  REQUIRE(s.train.size() == 3);
  CHECK(s.train[2].name == "0_00002");
  CHECK(s.train[2].time == 2);
  CHECK(s.width == 16);
  CHECK(s.height == 12);
  // Cameras: the JSON is at twice the images' size (halved, MoSca's ratios); its integer-centred
  // principal point (15.5, 11.5) / 2 + 0.5.
  for (const trainer::Camera& c : s.train_cameras) {
    CHECK((c.width == 16 && c.height == 12));
    CHECK((c.fx == 20.0 && c.fy == 20.0));  // 40 / 2
    CHECK((c.cx == 8.25 && c.cy == 6.25));
  }
  CHECK(s.train_rgb[0].pixels[0] == doctest::Approx(40.0 / 255.0));
  REQUIRE(s.val.size() == 1);
  CHECK(s.val[0].camera == 1);
  CHECK(s.val[0].time == 1);
  CHECK(s.val_cameras[0].center().x() == doctest::Approx(0.1));
  CHECK(s.val_covisible[0][11] == 1);  // 7 > 0
  CHECK(s.val_covisible[0][12] == 0);
  // Depth: 1 m on the square, 2 m elsewhere; 0 and 5000 m (beyond the 1000 m clip) invalid.
  const std::size_t HW = 16 * 12;
  for (std::size_t t = 0; t < 3; ++t) {
    CAPTURE(t);
    CHECK(s.depth[t * HW + 0] == 0.0f);
    CHECK(s.depth[t * HW + 1] == 0.0f);
    CHECK(s.depth[t * HW + 2] == 2.0f);
    CHECK(s.depth[t * HW + 5 * 16 + 4 + t] == 1.0f);
    // Dynamic mask: epipolar error 0.01 > 0.001 on the square, 0.0005 elsewhere.
    CHECK(s.has_mask[t] == 1);
    CHECK(s.dynamic_mask[t * HW + 5 * 16 + 4 + t] == 1);
    CHECK(s.dynamic_mask[t * HW + 5 * 16 + 3 + t] == 0);
  }
  // Tracks: dynamic_dep (2) then uniform_dep (18), by file name; x, y + 0.5.
  const trainer::DycheckTracks& tr = s.tracks;
  REQUIRE(tr.count == 20);
  REQUIRE(tr.frames == 3);
  auto at = [](std::size_t t, std::size_t k) { return t * 20 + k; };
  CHECK(tr.query_t[0] == 1);  // no queries array: the first visible frame
  CHECK(tr.query_t[1] == 0);
  CHECK(tr.query_t[2] == 0);  // queries[:, 0]
  CHECK(tr.visible[at(0, 0)] == 0);
  CHECK(tr.uv[2 * at(0, 0)] == 5.75f);
  CHECK(tr.uv[2 * at(0, 0) + 1] == 5.25f);
  CHECK(tr.uv[2 * at(2, 2)] == 6.5f);   // the square's (4, 4), 2 px right at t = 2
  CHECK(tr.uv[2 * at(2, 2) + 1] == 4.5f);
  CHECK(tr.visible[at(2, 2)] == 1);
  CHECK(tr.visible[at(2, 18)] == 0);     // (0, 0): invisible in the file at t = 2
  CHECK(tr.visible[at(1, 18)] == 1);
  CHECK(tr.visible[at(1, 19)] == 0);     // x = 16.2: outside the image, cleared
  CHECK(tr.visible[at(2, 19)] == 1);
  // vos_deva instance ids 5 and 257 -> channels 0 and 1, full-resolution grid.
  REQUIRE(s.feature_dim == 2);
  CHECK(s.feature_width == 16);
  CHECK(s.feature_height == 12);
  CHECK(s.has_features == std::vector<std::uint8_t>{1, 1, 1});
  const std::size_t per = HW * 2;
  CHECK(s.features[0 * per + (4 * 16 + 4) * 2 + 1] == 1.0f);
  CHECK(s.features[0 * per + (4 * 16 + 4) * 2 + 0] == 0.0f);
  CHECK(s.features[2 * per + (10 * 16 + 0) * 2 + 0] == 1.0f);
  CHECK(s.features[2 * per + (0 * 16 + 0) * 2 + 0] == 0.0f);
  CHECK(s.features[2 * per + (0 * 16 + 0) * 2 + 1] == 0.0f);
}

TEST_CASE("read_mosca: without epi/error every pixel is dynamic; without vos_deva no features") {
  const fs::path d = mosca_copy("no_epi");
  fs::remove_all(d / "epi");
  fs::remove_all(d / "vos_deva");
  const trainer::DycheckScene s = trainer::read_data_scene(d.string());
  CHECK(s.dynamic_mask == std::vector<std::uint8_t>(3 * 16 * 12, 1));
  CHECK(s.feature_dim == 0);
  fs::remove_all(d);
}

TEST_CASE("read_mosca: one broken file at a time names that file") {
  const std::string dep = "sensor_depth/0_00001.npz", uni = "uniform_dep=sensor_bootstapir_tap.npz";
  SUBCASE("an npz without dep") {
    const fs::path d = mosca_copy("no_dep");
    std::vector<float> v(16 * 12, 1.0f);
    smg::test::write_bytes(d / dep, trainer::files::npz_bytes({{"depth", npy::to_bytes(v.data(), {12, 16})}}));
    CHECK(layout_read_error(d) == dep + ": no array `dep` (MoSca's sensor depth key)");
  }
  // A track file: tracks [frames, n, 2] (ones), visibility [vis_frames, vis_n] (false).
  auto track_file = [](std::int64_t frames, std::int64_t n, std::int64_t vis_frames, std::int64_t vis_n) {
    const std::vector<float> xy(static_cast<std::size_t>(frames * n * 2), 1.0f);
    const std::unique_ptr<bool[]> vis(new bool[static_cast<std::size_t>(vis_frames * vis_n)]());
    return trainer::files::npz_bytes({{"tracks", npy::to_bytes(xy.data(), {frames, n, 2})},
                                      {"visibility", npy::to_bytes(vis.get(), {vis_frames, vis_n})}});
  };
  SUBCASE("tracks and visibility of different shapes") {
    const fs::path d = mosca_copy("track_shape");
    smg::test::write_bytes(d / uni, track_file(3, 18, 3, 17));
    CHECK(layout_read_error(d) == uni + ": visibility has shape [3, 17], expected [3, 18] (that of tracks)");
  }
  SUBCASE("tracks over another number of frames") {
    const fs::path d = mosca_copy("track_frames");
    smg::test::write_bytes(d / uni, track_file(2, 18, 2, 18));
    CHECK(layout_read_error(d) == uni + ": tracks has shape [2, 18, 2], expected [3, N, 2] (3 frames in images/)");
  }
  SUBCASE("a missing camera JSON, depth, test camera, covisible mask") {
    trainer::test::check_missing_files("mosca_small", {"cameras/0_00002.json", "sensor_depth/0_00000.npz", "test_cameras/1_00001.json",
                                                       "test_covisible/1_00001.png"});
  }
  // MoSca reads sorted(glob("epi/error/*.npy")) and stacks them (epi_analysis.py, load_epi_error):
  // one map per image, by position; the count and the names are checked.
  SUBCASE("epipolar error maps: one missing, one too many, one named after another image") {
    const fs::path d = mosca_copy("epi_count");
    fs::remove(d / "epi/error/0_00001.png.npy");
    CHECK(layout_read_error(d) ==
          "epi/error: 2 epipolar error maps (*.npy) for 3 images in images/ (MoSca writes one per image, named <image file name>.npy)");
    fs::copy_file(d / "epi/error/0_00000.png.npy", d / "epi/error/0_00001.png.npy");
    fs::copy_file(d / "epi/error/0_00000.png.npy", d / "epi/error/0_00003.png.npy");
    CHECK(layout_read_error(d) ==
          "epi/error: 4 epipolar error maps (*.npy) for 3 images in images/ (MoSca writes one per image, named <image file name>.npy)");
    fs::remove(d / "epi/error/0_00002.png.npy");
    CHECK(layout_read_error(d) == "epi/error/0_00003.png.npy: sorted as the map of images/0_00002.png, expected 0_00002.png.npy "
                                  "(MoSca's name) or 0_00002.npy");
  }
  SUBCASE("epipolar error maps named <stem>.npy (an older export) are read in the same order") {
    const fs::path d = mosca_copy("epi_stem");
    const trainer::DycheckScene before = trainer::read_mosca(d.string());
    for (int t = 0; t < 3; ++t) {
      const std::string n = "epi/error/0_0000" + std::to_string(t);
      fs::rename(d / (n + ".png.npy"), d / (n + ".npy"));
    }
    const trainer::DycheckScene after = trainer::read_mosca(d.string());
    CHECK(after.dynamic_mask == before.dynamic_mask);
    CHECK(std::count(before.dynamic_mask.begin(), before.dynamic_mask.end(), 1) > 0);
    CHECK(std::count(before.dynamic_mask.begin(), before.dynamic_mask.end(), 0) > 0);
  }
  SUBCASE("an image neither the camera's size nor half of it") {
    const fs::path d = mosca_copy("image_size");
    fs::copy_file(d / "vos_deva/Annotations/0_00000.png", d / "images/0_00001.png", fs::copy_options::overwrite_existing);
    smg::test::write_bytes(d / "cameras/0_00001.json", "{\"orientation\": [[1,0,0],[0,1,0],[0,0,1]], \"position\": [0,0,0], "
                                                       "\"focal_length\": 40, \"principal_point\": [15.5, 11.5], \"skew\": 0, "
                                                       "\"pixel_aspect_ratio\": 1, \"radial_distortion\": [0, 0, 0], "
                                                       "\"tangential_distortion\": [0, 0], \"image_size\": [20, 20]}");
    CHECK(layout_read_error(d) == "images/0_00001.png: image is 16x12, but cameras/0_00001.json says 20x20 (nor half of it)");
  }
  SUBCASE("one file replaced or added: a second image of a frame, dep or an epipolar error map of the wrong shape") {
    const std::vector<float> v(16, 0.0f);
    const struct {
      std::string rel, bytes, message;
    } cases[] = {
        {"images/0_00001.jpg", "jpeg", "images/0_00001.jpg: two images of frame 0_00001 (0_00001.png too)"},
        {dep, trainer::files::npz_bytes({{"dep", npy::to_bytes(v.data(), {2, 8})}}), dep + ": dep has shape [2, 8], expected [12, 16]"},
        {"epi/error/0_00000.png.npy", npy::to_bytes(v.data(), {16}), "epi/error/0_00000.png.npy: shape [16], expected [12, 16]"},
    };
    for (const auto& c : cases) {
      CAPTURE(c.rel);
      const fs::path d = mosca_copy("replaced");
      smg::test::write_bytes(d / c.rel, c.bytes);
      CHECK(layout_read_error(d) == c.message);
    }
  }
}

// What `f` writes to stderr (file descriptor 2, redirected to a temporary file meanwhile).
template <class F>
static std::string mosca_stderr_of(F&& f) {
  std::FILE* tmp = std::tmpfile();
  REQUIRE(tmp != nullptr);
  std::fflush(stderr);
  const int saved = ::dup(2);
  REQUIRE(saved >= 0);
  REQUIRE(::dup2(::fileno(tmp), 2) == 2);
  struct Restore {
    int fd;
    ~Restore() {
      std::fflush(stderr);
      ::dup2(fd, 2);
      ::close(fd);
    }
  };
  {
    const Restore restore{saved};
    f();
  }
  std::rewind(tmp);
  std::string got;
  for (int ch; (ch = std::fgetc(tmp)) != EOF;) got += static_cast<char>(ch);
  std::fclose(tmp);
  return got;
}

// The three training images as JPEG files written by libjpeg-turbo's cjpeg (tests/data/mosca_jpeg,
// made by its make_fixture.py), in place of mosca_small's PNGs.
TEST_CASE("read_mosca: JPEG images written by libjpeg's cjpeg decode as djpeg decodes them") {
  const fs::path d = mosca_copy("jpeg");
  const fs::path overlay = fs::path(SMG_TEST_DATA_DIR) / "mosca_jpeg";
  const trainer::DycheckScene png = trainer::read_mosca(d.string());
  for (int t = 0; t < 3; ++t) {
    const std::string n = "0_0000" + std::to_string(t);
    fs::remove(d / ("images/" + n + ".png"));
    // MoSca names each epipolar error map after its image file: now the JPEG's.
    fs::rename(d / ("epi/error/" + n + ".png.npy"), d / ("epi/error/" + n + ".jpg.npy"));
  }
  fs::copy(overlay / "images", d / "images", fs::copy_options::recursive | fs::copy_options::overwrite_existing);
  const trainer::DycheckScene s = trainer::read_mosca(d.string());
  REQUIRE(s.train.size() == 3);
  CHECK(s.train[1].name == "0_00001");
  for (std::size_t t = 0; t < 3; ++t) {
    CAPTURE(t);
    // djpeg's P6 file: "P6\n16 12\n255\n" and 16 x 12 x 3 bytes.
    const std::string ppm = smg::test::slurp(overlay / ("reference/0_0000" + std::to_string(t) + ".ppm"));
    const std::string head = "P6\n16 12\n255\n";
    REQUIRE(ppm.size() == head.size() + 16 * 12 * 3);
    REQUIRE(ppm.compare(0, head.size(), head) == 0);
    const trainer::Image& im = s.train_rgb[t];
    REQUIRE(im.pixels.size() == 16 * 12 * 3);
    double to_djpeg = 0, to_original = 0;
    for (std::size_t k = 0; k < im.pixels.size(); ++k) {
      const double v = std::round(255.0 * im.pixels[k]);  // back to the decoded 8-bit level
      to_djpeg = std::max(to_djpeg, std::abs(v - static_cast<unsigned char>(ppm[head.size() + k])));
      to_original = std::max(to_original, std::abs(v - std::round(255.0 * png.train_rgb[t].pixels[k])));
    }
    // libjpeg-turbo's integer IDCT, as djpeg -dct int: the same pixels; against the lossless
    // original, the encoder's loss at quality 95 on the square's sharp edges.
    MESSAGE("frame " << t << ": max |decoded - djpeg| " << to_djpeg << " levels, max |decoded - original PNG| " << to_original);
    CHECK(to_djpeg == 0.0);
    CHECK(to_original <= 24.0);
    CHECK(to_original > 0.0);  // lossy: these are the JPEG's pixels, not the PNG's
  }
  SUBCASE("a .jpg that is not a JPEG") {
    smg::test::write_bytes(d / "images/0_00002.jpg", smg::test::slurp(fs::path(SMG_TEST_DATA_DIR) / "mosca_small/images/0_00002.png"));
    CHECK(layout_read_error(d) == "images/0_00002.jpg: not a JPEG image (no JPEG start-of-image marker)");
  }
  SUBCASE("a truncated JPEG") {
    const std::string b = smg::test::slurp(overlay / "images/0_00000.jpg");
    smg::test::write_bytes(d / "images/0_00000.jpg", b.substr(0, 40));
    CHECK(layout_read_error(d).rfind("images/0_00000.jpg: ", 0) == 0);
  }
  SUBCASE("a stray byte before the DQT marker (issue 47): read, the same pixels, one note on stderr naming the file") {
    std::string b = smg::test::slurp(overlay / "images/0_00001.jpg");
    const std::size_t dqt = b.find("\xff\xdb");
    REQUIRE(dqt != std::string::npos);
    b.insert(dqt, 1, '\0');
    smg::test::write_bytes(d / "images/0_00001.jpg", b);
    trainer::DycheckScene stray;
    const std::string err = mosca_stderr_of([&] { stray = trainer::read_mosca(d.string()); });
    CHECK(err == "[data] images/0_00001.jpg: libjpeg warning: Corrupt JPEG data: 1 extraneous bytes before marker 0xdb (read anyway)\n");
    REQUIRE(stray.train_rgb.size() == 3);
    for (std::size_t t = 0; t < 3; ++t) CHECK(stray.train_rgb[t].pixels == s.train_rgb[t].pixels);
  }
}
