// Tests of examples/trainer/dycheck.hpp: a small synthetic scene written in the Dycheck iPhone
// layout and read back unchanged, then one broken file at a time, each an error naming that file.
// Also the .npz reader on numpy's own compressed output and the ZIP/PNG helpers
// (examples/trainer/file_formats.hpp).
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "npy.hpp"
#include "support/errors.hpp"
#include "support/files.hpp"
#include "trainer/dycheck.hpp"
#include "trainer/file_formats.hpp"
#include "trainer/image_io.hpp"

using trainer::DataError;
using trainer::DycheckScene;
namespace fs = std::filesystem;
using smg::test::slurp;
using smg::test::write_bytes;

namespace {

fs::path temp_dir(const std::string& name) {
  const fs::path p = fs::temp_directory_path() / ("smg_test_dycheck_" + name);
  fs::remove_all(p);
  return p;
}
// Replaces the first occurrence of `from` in a file.
void replace_in(const fs::path& p, const std::string& from, const std::string& by) {
  std::string text = slurp(p);
  const auto at = text.find(from);
  REQUIRE(at != std::string::npos);
  write_bytes(p, text.replace(at, from.size(), by));
}
// Replaces the text after `prefix` up to the next ',' (a number in a camera file).
void replace_value(const fs::path& p, const std::string& prefix, const std::string& by) {
  std::string text = slurp(p);
  const auto at = text.find(prefix);
  REQUIRE(at != std::string::npos);
  const auto begin = at + prefix.size(), end = text.find(',', begin);
  write_bytes(p, text.replace(begin, end - begin, by));
}

trainer::Camera camera(int index, int width, int height) {
  const double a = 0.3 * index;
  trainer::Camera c = trainer::look_at(Eigen::Vector3d(3 * std::cos(a), 0.5 + 0.1 * index, 3 * std::sin(a)),
                                       Eigen::Vector3d(0.1, 0.2, -0.1), Eigen::Vector3d(0, -1, 0), width, height, 0.9);
  c.fy = c.fx * 1.01;  // a pixel aspect ratio other than 1
  c.cx = 0.5 * width + 0.25;
  c.cy = 0.5 * height - 0.75;
  return c;
}
trainer::Image rgb(int width, int height, int seed) {
  trainer::Image im(width, height, 3);
  for (std::size_t i = 0; i < im.pixels.size(); ++i)
    im.pixels[i] = static_cast<float>((i * 37 + static_cast<std::size_t>(seed) * 11) % 256) / 255.0f;
  return im;
}

// 3 training frames 8x6 at times 0, 2, 4; 2 validation frames (10x8 and 8x6); 5 tracks;
// masks on frames 0 and 2; features 3x4x5 on frames 0 and 1.
DycheckScene synthetic() {
  DycheckScene s;
  s.width = 8;
  s.height = 6;
  const int T = 3, Q = 5, HW = 48;
  for (int t = 0; t < T; ++t) {
    const int time = 2 * t;
    char name[16];
    std::snprintf(name, sizeof name, "0_%05d", time);
    s.train.push_back({name, 0, time});
    s.train_cameras.push_back(camera(t, 8, 6));
    s.train_rgb.push_back(rgb(8, 6, t));
  }
  s.depth.resize(T * HW);
  for (std::size_t i = 0; i < s.depth.size(); ++i) s.depth[i] = i % 7 == 0 ? 0.0f : 1.0f + 0.013f * static_cast<float>(i);
  s.val = {{"1_00001", 1, 1}, {"2_00003", 2, 3}};
  s.val_cameras = {camera(5, 10, 8), camera(6, 8, 6)};
  s.val_rgb = {rgb(10, 8, 5), rgb(8, 6, 6)};
  for (const auto& c : s.val_cameras) {
    std::vector<std::uint8_t> m(static_cast<std::size_t>(c.width * c.height));
    for (std::size_t i = 0; i < m.size(); ++i) m[i] = (i % 3) ? 1 : 0;
    s.val_covisible.push_back(m);
  }
  s.tracks.count = Q;
  s.tracks.frames = T;
  for (int t = 0; t < T; ++t)
    for (int q = 0; q < Q; ++q) {
      s.tracks.uv.push_back(0.5f + static_cast<float>(q) + 0.25f * static_cast<float>(t));
      s.tracks.uv.push_back(5.75f - static_cast<float>(q) * 0.5f);
      s.tracks.visible.push_back((q + t) % 2 ? 1 : 0);
    }
  s.tracks.uv[2] = -30.0f;  // t = 0, q = 1: outside but within the margin (visible)
  s.tracks.uv[4] = 500.0f;  // t = 0, q = 2: far outside, but not visible
  s.tracks.query_t = {0, 1, 2, 1, 0};
  s.dynamic_mask.assign(T * HW, 0);
  s.has_mask = {1, 0, 1};
  for (int i = 0; i < HW; ++i) {
    s.dynamic_mask[static_cast<std::size_t>(i)] = i % 4 == 0;
    s.dynamic_mask[2 * static_cast<std::size_t>(HW) + static_cast<std::size_t>(i)] = i % 5 == 1;
  }
  s.feature_height = 3;
  s.feature_width = 4;
  s.feature_dim = 5;
  s.has_features = {1, 1, 0};
  s.features.assign(T * 60, 0.0f);
  for (int i = 0; i < 120; ++i) s.features[static_cast<std::size_t>(i)] = 0.125f * static_cast<float>(i) - 3.0f;
  return s;
}

void check_camera(const trainer::Camera& a, const trainer::Camera& b) {
  CHECK(a.width == b.width);
  CHECK(a.height == b.height);
  auto close = [](double x, double y) { return std::abs(x - y) <= 1e-6 * std::max(1.0, std::abs(y)); };
  CHECK(close(a.fx, b.fx));
  CHECK(close(a.fy, b.fy));
  CHECK(close(a.cx, b.cx));
  CHECK(close(a.cy, b.cy));
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) CHECK(close(a.world_to_camera(i, j), b.world_to_camera(i, j)));
}

// A freshly written synthetic scene in its own folder.
fs::path fresh(const std::string& name) {
  const fs::path dir = temp_dir(name);
  trainer::write_dycheck(dir.string(), synthetic());
  return dir;
}
fs::path fresh(const std::string& name, const std::function<void(DycheckScene&)>& change) {
  const fs::path dir = temp_dir(name);
  DycheckScene s = synthetic();
  change(s);
  trainer::write_dycheck(dir.string(), s);
  return dir;
}
std::string read_error(const fs::path& dir, const trainer::DycheckReadOptions& o = {}) {
  return smg::test::error_message<DataError>([&] { trainer::read_dycheck(dir.string(), o); }, "no error");
}
bool starts_with(const std::string& s, const std::string& prefix) { return s.compare(0, prefix.size(), prefix) == 0; }

// One broken scene: the synthetic scene, changed by `change` before it is written (when given),
// written to the folder `name`, its files then broken by `breaks` (when given); reading it must
// fail with the message `error` (Match::prefix: a one-line message that starts with `error`).
using Dir = const fs::path&;
enum class Match { exact, prefix };
struct Broken {
  std::string name;
  std::function<void(Dir)> breaks;
  std::string error;
  Match match = Match::exact;
  std::function<void(DycheckScene&)> change = {};
};
void check_broken(const std::vector<Broken>& cases) {
  for (const Broken& c : cases) {
    CAPTURE(c.name);
    const fs::path d = c.change ? fresh(c.name, c.change) : fresh(c.name);
    if (c.breaks) c.breaks(d);
    const std::string msg = read_error(d);
    if (c.match == Match::exact) {
      CHECK(msg == c.error);
    } else {
      INFO(msg);
      CHECK(starts_with(msg, c.error));
      CHECK(msg.find('\n') == std::string::npos);
    }
  }
}

// The common ways to break a written scene: a file removed, the first `from` in it replaced (or
// the number after `prefix`), its bytes replaced, an image or an array written in its place.
std::function<void(Dir)> removed(const std::string& file) {
  return [file](Dir d) { fs::remove(d / file); };
}
std::function<void(Dir)> replaced(const std::string& file, const std::string& from, const std::string& by) {
  return [=](Dir d) { replace_in(d / file, from, by); };
}
std::function<void(Dir)> value_replaced(const std::string& file, const std::string& prefix, const std::string& by) {
  return [=](Dir d) { replace_value(d / file, prefix, by); };
}
std::function<void(Dir)> written(const std::string& file, const std::string& bytes) {
  return [=](Dir d) { write_bytes(d / file, bytes); };
}
std::function<void(Dir)> png_written(const std::string& file, const trainer::Image& image) {
  return [=](Dir d) { trainer::write_png((d / file).string(), image); };
}
template <class T>
std::function<void(Dir)> npy_written(const std::string& file, const std::vector<T>& values,
                                     const std::vector<std::int64_t>& shape) {
  return [=](Dir d) { npy::write((d / file).string(), values, shape); };
}

void write_tracks(const fs::path& dir, const std::vector<float>& uv, const std::vector<std::int64_t>& uv_shape,
                  const std::vector<std::uint8_t>& vis, const std::vector<std::int64_t>& vis_shape,
                  const std::vector<std::int32_t>& qt) {
  const std::string npz = trainer::files::npz_bytes(
      {{"uv", npy::to_bytes(uv.data(), uv_shape)},
       {"visible", npy::to_bytes(reinterpret_cast<const bool*>(vis.data()), vis_shape)},
       {"query_t", npy::to_bytes(qt.data(), {static_cast<std::int64_t>(qt.size())})}});
  write_bytes(dir / "priors/tracks.npz", npz);
}

}  // namespace

TEST_CASE("dycheck: a written scene reads back unchanged") {
  const DycheckScene a = synthetic();
  const fs::path dir = fresh("round_trip");
  for (const char* f : {"camera/0_00002.json", "rgb/2x/1_00001.png", "depth/2x/0_00004.npy", "covisible/2x/val/2_00003.png",
                        "splits/train.json", "splits/val.json", "dataset.json", "scene.json", "metadata.json",
                        "priors/tracks.npz", "priors/masks/0_00000.png", "priors/features/0_00002.npy"})
    CHECK_MESSAGE(fs::exists(dir / f), f);
  CHECK(!fs::exists(dir / "priors/masks/0_00002.png"));      // has_mask 0
  CHECK(!fs::exists(dir / "priors/features/0_00004.npy"));  // has_features 0
  // The camera file is at 1x.
  const std::string cam = slurp(dir / "camera/0_00000.json");
  CHECK(cam.find("\"image_size\": [16, 12]") != std::string::npos);

  const DycheckScene b = trainer::read_dycheck(dir.string());
  CHECK(b.root == dir.string());
  CHECK(b.width == 8);
  CHECK(b.height == 6);
  REQUIRE(b.frames() == 3);
  for (std::size_t t = 0; t < 3; ++t) {
    CHECK(b.train[t].name == a.train[t].name);
    CHECK(b.train[t].time == a.train[t].time);
    CHECK(b.train[t].camera == 0);
    check_camera(b.train_cameras[t], a.train_cameras[t]);
    CHECK(b.train_rgb[t].channels == 3);
    CHECK(b.train_rgb[t].pixels == a.train_rgb[t].pixels);
  }
  CHECK(b.depth == a.depth);
  REQUIRE(b.val.size() == 2);
  for (std::size_t v = 0; v < 2; ++v) {
    CHECK(b.val[v].name == a.val[v].name);
    CHECK(b.val[v].time == a.val[v].time);
    CHECK(b.val[v].camera == a.val[v].camera);
    check_camera(b.val_cameras[v], a.val_cameras[v]);
    CHECK(b.val_rgb[v].pixels == a.val_rgb[v].pixels);
    CHECK(b.val_covisible[v] == a.val_covisible[v]);
  }
  CHECK(b.tracks.count == 5);
  CHECK(b.tracks.frames == 3);
  CHECK(b.tracks.uv == a.tracks.uv);
  CHECK(b.tracks.visible == a.tracks.visible);
  CHECK(b.tracks.query_t == a.tracks.query_t);
  CHECK(b.has_mask == a.has_mask);
  CHECK(b.dynamic_mask == a.dynamic_mask);
  CHECK(b.feature_width == 4);
  CHECK(b.feature_height == 3);
  CHECK(b.feature_dim == 5);
  CHECK(b.has_features == a.has_features);
  CHECK(b.features == a.features);

  // Without the validation frames, nothing of them is read (their files may be absent).
  fs::remove(dir / "covisible/2x/val/1_00001.png");
  trainer::DycheckReadOptions no_val;
  no_val.read_val = false;
  const DycheckScene c = trainer::read_dycheck(dir.string(), no_val);
  CHECK(c.val.empty());
  CHECK(c.val_rgb.empty());
}

TEST_CASE("dycheck: training frames are sorted by time; extra keys and files are tolerated; float16 features") {
  const fs::path dir = fresh("tolerant");
  write_bytes(dir / "splits/train.json",
             "{\"frame_names\": [\"0_00004\", \"0_00000\", \"0_00002\"], \"time_ids\": [4, 0, 2], "
             "\"camera_ids\": [0, 0, 0], \"comment\": {\"any\": [1, 2]}}");
  replace_in(dir / "camera/0_00002.json", "\"skew\"", "\"unused\": [null, true], \"skew\"");
  write_bytes(dir / "notes.txt", "extra file");
  // Features of frame 0 as float16 (the values are multiples of 1/8, exact in half precision).
  const DycheckScene a = synthetic();
  std::vector<std::uint16_t> half(60);
  for (std::size_t i = 0; i < 60; ++i) {
    const float f = a.features[i];
    // float -> half for these exactly representable values: through the bit patterns.
    std::uint32_t bits;
    std::memcpy(&bits, &f, 4);
    const std::uint32_t sign = (bits >> 16) & 0x8000u;
    if (f == 0.0f) {
      half[i] = static_cast<std::uint16_t>(sign);
      continue;
    }
    const int exponent = static_cast<int>((bits >> 23) & 0xFF) - 127 + 15;
    half[i] = static_cast<std::uint16_t>(sign | (static_cast<std::uint32_t>(exponent) << 10) | ((bits >> 13) & 0x3FFu));
  }
  // The float32 file's header with the dtype changed ("<f4" and "<f2" have the same length).
  const std::string f32 = npy::to_bytes(a.features.data(), {3, 4, 5});
  std::string f16 = f32.substr(0, f32.size() - 240);
  f16.replace(f16.find("<f4"), 3, "<f2");
  f16.append(reinterpret_cast<const char*>(half.data()), 120);
  write_bytes(dir / "priors/features/0_00000.npy", f16);

  const DycheckScene b = trainer::read_dycheck(dir.string());
  REQUIRE(b.frames() == 3);
  CHECK(b.train[0].time == 0);
  CHECK(b.train[1].time == 2);
  CHECK(b.train[2].time == 4);
  CHECK(b.features == a.features);
}

TEST_CASE("dycheck: broken camera files name the camera file") {
  const std::string c0 = "camera/0_00000.json", c2 = "camera/0_00002.json", c4 = "camera/0_00004.json";
  check_broken({
      {"cam_missing", removed(c2), "camera/0_00002.json: file is missing"},
      {"cam_key", replaced(c2, "\"focal_length\"", "\"focal\""), "camera/0_00002.json: missing key 'focal_length'"},
      {"cam_nan", value_replaced(c4, "\"focal_length\": ", "NaN"), "camera/0_00004.json: focal_length is NaN"},
      {"cam_position_inf", value_replaced(c0, "\"position\": [", "-Infinity"), "camera/0_00000.json: position[0] is infinite"},
      {"cam_distortion", replaced(c0, "\"radial_distortion\": [0, ", "\"radial_distortion\": [0.01, "),
       "camera/0_00000.json: non-zero radial_distortion (distortion is not supported; undistort the images)"},
      {"cam_tangential", replaced(c0, "\"tangential_distortion\": [0, 0]", "\"tangential_distortion\": [0, 1e-4]"),
       "camera/0_00000.json: non-zero tangential_distortion", Match::prefix},
      // Absent distortion keys are zero.
      {"cam_no_distortion_keys", replaced(c0, "\"tangential_distortion\": [0, 0],", ""), "no error"},
      {"cam_rotation", {}, "camera/0_00002.json: orientation is not a rotation", Match::prefix,
       [](DycheckScene& s) { s.train_cameras[1].world_to_camera.topLeftCorner<3, 3>() *= 1.01; }},
      // A reflection is orthogonal but not a rotation.
      {"cam_reflection", {}, "camera/1_00001.json: orientation is not a rotation", Match::prefix,
       [](DycheckScene& s) { s.val_cameras[0].world_to_camera.row(0) *= -1; }},
      {"cam_syntax", written(c0, "{\"orientation\": [[1, 0, 0], [0, 1, 0], [0, 0, 1],}"),
       "camera/0_00000.json: line 1, column 50: unexpected character '}'"},
      {"cam_skew", replaced(c0, "\"skew\": 0.0", "\"skew\": 0.5"), "camera/0_00000.json: skew is 0.5", Match::prefix},
      // Another size than the other training frames.
      {"cam_size", replaced(c4, "\"image_size\": [16, 12]", "\"image_size\": [18, 12]"),
       "camera/0_00004.json: image size 9x6 at 2x differs", Match::prefix},
  });
}

TEST_CASE("dycheck: the 2x size rounds like Dycheck (Python's round, halves to even)") {
  const fs::path d = fresh("half_even");
  // 1x 17x13 -> 8.5 -> 8, 6.5 -> 6; the 8x6 images still fit. 1x 19 -> 9.5 -> 10.
  for (const char* f : {"0_00000", "0_00002", "0_00004"})
    replace_in(d / ("camera/" + std::string(f) + ".json"), "\"image_size\": [16, 12]", "\"image_size\": [17, 13]");
  CHECK(read_error(d) == "no error");
  replace_in(d / "camera/1_00001.json", "\"image_size\": [20, 16]", "\"image_size\": [19, 15]");
  CHECK(read_error(d) == "no error");  // 10x8, as the image
  replace_in(d / "camera/1_00001.json", "\"image_size\": [19, 15]", "\"image_size\": [21, 17]");
  CHECK(read_error(d) == "no error");  // 10.5 -> 10, 8.5 -> 8
  replace_in(d / "camera/1_00001.json", "\"image_size\": [21, 17]", "\"image_size\": [23, 17]");
  CHECK(read_error(d) == "rgb/2x/1_00001.png: image is 10x8, camera/1_00001.json gives 12x8 at 2x");
}

TEST_CASE("dycheck: broken images, depth, covisible and splits name their file") {
  const trainer::Image grey(8, 6, 1, 0.5f), white(8, 6, 1, 1.0f);
  const std::vector<float> depth = synthetic().depth;
  check_broken({
      {"rgb_size", png_written("rgb/2x/0_00002.png", rgb(7, 6, 0)),
       "rgb/2x/0_00002.png: image is 7x6, camera/0_00002.json gives 8x6 at 2x"},
      {"rgb_garbage", written("rgb/2x/0_00000.png", "this is not a PNG file at all"), "rgb/2x/0_00000.png: not a PNG image",
       Match::prefix},
      {"rgb_truncated",
       [](Dir d) {
         const std::string png = slurp(d / "rgb/2x/0_00000.png");
         write_bytes(d / "rgb/2x/0_00000.png", png.substr(0, png.size() / 2));
       },
       "rgb/2x/0_00000.png: corrupt PNG", Match::prefix},
      {"rgb_grey", png_written("rgb/2x/0_00000.png", grey), "rgb/2x/0_00000.png: expected an RGB or RGBA image, found 1 channel(s)"},
      {"depth_missing", removed("depth/2x/0_00004.npy"), "depth/2x/0_00004.npy: file is missing"},
      {"depth_negative", {}, "depth/2x/0_00002.npy: negative depth -0.5 at pixel (3, 2)", Match::exact,
       [](DycheckScene& s) { s.depth[48 + 8 * 2 + 3] = -0.5f; }},
      {"depth_nan", {}, "depth/2x/0_00000.npy: depth is NaN at pixel (5, 0)", Match::exact,
       [](DycheckScene& s) { s.depth[5] = std::numeric_limits<float>::quiet_NaN(); }},
      {"depth_shape", npy_written("depth/2x/0_00000.npy", std::vector<float>(96, 1.0f), {6, 8, 2}),
       "depth/2x/0_00000.npy: shape [6, 8, 2], expected [6, 8, 1] (the 2x image size)"},
      // [H, W] is accepted.
      {"depth_2d", npy_written("depth/2x/0_00000.npy", std::vector<float>(depth.begin(), depth.begin() + 48), {6, 8}), "no error"},
      {"depth_int", npy_written("depth/2x/0_00000.npy", std::vector<std::int32_t>(48, 1), {6, 8, 1}),
       "depth/2x/0_00000.npy: dtype int32, expected float32"},
      // Fortran order is read (and transposed; the values then differ, but the file is valid).
      {"depth_fortran", replaced("depth/2x/0_00002.npy", "False,", "True, "), "no error"},
      {"depth_fortran_short",
       [](Dir d) {
         replace_in(d / "depth/2x/0_00002.npy", "False,", "True, ");
         const std::string b = slurp(d / "depth/2x/0_00002.npy");
         write_bytes(d / "depth/2x/0_00002.npy", b.substr(0, b.size() - 4));
       },
       "depth/2x/0_00002.npy: truncated data (188 of 192 bytes for shape [6, 8, 1])"},
      {"covisible_missing", removed("covisible/2x/val/2_00003.png"), "covisible/2x/val/2_00003.png: file is missing"},
      {"covisible_grey", png_written("covisible/2x/val/2_00003.png", grey),
       "covisible/2x/val/2_00003.png: value 128 at pixel (0, 0) is neither 0 nor 255"},
      {"covisible_size", png_written("covisible/2x/val/1_00001.png", white), "covisible/2x/val/1_00001.png: image is 8x6, expected 10x8"},
      {"split_lengths", written("splits/val.json", "{\"frame_names\": [\"1_00001\"], \"time_ids\": [1, 3], \"camera_ids\": [1]}"),
       "splits/val.json: frame_names, time_ids and camera_ids have different lengths (1, 2, 1)"},
      {"split_missing_key", written("splits/train.json", "{\"frame_names\": [\"0_00000\"], \"time_ids\": [0]}"),
       "splits/train.json: missing key 'camera_ids'"},
      {"split_duplicate_time",
       written("splits/train.json",
               "{\"frame_names\": [\"0_00000\", \"0_00002\", \"1_00002\"], \"time_ids\": [0, 2, 2], \"camera_ids\": [0, 0, 1]}"),
       "splits/train.json: time id 2 appears more than once"},
      {"split_name", written("splits/train.json", "{\"frame_names\": [\"0_0000\"], \"time_ids\": [0], \"camera_ids\": [0]}"),
       "splits/train.json: frame_names[0] is '0_0000', expected '0_00000' for camera_ids[0] = 0, time_ids[0] = 0"},
      {"split_missing", removed("splits/train.json"), "splits/train.json: file is missing"},
  });
  {
    // A depth file in Fortran order, as numpy writes np.asfortranarray(depth): the same depth.
    const fs::path d = fresh("depth_fortran_order");
    const std::string rel = "depth/2x/0_00002.npy";
    const std::string c_file = slurp(d / rel);
    const std::size_t head = c_file.size() - 48 * 4;
    std::string f_file = c_file.substr(0, head);
    const auto flag = f_file.find("False,");
    REQUIRE(flag != std::string::npos);
    f_file.replace(flag, 6, "True, ");
    for (std::size_t x = 0; x < 8; ++x)  // Fortran order of [6, 8, 1]: y runs fastest
      for (std::size_t y = 0; y < 6; ++y) f_file += c_file.substr(head + (y * 8 + x) * 4, 4);
    write_bytes(d / rel, f_file);
    CHECK(trainer::read_dycheck(d.string()).depth == synthetic().depth);
  }
  {
    // RGBA: alpha is ignored.
    const fs::path d = fresh("rgba");
    trainer::Image im(8, 6, 4, 0.0f);
    const trainer::Image src = synthetic().train_rgb[0];
    for (int y = 0; y < 6; ++y)
      for (int x = 0; x < 8; ++x) {
        for (int c = 0; c < 3; ++c) im.at(x, y, c) = src.at(x, y, c);
        im.at(x, y, 3) = 0.5f;
      }
    trainer::write_png((d / "rgb/2x/0_00000.png").string(), im);
    CHECK(trainer::read_dycheck(d.string()).train_rgb[0].pixels == src.pixels);
  }
}

TEST_CASE("dycheck: broken tracks, masks and features name their file") {
  const std::vector<std::uint8_t> vis(15, 1);
  const std::vector<float> uv(30, 2.0f);
  const std::string tracks = "priors/tracks.npz", f2 = "priors/features/0_00002.npy";
  check_broken({
      {"tracks_t",
       [](Dir d) { write_tracks(d, std::vector<float>(20, 1.0f), {5, 2, 2}, std::vector<std::uint8_t>(10, 1), {5, 2}, {0, 0, 0, 0, 0}); },
       "priors/tracks.npz: uv has T = 2 frames, splits/train.json has 3 training frames"},
      {"tracks_q", [&](Dir d) { write_tracks(d, uv, {5, 3, 2}, std::vector<std::uint8_t>(12, 1), {4, 3}, {0, 0, 0, 0, 0}); },
       "priors/tracks.npz: visible has shape [4, 3], expected [5, 3]"},
      {"tracks_nan", {}, "priors/tracks.npz: uv[3][0] is NaN", Match::exact,
       [](DycheckScene& s) { s.tracks.uv[7] = std::numeric_limits<float>::quiet_NaN(); }},
      {"tracks_query", [&](Dir d) { write_tracks(d, uv, {5, 3, 2}, vis, {5, 3}, {0, 2, 4, 3, 0}); },
       "priors/tracks.npz: query_t[3] = 3 is not a training time id"},
      {"tracks_member", written(tracks, trainer::files::npz_bytes({{"uv", npy::to_bytes(uv.data(), {5, 3, 2})}})),
       "priors/tracks.npz: missing array 'visible'"},
      {"tracks_truncated",
       [&](Dir d) {
         const std::string z = slurp(d / tracks);
         write_bytes(d / tracks, z.substr(0, z.size() - 30));
       },
       "priors/tracks.npz: truncated archive (no end of central directory)"},
      {"tracks_crc",
       [&](Dir d) {
         std::string z = slurp(d / tracks);
         z[30 + 6 + 130] = static_cast<char>(z[30 + 6 + 130] ^ 0x01);  // a data byte of uv.npy
         write_bytes(d / tracks, z);
       },
       "priors/tracks.npz: CRC-32 mismatch in member 'uv.npy' (corrupt archive)"},
      {"tracks_missing", removed(tracks), "priors/tracks.npz: file is missing"},
      {"mask_values", png_written("priors/masks/0_00002.png", trainer::Image(8, 6, 1, 0.5f)),
       "priors/masks/0_00002.png: value 128 at pixel (0, 0) is neither 0 nor 255"},
      {"mask_size", png_written("priors/masks/0_00000.png", trainer::Image(6, 8, 1, 1.0f)),
       "priors/masks/0_00000.png: image is 6x8, expected 8x6"},
      {"features_c0", npy_written(f2, std::vector<float>{}, {3, 4, 0}),
       "priors/features/0_00002.npy: C = 0 feature channels (1 .. 64 allowed)"},
      {"features_c65", npy_written(f2, std::vector<float>(3 * 4 * 65, 0.5f), {3, 4, 65}),
       "priors/features/0_00002.npy: C = 65 feature channels (1 .. 64 allowed)"},
      {"features_size", npy_written(f2, std::vector<float>(2 * 4 * 5, 0.5f), {2, 4, 5}),
       "priors/features/0_00002.npy: shape [2, 4, 5] differs from priors/features/0_00000.npy's [3, 4, 5]"},
      {"features_nan", {}, "priors/features/0_00002.npy: non-finite feature value at flat index 10", Match::exact,
       [](DycheckScene& s) { s.features[70] = std::numeric_limits<float>::infinity(); }},
  });
  {
    const fs::path d = fresh("tracks_far", [](DycheckScene& s) {
      s.tracks.uv[2 * (2 * 5 + 1)] = -70.0f;  // t = 2 (time id 4), q = 1, visible
      s.tracks.visible[2 * 5 + 1] = 1;
    });
    CHECK(read_error(d) ==
          "priors/tracks.npz: track 1 is visible at (-70, 5.25) at time id 4, more than 64 px outside the 8x6 image");
    trainer::DycheckReadOptions wide;
    wide.track_margin_px = 100;
    CHECK(read_error(d, wide) == "no error");
  }
}

TEST_CASE("npz: numpy.savez_compressed output (deflate members) is read") {
  // tests/data/tracks_compressed.npz was made by
  //   python3 -c "import numpy as np; np.savez_compressed('tracks_compressed.npz',
  //     uv=(np.arange(24, dtype=np.float32).reshape(4, 3, 2) * 0.5),
  //     visible=(np.arange(12).reshape(4, 3) % 3 != 0), query_t=np.array([0, 2, 4, 2], dtype=np.int32),
  //     half=np.array([1.5, -2.0, 65504.0], dtype=np.float16))"
  const std::string fixture = std::string(SMG_TEST_DATA_DIR) + "/tracks_compressed.npz";
  const std::vector<unsigned char> bytes = trainer::files::read_bytes(fixture, "fixture");
  const auto arrays = trainer::files::parse_npz(bytes, "fixture");
  REQUIRE(arrays.size() == 4);
  CHECK(arrays.at("uv").shape == std::vector<std::int64_t>{4, 3, 2});
  const std::vector<float> uv = arrays.at("uv").as<float>();
  for (std::size_t i = 0; i < uv.size(); ++i) CHECK(uv[i] == 0.5f * static_cast<float>(i));
  CHECK(arrays.at("visible").dtype == npy::DType::b1);
  const std::vector<std::uint8_t> vis = arrays.at("visible").as<std::uint8_t>();
  for (std::size_t i = 0; i < vis.size(); ++i) CHECK(vis[i] == (i % 3 != 0));
  CHECK(arrays.at("query_t").as<std::int32_t>() == std::vector<std::int32_t>{0, 2, 4, 2});
  CHECK(arrays.at("half").as<float>() == std::vector<float>{1.5f, -2.0f, 65504.0f});

  // As a scene's tracks.npz (training times 0, 2, 4; the extra array is tolerated).
  const fs::path d = fresh("npz_compressed");
  fs::copy_file(fixture, d / "priors/tracks.npz", fs::copy_options::overwrite_existing);
  const DycheckScene s = trainer::read_dycheck(d.string());
  CHECK(s.tracks.count == 4);
  CHECK(s.tracks.query_t == std::vector<std::int32_t>{0, 1, 2, 1});
  CHECK(s.tracks.uv[2 * (1 * 4 + 2)] == uv[2 * (2 * 3 + 1)]);  // [t=1][q=2] from the file's [q=2][t=1]

  // A flipped bit in the compressed stream: corrupt deflate data or a CRC mismatch, never garbage.
  for (std::size_t at : {std::size_t{60}, std::size_t{100}}) {
    std::vector<unsigned char> bad = bytes;
    bad[at] ^= 0x10;
    CHECK_THROWS_AS(trainer::files::parse_npz(bad, "bad.npz"), npy::Error);
  }
  CHECK_THROWS_WITH_AS(trainer::files::parse_npz(std::vector<unsigned char>(100, 0), "z.npz"),
                       "z.npz: not an .npz archive (no ZIP end of central directory)", npy::Error);
}

TEST_CASE("npz: the writer's archive is a valid ZIP (CRC-32 check value, round trip)") {
  const unsigned char check[] = "123456789";
  CHECK(trainer::files::crc32(check, 9) == 0xCBF43926u);
  const float v[4] = {1, 2, 3, 4};
  const std::string z = trainer::files::npz_bytes({{"a", npy::to_bytes(v, {2, 2})}, {"b", npy::to_bytes(v, {4})}});
  const auto arrays = trainer::files::parse_npz(std::vector<unsigned char>(z.begin(), z.end()), "w.npz");
  CHECK(arrays.at("a").shape == std::vector<std::int64_t>{2, 2});
  CHECK(arrays.at("b").as<float>() == std::vector<float>{1, 2, 3, 4});
}

namespace {
// Appends each (value, byte count) field, little-endian.
void put_le(std::string& s, std::initializer_list<std::pair<std::uint64_t, int>> fields) {
  for (const auto& [v, bytes] : fields)
    for (int k = 0; k < bytes; ++k) s += static_cast<char>((v >> (8 * k)) & 0xFFu);
}
// A one-member stored archive that uses every ZIP64 field: sizes and offset 0xFFFFFFFF in the
// headers with their 64-bit values in the extra fields, a ZIP64 end of central directory record
// and its locator, and 0xFFFF / 0xFFFFFFFF in the classic end record.
std::string zip64_archive(const std::string& name, const std::string& data) {
  const std::uint32_t crc = trainer::files::crc32(reinterpret_cast<const unsigned char*>(data.data()), data.size());
  const std::uint64_t size = data.size(), name_size = name.size(), ff = 0xFFFFFFFF;
  // Local header: signature, version 4.5, flags, method (stored), time and date, CRC, the two
  // sizes (in the extra field), name and extra lengths; then the name and the ZIP64 extra field.
  std::string z;
  put_le(z, {{0x04034b50, 4}, {45, 2}, {0, 2}, {0, 2}, {0, 4}, {crc, 4}, {ff, 4}, {ff, 4}, {name_size, 2}, {20, 2}});
  z += name;
  put_le(z, {{0x0001, 2}, {16, 2}, {size, 8}, {size, 8}});
  z += data;
  // Central directory entry: as the local header plus comment length, disk, attributes and the
  // local header's offset, whose 64-bit value follows the sizes in the extra field (4 + 24 bytes).
  const std::uint64_t cd_offset = z.size();
  std::string cd;
  put_le(cd, {{0x02014b50, 4}, {45, 2}, {45, 2}, {0, 2}, {0, 2}, {0, 4}, {crc, 4}, {ff, 4}, {ff, 4}, {name_size, 2}, {28, 2}});
  put_le(cd, {{0, 2}, {0, 2}, {0, 2}, {0, 4}, {ff, 4}});
  cd += name;
  put_le(cd, {{0x0001, 2}, {24, 2}, {size, 8}, {size, 8}, {0, 8}});
  z += cd;
  // ZIP64 end of central directory record (44 bytes after its size field), its locator, and the
  // classic end record with every count, size and offset saturated.
  const std::uint64_t z64 = z.size();
  put_le(z, {{0x06064b50, 4}, {44, 8}, {45, 2}, {45, 2}, {0, 4}, {0, 4}, {1, 8}, {1, 8}, {cd.size(), 8}, {cd_offset, 8}});
  put_le(z, {{0x07064b50, 4}, {0, 4}, {z64, 8}, {1, 4}});
  put_le(z, {{0x06054b50, 4}, {0, 2}, {0, 2}, {0xFFFF, 2}, {0xFFFF, 2}, {ff, 4}, {ff, 4}, {0, 2}});
  return z;
}
}  // namespace

TEST_CASE("npz: ZIP64 size, offset and end-of-directory fields are followed") {
  const std::int32_t v[3] = {7, -8, 9};
  const std::string z = zip64_archive("q.npy", npy::to_bytes(v, {3}));
  const auto arrays = trainer::files::parse_npz(std::vector<unsigned char>(z.begin(), z.end()), "z64.npz");
  CHECK(arrays.at("q").as<std::int32_t>() == std::vector<std::int32_t>{7, -8, 9});
  // A member that is not an .npy file.
  const std::string t = zip64_archive("readme.txt", "hello");
  CHECK_THROWS_WITH_AS(trainer::files::parse_npz(std::vector<unsigned char>(t.begin(), t.end()), "t.npz"),
                       "t.npz: member 'readme.txt' is not an .npy file", npy::Error);
}

TEST_CASE("npz: every truncation and every flipped byte is an error or a valid read, never a crash") {
  const std::string fixture = std::string(SMG_TEST_DATA_DIR) + "/tracks_compressed.npz";
  const float v[6] = {1, 2, 3, 4, 5, 6};
  const std::string stored = trainer::files::npz_bytes({{"uv", npy::to_bytes(v, {3, 2})}});
  for (const std::vector<unsigned char>& good :
       {trainer::files::read_bytes(fixture, "fixture"), std::vector<unsigned char>(stored.begin(), stored.end())}) {
    int errors = 0;
    for (std::size_t n = 0; n < good.size(); ++n) {
      try {
        trainer::files::parse_npz(std::vector<unsigned char>(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n)), "t");
      } catch (const npy::Error&) {
        ++errors;
      }
    }
    CHECK(errors == static_cast<int>(good.size()));  // every proper prefix is refused
    for (std::size_t i = 0; i < good.size(); ++i) {
      std::vector<unsigned char> bad = good;
      bad[i] ^= 0x5A;
      try {
        trainer::files::parse_npz(bad, "f");
      } catch (const npy::Error&) {
      }
    }
  }
}

TEST_CASE("dycheck: the writer names the file or folder it cannot write, and refuses an inconsistent scene") {
  const fs::path d = temp_dir("write_errors");
  fs::create_directories(d);
  write_bytes(d / "rgb", "a file where the rgb folder should be");
  try {
    trainer::write_dycheck(d.string(), synthetic());
    FAIL("no error");
  } catch (const DataError& e) {
    CHECK(starts_with(e.what(), "rgb/2x: cannot create the folder"));
  }
  DycheckScene s = synthetic();
  s.depth.pop_back();
  try {
    trainer::write_dycheck(temp_dir("write_inconsistent").string(), s);
    FAIL("no error");
  } catch (const DataError& e) {
    CHECK(std::string(e.what()) ==
          "depth/2x: the scene to write is inconsistent: depth holds 143 values, expected 144 (frames x height x width)");
  }
}

// A deflate bomb as priors/tracks.npz (tests/fuzz/corpus/npz, written by tests/fuzz/make_seeds.py):
// once `smg_trainer: error: std::bad_alloc`, now one line naming the file and the member.
TEST_CASE("dycheck: deflate bombs in priors/tracks.npz are refused naming the file and the member") {
  const fs::path corpus = fs::path(SMG_TEST_DATA_DIR) / ".." / "fuzz" / "corpus" / "npz";
  const fs::path d = fresh("bomb");
  write_bytes(d / "priors/tracks.npz", slurp(corpus / "bomb-header.npz"));
  CHECK(read_error(d) == "priors/tracks.npz: member 'uv.npy': its .npy header declares 4000000000128 bytes, the archive records 1048576");
  write_bytes(d / "priors/tracks.npz", slurp(corpus / "bomb-ratio.npz"));
  CHECK(starts_with(read_error(d), "priors/tracks.npz: member 'uv.npy' records 1073741824 bytes from "));
}
