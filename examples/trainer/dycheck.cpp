// examples/trainer/dycheck.cpp — reading and writing a scene in the Dycheck iPhone layout plus
// SMG's priors (docs/data.md sections 1 and 2; the contract is dycheck.hpp).
//
// Choices where the layout leaves room:
// - 2x image size: Dycheck's Camera.rescale_image_domain(0.5) computes int(round(size * 0.5))
//   with Python's round, which rounds halves to even: 1x width 1921 -> 960, 1923 -> 962. The
//   reader does the same, so its sizes match the 2x images Dycheck ships.
// - Focal length: fx = focal_length / 2, fy = focal_length * pixel_aspect_ratio / 2 (Dycheck's
//   scale_factor_y). Non-zero skew and distortion are refused (trainer::Camera has neither).
// - RGB PNGs: 8-bit RGB or RGBA; the alpha channel is ignored (Dycheck keeps rgba[..., :3]; the
//   iPhone data is undistorted, so its alpha is 255 anyway). Grey images are refused.
// - Covisible and mask PNGs: 8-bit, one channel (or grey + alpha, or RGB(A) with equal colour
//   channels); every value must be 0 or 255. Dycheck uses covisible / 255 as a 0/1 weight, so any
//   other value is a broken file, reported with its pixel rather than silently thresholded.
// - Numbers in the JSON files may be written as NaN/Infinity (Python's json does that); they are
//   parsed and then reported by name ("focal_length is NaN").
#include "trainer/dycheck.hpp"
#include "trainer/layout_io.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>

#include <Eigen/LU>

#include "json_read.hpp"
#include "npy.hpp"
#include "trainer/file_formats.hpp"
#include "trainer/image_io.hpp"

namespace trainer {

std::string dycheck_frame_name(int camera, int time) {
  char b[48];
  std::snprintf(b, sizeof b, "%d_%05d", camera, time);
  return b;
}

namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& file, const std::string& problem) { throw DataError(file + ": " + problem); }

std::string fmt(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.9g", v);
  return b;
}
std::string size_str(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }
std::string pixel_str(std::size_t x, std::size_t y) { return "(" + std::to_string(x) + ", " + std::to_string(y) + ")"; }

// The helpers of file_formats.hpp and npy.hpp throw std::runtime_error("<label>: ..."), already
// labelled with the relative file name: turn those into DataError.
template <class F>
auto labelled(F&& f) {
  try {
    return f();
  } catch (const DataError&) {
    throw;
  } catch (const std::runtime_error& e) {
    throw DataError(e.what());
  }
}

// ---- reading ----------------------------------------------------------------------------------

// A scene folder: every file is named by its path `rel` under the root (the reader and the writer
// share this, so that a message names the file as the scene does).
class SceneFolder {
 public:
  explicit SceneFolder(std::string root) : root_(std::move(root)) {}
  std::string path(const std::string& rel) const { return (fs::path(root_) / rel).string(); }

 private:
  std::string root_;
};

class SceneReader : public SceneFolder {
 public:
  using SceneFolder::SceneFolder;

  bool exists(const std::string& rel) const {
    std::error_code ec;
    return fs::exists(path(rel), ec);
  }
  std::vector<unsigned char> bytes(const std::string& rel) const {
    return labelled([&] { return files::read_bytes(path(rel), rel); });
  }
  json::Value json(const std::string& rel) const {
    const std::vector<unsigned char> b = bytes(rel);
    try {
      return json::parse(std::string(b.begin(), b.end()), 64, /*allow_non_finite=*/true);
    } catch (const json::Error& e) {
      fail(rel, e.what());
    }
  }
  npy::Array npy_file(const std::string& rel) const {
    const std::vector<unsigned char> b = bytes(rel);
    return labelled([&] { return npy::parse(b.data(), b.size(), rel); });
  }
  // `limits`: the sizes the image may have, checked from its header before it is decoded.
  files::Pixels8 png(const std::string& rel, const files::ImageLimits& limits) const {
    const std::vector<unsigned char> b = bytes(rel);
    return labelled([&] { return files::decode_png(b, rel, limits); });
  }
  // A photograph: JPEG where the name says so (MoSca's images/*.jpg), else PNG; `notes` as
  // files::decode_jpeg's.
  files::Pixels8 photo(const std::string& rel, const files::ImageLimits& limits, std::FILE* notes = stderr) const {
    if (!files::is_jpeg_name(rel)) return png(rel, limits);
    const std::vector<unsigned char> b = bytes(rel);
    return labelled([&] { return files::decode_jpeg(b, rel, limits, notes); });
  }
};

// A finite number member (NaN / Infinity named).
double finite(const json::Value& v, const std::string& key, const std::string& rel) {
  double x = 0;
  try {
    x = json::get_number(v, key);
  } catch (const json::Error& e) {
    fail(rel, e.what());
  }
  if (std::isnan(x)) fail(rel, key + " is NaN");
  if (!std::isfinite(x)) fail(rel, key + " is infinite");
  return x;
}
std::vector<double> finite_array(const json::Value& v, const std::string& key, long n, const std::string& rel) {
  std::vector<double> a;
  try {
    a = json::get_numbers(v, key, n);
  } catch (const json::Error& e) {
    fail(rel, e.what());
  }
  for (std::size_t i = 0; i < a.size(); ++i)
    if (!std::isfinite(a[i])) fail(rel, key + "[" + std::to_string(i) + "] is " + (std::isnan(a[i]) ? "NaN" : "infinite"));
  return a;
}

// A Nerfies camera JSON (1x) converted to trainer::Camera at `factor` (1 or 2; see the file
// comment for 2x). The principal point is taken as stored (Dycheck's pixel-centre convention).
Camera read_camera(const SceneReader& in, const std::string& rel, int factor) {
  const json::Value v = in.json(rel);
  if (!v.is_object()) fail(rel, "expected a JSON object");

  // orientation: 3 rows of 3 numbers.
  Eigen::Matrix3d R;
  {
    const json::Value* o = v.find("orientation");
    if (!o) fail(rel, "missing key 'orientation'");
    if (!o->is_array() || o->items.size() != 3) fail(rel, "'orientation' is not a 3x3 array");
    for (int r = 0; r < 3; ++r) {
      const json::Value& row = o->items[static_cast<std::size_t>(r)];
      if (!row.is_array() || row.items.size() != 3) fail(rel, "'orientation' is not a 3x3 array");
      for (int c = 0; c < 3; ++c) {
        const json::Value& e = row.items[static_cast<std::size_t>(c)];
        if (!e.is_number()) fail(rel, "'orientation' is not a 3x3 array of numbers");
        if (!std::isfinite(e.number))
          fail(rel, "orientation[" + std::to_string(r) + "][" + std::to_string(c) + "] is " + (std::isnan(e.number) ? "NaN" : "infinite"));
        R(r, c) = e.number;
      }
    }
  }
  const double orth = (R * R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  const double det = R.determinant();
  if (orth > 1e-3 || std::abs(det - 1.0) > 1e-3)
    fail(rel, "orientation is not a rotation (max |R R^T - I| = " + fmt(orth) + ", det = " + fmt(det) + ")");

  const std::vector<double> p = finite_array(v, "position", 3, rel);
  const double focal = finite(v, "focal_length", rel);
  if (!(focal > 0)) fail(rel, "focal_length is " + fmt(focal) + " (must be > 0)");
  const std::vector<double> pp = finite_array(v, "principal_point", 2, rel);
  const double aspect = finite(v, "pixel_aspect_ratio", rel);
  if (!(aspect > 0)) fail(rel, "pixel_aspect_ratio is " + fmt(aspect) + " (must be > 0)");
  const double skew = finite(v, "skew", rel);
  if (skew != 0) fail(rel, "skew is " + fmt(skew) + " (non-zero skew is not supported)");
  for (const auto& [key, n] : {std::pair<const char*, long>{"radial_distortion", 3}, {"tangential_distortion", 2}}) {
    if (!v.find(key)) continue;
    const std::vector<double> d = finite_array(v, key, n, rel);
    if (std::any_of(d.begin(), d.end(), [](double x) { return x != 0; }))
      fail(rel, std::string("non-zero ") + key + " (distortion is not supported; undistort the images)");
  }
  std::vector<std::int64_t> size;
  try {
    size = json::get_ints(v, "image_size", 2);
  } catch (const json::Error& e) {
    fail(rel, e.what());
  }
  if (size[0] < 2 || size[1] < 2 || size[0] > (1 << 20) || size[1] > (1 << 20))
    fail(rel, "image_size [" + std::to_string(size[0]) + ", " + std::to_string(size[1]) + "] is out of range");

  // 2x: Python's round(size * 0.5), halves to even (Dycheck's rescale_image_domain); 1x: as stored.
  auto half = [factor](std::int64_t n) {
    if (factor == 1) return static_cast<int>(n);
    const std::int64_t q = n / 2;
    return static_cast<int>((n % 2 == 1 && q % 2 == 1) ? q + 1 : q);
  };
  const double f = factor;
  Camera cam;
  cam.width = half(size[0]);
  cam.height = half(size[1]);
  cam.fx = focal / f;
  cam.fy = focal * aspect / f;
  cam.cx = pp[0] / f;
  cam.cy = pp[1] / f;
  const Eigen::Vector3d position(p[0], p[1], p[2]);
  cam.world_to_camera.setIdentity();
  cam.world_to_camera.topLeftCorner<3, 3>() = R;
  cam.world_to_camera.topRightCorner<3, 1>() = -R * position;
  return cam;
}

std::vector<DycheckFrame> read_split(const SceneReader& in, const std::string& rel) {
  const json::Value v = in.json(rel);
  std::vector<std::string> names;
  std::vector<std::int64_t> times, cams;
  try {
    names = json::get_strings(v, "frame_names");
    times = json::get_ints(v, "time_ids");
    cams = json::get_ints(v, "camera_ids");
  } catch (const json::Error& e) {
    fail(rel, e.what());
  }
  if (names.size() != times.size() || names.size() != cams.size())
    fail(rel, "frame_names, time_ids and camera_ids have different lengths (" + std::to_string(names.size()) + ", " +
                  std::to_string(times.size()) + ", " + std::to_string(cams.size()) + ")");
  std::vector<DycheckFrame> frames(names.size());
  std::map<std::string, std::size_t> seen;
  for (std::size_t i = 0; i < names.size(); ++i) {
    const std::string at = "[" + std::to_string(i) + "]";
    if (times[i] < 0 || times[i] > 9999999) fail(rel, "time_ids" + at + " = " + std::to_string(times[i]) + " is out of range");
    if (cams[i] < 0 || cams[i] > 999) fail(rel, "camera_ids" + at + " = " + std::to_string(cams[i]) + " is out of range");
    frames[i].camera = static_cast<int>(cams[i]);
    frames[i].time = static_cast<int>(times[i]);
    frames[i].name = names[i];
    const std::string expected = dycheck_frame_name(frames[i].camera, frames[i].time);
    if (names[i] != expected)
      fail(rel, "frame_names" + at + " is '" + names[i] + "', expected '" + expected + "' for camera_ids" + at + " = " +
                    std::to_string(cams[i]) + ", time_ids" + at + " = " + std::to_string(times[i]));
    if (!seen.emplace(names[i], i).second) fail(rel, "frame '" + names[i] + "' is listed twice");
  }
  return frames;
}

// A 0/255 one-channel PNG (see the file comment) as 0/1, checked against the expected size.
std::vector<std::uint8_t> read_binary_png(const SceneReader& in, const std::string& rel, int width, int height) {
  const files::Pixels8 png = in.png(rel, files::image_of_size(width, height));  // refused unless width x height
  const int C = png.channels;
  const int colour = (C == 2 || C == 4) ? C - 1 : C;
  std::vector<std::uint8_t> out(static_cast<std::size_t>(width) * static_cast<std::size_t>(height));
  for (std::size_t i = 0; i < out.size(); ++i) {
    const std::uint8_t* px = png.pixels.data() + i * static_cast<std::size_t>(C);
    for (int c = 1; c < colour; ++c)
      if (px[c] != px[0])
        fail(rel, "colour channels differ at pixel " + pixel_str(i % static_cast<std::size_t>(width), i / static_cast<std::size_t>(width)) +
                      " (expected a grey 0/255 image)");
    if (px[0] != 0 && px[0] != 255)
      fail(rel, "value " + std::to_string(px[0]) + " at pixel " +
                    pixel_str(i % static_cast<std::size_t>(width), i / static_cast<std::size_t>(width)) + " is neither 0 nor 255");
    out[i] = px[0] ? 1 : 0;
  }
  return out;
}

// 8-bit RGB(A) as an Image [H][W][3] with values / 255 (alpha ignored). `scale` ("1x", "2x")
// only words the size message.
Image read_rgb(const SceneReader& in, const std::string& rel, const Camera& cam, const std::string& camera_rel,
               const char* scale = "2x") {
  // Refused before decoding unless of the camera's size.
  const files::Pixels8 png =
      in.photo(rel, files::image_of_size(cam.width, cam.height, camera_rel + " gives " + size_str(cam.width, cam.height) + " at " + scale));
  if (png.channels != 3 && png.channels != 4)
    fail(rel, "expected an RGB or RGBA image, found " + std::to_string(png.channels) + " channel(s)");
  Image im(png.width, png.height, 3);
  const std::size_t n = static_cast<std::size_t>(png.width) * static_cast<std::size_t>(png.height);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t c = 0; c < 3; ++c)
      im.pixels[i * 3 + c] = static_cast<float>(png.pixels[i * static_cast<std::size_t>(png.channels) + c]) / 255.0f;
  return im;
}

// A float .npy converted to float; every value finite.
std::vector<float> finite_floats(const npy::Array& a, const std::string& rel) {
  if (!npy::is_float(a.dtype)) fail(rel, std::string("dtype ") + npy::dtype_name(a.dtype) + ", expected float32");
  std::vector<float> v = labelled([&] { return a.as<float>(rel); });
  return v;
}

void read_depth(const SceneReader& in, DycheckScene& s, std::size_t t) {
  const std::string rel = "depth/2x/" + s.train[t].name + ".npy";
  const npy::Array a = in.npy_file(rel);
  const auto& sh = a.shape;
  const bool ok = (sh.size() == 3 && sh[2] == 1) || sh.size() == 2;
  if (!ok || sh[0] != s.height || sh[1] != s.width)
    fail(rel, "shape " + npy::shape_string(sh) + ", expected [" + std::to_string(s.height) + ", " +
                  std::to_string(s.width) + ", 1] (the 2x image size)");
  const std::vector<float> d = finite_floats(a, rel);
  const std::size_t W = static_cast<std::size_t>(s.width);
  for (std::size_t i = 0; i < d.size(); ++i) {
    if (std::isnan(d[i])) fail(rel, "depth is NaN at pixel " + pixel_str(i % W, i / W));
    if (!std::isfinite(d[i])) fail(rel, "depth is infinite at pixel " + pixel_str(i % W, i / W));
    if (d[i] < 0) fail(rel, "negative depth " + fmt(d[i]) + " at pixel " + pixel_str(i % W, i / W));
  }
  std::copy(d.begin(), d.end(), s.depth.begin() + static_cast<std::ptrdiff_t>(t * d.size()));
}

void read_tracks(const SceneReader& in, DycheckScene& s, const DycheckReadOptions& options) {
  const std::string rel = "priors/tracks.npz";
  const std::vector<unsigned char> b = in.bytes(rel);
  const std::map<std::string, npy::Array> arrays = labelled([&] { return files::parse_npz(b, rel); });
  auto member = [&](const char* key) -> const npy::Array& {
    const auto it = arrays.find(key);
    if (it == arrays.end()) fail(rel, std::string("missing array '") + key + "'");
    return it->second;
  };
  const npy::Array& uv_a = member("uv");
  const npy::Array& vis_a = member("visible");
  const npy::Array& qt_a = member("query_t");
  const std::int64_t T = s.frames();
  if (uv_a.shape.size() != 3 || uv_a.shape[2] != 2) fail(rel, "uv has shape " + npy::shape_string(uv_a.shape) + ", expected [Q, T, 2]");
  const std::int64_t Q = uv_a.shape[0];
  if (uv_a.shape[1] != T)
    fail(rel, "uv has T = " + std::to_string(uv_a.shape[1]) + " frames, splits/train.json has " + std::to_string(T) + " training frames");
  if (vis_a.shape != std::vector<std::int64_t>{Q, T})
    fail(rel, "visible has shape " + npy::shape_string(vis_a.shape) + ", expected [" + std::to_string(Q) + ", " + std::to_string(T) + "]");
  if (qt_a.shape != std::vector<std::int64_t>{Q})
    fail(rel, "query_t has shape " + npy::shape_string(qt_a.shape) + ", expected [" + std::to_string(Q) + "]");
  if (Q > std::numeric_limits<int>::max() / 4) fail(rel, "too many tracks");
  if (!npy::is_float(uv_a.dtype)) fail(rel, std::string("uv has dtype ") + npy::dtype_name(uv_a.dtype) + ", expected float32");
  if (!npy::is_boolish(vis_a.dtype)) fail(rel, std::string("visible has dtype ") + npy::dtype_name(vis_a.dtype) + ", expected bool");
  if (!npy::is_integer(qt_a.dtype)) fail(rel, std::string("query_t has dtype ") + npy::dtype_name(qt_a.dtype) + ", expected int32");
  const std::vector<float> uv = labelled([&] { return uv_a.as<float>(rel + " uv"); });
  const std::vector<std::uint8_t> vis = labelled([&] { return vis_a.as<std::uint8_t>(rel + " visible"); });
  const std::vector<std::int64_t> qt = labelled([&] { return qt_a.as<std::int64_t>(rel + " query_t"); });

  std::map<std::int64_t, int> index_of_time;
  for (int t = 0; t < s.frames(); ++t) index_of_time[s.train[static_cast<std::size_t>(t)].time] = t;
  DycheckTracks& tr = s.tracks;
  layout_io::size_tracks(tr, T, Q);
  const double m = options.track_margin_px;
  for (std::int64_t q = 0; q < Q; ++q) {
    const auto it = index_of_time.find(qt[static_cast<std::size_t>(q)]);
    if (it == index_of_time.end())
      fail(rel, "query_t[" + std::to_string(q) + "] = " + std::to_string(qt[static_cast<std::size_t>(q)]) + " is not a training time id");
    tr.query_t[static_cast<std::size_t>(q)] = it->second;
    for (std::int64_t t = 0; t < T; ++t) {
      const std::size_t src = static_cast<std::size_t>(q * T + t), dst = static_cast<std::size_t>(t * Q + q);
      const float x = uv[2 * src], y = uv[2 * src + 1];
      const std::string at = "[" + std::to_string(q) + "][" + std::to_string(t) + "]";
      if (!std::isfinite(x) || !std::isfinite(y))
        fail(rel, "uv" + at + " is " + (std::isnan(x) || std::isnan(y) ? "NaN" : "infinite"));
      const std::uint8_t v = vis[src];
      if (v > 1) fail(rel, "visible" + at + " is " + std::to_string(v) + " (expected 0 or 1)");
      if (v && (x < -m || y < -m || x > s.width + m || y > s.height + m))
        fail(rel, "track " + std::to_string(q) + " is visible at (" + fmt(x) + ", " + fmt(y) + ") at time id " +
                      std::to_string(s.train[static_cast<std::size_t>(t)].time) + ", more than " + fmt(m) +
                      " px outside the " + size_str(s.width, s.height) + " image");
      tr.uv[2 * dst] = x;
      tr.uv[2 * dst + 1] = y;
      tr.visible[dst] = v;
    }
  }
}

void read_features(const SceneReader& in, DycheckScene& s) {
  const std::size_t T = s.train.size();
  s.has_features.assign(T, 0);
  std::string first;  // the file that fixed h, w, C
  std::vector<std::vector<float>> maps(T);
  for (std::size_t t = 0; t < T; ++t) {
    const std::string rel = "priors/features/" + s.train[t].name + ".npy";
    if (!in.exists(rel)) continue;
    const npy::Array a = in.npy_file(rel);
    if (a.shape.size() != 3) fail(rel, "shape " + npy::shape_string(a.shape) + ", expected [h, w, C]");
    if (a.shape[2] < 1 || a.shape[2] > 64) fail(rel, "C = " + std::to_string(a.shape[2]) + " feature channels (1 .. 64 allowed)");
    if (a.shape[0] < 1 || a.shape[1] < 1 || a.shape[0] > 65536 || a.shape[1] > 65536)
      fail(rel, "shape " + npy::shape_string(a.shape) + " has an empty or huge grid");
    if (first.empty()) {
      first = rel;
      s.feature_height = static_cast<int>(a.shape[0]);
      s.feature_width = static_cast<int>(a.shape[1]);
      s.feature_dim = static_cast<int>(a.shape[2]);
    } else if (a.shape[0] != s.feature_height || a.shape[1] != s.feature_width || a.shape[2] != s.feature_dim) {
      fail(rel, "shape " + npy::shape_string(a.shape) + " differs from " + first + "'s [" + std::to_string(s.feature_height) +
                    ", " + std::to_string(s.feature_width) + ", " + std::to_string(s.feature_dim) + "]");
    }
    maps[t] = finite_floats(a, rel);
    for (std::size_t i = 0; i < maps[t].size(); ++i)
      if (!std::isfinite(maps[t][i])) fail(rel, "non-finite feature value at flat index " + std::to_string(i));
    s.has_features[t] = 1;
  }
  const std::size_t per = static_cast<std::size_t>(s.feature_height) * static_cast<std::size_t>(s.feature_width) *
                          static_cast<std::size_t>(s.feature_dim);
  s.features.assign(T * per, 0.0f);
  for (std::size_t t = 0; t < T; ++t)
    if (s.has_features[t]) std::copy(maps[t].begin(), maps[t].end(), s.features.begin() + static_cast<std::ptrdiff_t>(t * per));
}

// ---- writing ----------------------------------------------------------------------------------

class SceneWriter : public SceneFolder {
 public:
  using SceneFolder::SceneFolder;

  void dir(const std::string& rel) const {
    std::error_code ec;
    fs::create_directories(path(rel), ec);
    if (ec) fail(rel, "cannot create the folder: " + ec.message());
  }
  void file(const std::string& rel, const std::string& bytes) const {
    std::ofstream f(path(rel), std::ios::binary | std::ios::trunc);
    if (!f) fail(rel, "cannot open for writing");
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    f.flush();
    if (!f) fail(rel, "write error");
  }
  void png(const std::string& rel, const Image& im) const {
    try {
      write_png(path(rel), im);
    } catch (const std::runtime_error&) {
      fail(rel, "cannot write the PNG");
    }
  }
};

// JSON number text that reads back to the same double.
std::string num(double v) {
  if (!std::isfinite(v)) return "NaN";  // only reached for a broken scene; the reader names it
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}
std::string num_array(const double* v, int n) {
  std::string s = "[";
  for (int i = 0; i < n; ++i) s += (i ? ", " : "") + num(v[i]);
  return s + "]";
}
std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

// The camera JSON at 1x for a camera at `factor` (1 or 2; the inverse of read_camera).
std::string camera_json(const Camera& cam, int factor = 2) {
  const double f = factor;
  const Eigen::Matrix3d R = cam.rotation();
  const Eigen::Vector3d p = cam.center();
  std::ostringstream s;
  s << "{\n  \"orientation\": [";
  for (int r = 0; r < 3; ++r) {
    const double row[3] = {R(r, 0), R(r, 1), R(r, 2)};
    s << (r ? ", " : "") << num_array(row, 3);
  }
  const double pp[2] = {f * cam.cx, f * cam.cy};
  const double zeros[3] = {0, 0, 0};
  s << "],\n  \"position\": " << num_array(p.data(), 3) << ",\n  \"focal_length\": " << num(f * cam.fx)
    << ",\n  \"principal_point\": " << num_array(pp, 2) << ",\n  \"skew\": 0.0,\n  \"pixel_aspect_ratio\": "
    << num(cam.fy / cam.fx) << ",\n  \"radial_distortion\": " << num_array(zeros, 3)
    << ",\n  \"tangential_distortion\": " << num_array(zeros, 2) << ",\n  \"image_size\": [" << factor * cam.width << ", "
    << factor * cam.height << "]\n}\n";
  return s.str();
}

std::string split_json(const std::vector<DycheckFrame>& frames) {
  std::string names, times, cams;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const char* sep = i ? ", " : "";
    names += sep + quoted(frames[i].name);
    times += sep + std::to_string(frames[i].time);
    cams += sep + std::to_string(frames[i].camera);
  }
  return "{\"frame_names\": [" + names + "], \"time_ids\": [" + times + "], \"camera_ids\": [" + cams + "]}\n";
}

Image binary_image(const std::uint8_t* v, int width, int height) {
  Image im(width, height, 1);
  for (std::size_t i = 0; i < im.pixels.size(); ++i) im.pixels[i] = v[i] ? 1.0f : 0.0f;
  return im;
}

void need(bool ok, const std::string& rel, const std::string& what) {
  if (!ok) fail(rel, "the scene to write is inconsistent: " + what);
}

}  // namespace

// ---- shared with the other layouts (layout_io.hpp) -------------------------------------------

namespace layout_io {

void fail_at(const std::string& rel, const std::string& problem) { fail(rel, problem); }
bool has_file(const std::string& root, const std::string& rel) { return SceneReader(root).exists(rel); }
bool has_folder(const std::string& root, const std::string& rel) {
  std::error_code ec;
  return fs::is_directory(fs::path(root) / rel, ec);
}
std::vector<unsigned char> read_bytes(const std::string& root, const std::string& rel) { return SceneReader(root).bytes(rel); }
json::Value read_json(const std::string& root, const std::string& rel) { return SceneReader(root).json(rel); }
npy::Array read_npy(const std::string& root, const std::string& rel) { return SceneReader(root).npy_file(rel); }
files::Pixels8 read_png(const std::string& root, const std::string& rel, const files::ImageLimits& limits) {
  return SceneReader(root).png(rel, limits);
}
files::Pixels8 read_photo(const std::string& root, const std::string& rel, const files::ImageLimits& limits, std::FILE* notes) {
  return SceneReader(root).photo(rel, limits, notes);
}
std::map<std::string, npy::Array> read_npz(const std::string& root, const std::string& rel) {
  const std::vector<unsigned char> b = SceneReader(root).bytes(rel);
  return labelled([&] { return files::parse_npz(b, rel); });
}
std::vector<float> float_values(const npy::Array& a, const std::string& rel) { return finite_floats(a, rel); }
Camera read_nerfies_camera(const std::string& root, const std::string& rel, int factor) {
  return read_camera(SceneReader(root), rel, factor);
}
std::vector<DycheckFrame> read_split_file(const std::string& root, const std::string& rel) {
  return read_split(SceneReader(root), rel);
}
std::vector<DycheckFrame> read_train_split(const std::string& root) {
  std::vector<DycheckFrame> train = read_split(SceneReader(root), "splits/train.json");
  if (train.empty()) fail("splits/train.json", "no training frames");
  std::stable_sort(train.begin(), train.end(), [](const DycheckFrame& a, const DycheckFrame& b) { return a.time < b.time; });
  for (std::size_t t = 1; t < train.size(); ++t)
    if (train[t].time == train[t - 1].time)
      fail("splits/train.json", "time id " + std::to_string(train[t].time) + " appears more than once");
  return train;
}
Image read_rgb_png(const std::string& root, const std::string& rel, const Camera& cam, const std::string& camera_rel,
                   const char* scale) {
  return read_rgb(SceneReader(root), rel, cam, camera_rel, scale);
}
std::vector<std::uint8_t> read_binary_mask(const std::string& root, const std::string& rel, int width, int height) {
  return read_binary_png(SceneReader(root), rel, width, height);
}
void read_feature_files(const std::string& root, DycheckScene& scene) { read_features(SceneReader(root), scene); }
void make_dir(const std::string& root, const std::string& rel) { SceneWriter(root).dir(rel); }
void write_file(const std::string& root, const std::string& rel, const std::string& bytes) {
  SceneWriter(root).file(rel, bytes);
}
void write_png_file(const std::string& root, const std::string& rel, const Image& image) { SceneWriter(root).png(rel, image); }
std::string nerfies_camera_json(const Camera& cam, int factor) { return camera_json(cam, factor); }
std::string split_file_json(const std::vector<DycheckFrame>& frames) { return split_json(frames); }
Image mask_image(const std::uint8_t* mask, int width, int height) { return binary_image(mask, width, height); }
void size_tracks(DycheckTracks& tr, std::int64_t frames, std::int64_t count) {
  tr.count = static_cast<int>(count);
  tr.frames = static_cast<int>(frames);
  tr.uv.assign(static_cast<std::size_t>(frames * count * 2), 0.0f);
  tr.visible.assign(static_cast<std::size_t>(frames * count), 0);
  tr.query_t.assign(static_cast<std::size_t>(count), 0);
}
void check_scene_to_write(const std::string& root, const DycheckScene& s) {
  const std::size_t T = s.train.size(), V = s.val.size();
  const std::size_t HW = static_cast<std::size_t>(s.width) * static_cast<std::size_t>(s.height);
  const DycheckTracks& tr = s.tracks;
  const std::size_t Q = static_cast<std::size_t>(tr.count);
  if (s.train_cameras.size() != T || s.train_rgb.size() != T || s.depth.size() != T * HW || s.val_cameras.size() != V ||
      s.val_rgb.size() != V || s.val_covisible.size() != V || s.dynamic_mask.size() != T * HW ||
      tr.uv.size() != T * Q * 2 || tr.visible.size() != T * Q || tr.query_t.size() != Q)
    fail_at(root, "the scene to write is inconsistent");
}
void write_feature_files(const std::string& root, const DycheckScene& s) {
  const std::size_t T = s.train.size();
  const std::size_t per = static_cast<std::size_t>(s.feature_height) * static_cast<std::size_t>(s.feature_width) *
                          static_cast<std::size_t>(s.feature_dim);
  for (std::size_t t = 0; t < T && per > 0 && s.features.size() == T * per; ++t)
    if (t < s.has_features.size() && s.has_features[t])
      write_file(root, "priors/features/" + s.train[t].name + ".npy",
                 npy::to_bytes(s.features.data() + t * per, {s.feature_height, s.feature_width, s.feature_dim}));
}

}  // namespace layout_io

DycheckScene read_dycheck(const std::string& dir, const DycheckReadOptions& options) {
  const SceneReader in(dir);
  DycheckScene s;
  s.root = dir;
  {
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) throw DataError(dir + ": not a folder");
  }

  // Splits; training frames sorted by time id, each time id once.
  s.train = layout_io::read_train_split(dir);
  const std::size_t T = s.train.size();

  // Training cameras (one image size), images, depth.
  for (std::size_t t = 0; t < T; ++t) {
    s.train_cameras.push_back(read_camera(in, "camera/" + s.train[t].name + ".json", 2));
    const Camera& c = s.train_cameras.back();
    if (t == 0) {
      s.width = c.width;
      s.height = c.height;
    } else if (c.width != s.width || c.height != s.height) {
      fail("camera/" + s.train[t].name + ".json", "image size " + size_str(c.width, c.height) + " at 2x differs from " +
                                                      size_str(s.width, s.height) + " of the first training frame");
    }
  }
  const std::size_t HW = static_cast<std::size_t>(s.width) * static_cast<std::size_t>(s.height);
  s.depth.assign(T * HW, 0.0f);
  for (std::size_t t = 0; t < T; ++t) {
    const std::string& name = s.train[t].name;
    s.train_rgb.push_back(read_rgb(in, "rgb/2x/" + name + ".png", s.train_cameras[t], "camera/" + name + ".json"));
    read_depth(in, s, t);
  }

  // Validation frames.
  if (options.read_val) {
    s.val = read_split(in, "splits/val.json");
    for (const DycheckFrame& f : s.val) {
      s.val_cameras.push_back(read_camera(in, "camera/" + f.name + ".json", 2));
      const Camera& c = s.val_cameras.back();
      s.val_rgb.push_back(read_rgb(in, "rgb/2x/" + f.name + ".png", c, "camera/" + f.name + ".json"));
      s.val_covisible.push_back(read_binary_png(in, "covisible/2x/val/" + f.name + ".png", c.width, c.height));
    }
  }

  // Priors.
  read_tracks(in, s, options);
  s.dynamic_mask.assign(T * HW, 0);
  s.has_mask.assign(T, 0);
  for (std::size_t t = 0; t < T; ++t) {
    const std::string rel = "priors/masks/" + s.train[t].name + ".png";
    if (!in.exists(rel)) continue;
    const std::vector<std::uint8_t> m = read_binary_png(in, rel, s.width, s.height);
    std::copy(m.begin(), m.end(), s.dynamic_mask.begin() + static_cast<std::ptrdiff_t>(t * HW));
    s.has_mask[t] = 1;
  }
  read_features(in, s);
  return s;
}

void write_dycheck(const std::string& dir, const DycheckScene& s) {
  const SceneWriter out(dir);
  const std::size_t T = s.train.size(), V = s.val.size();
  const std::size_t HW = static_cast<std::size_t>(s.width) * static_cast<std::size_t>(s.height);
  const std::string train_rel = "splits/train.json";
  need(s.train_cameras.size() == T && s.val_cameras.size() == V, "camera", "one camera per training and validation frame");
  need(s.train_rgb.size() == T && s.val_rgb.size() == V, "rgb/2x", "one image per training and validation frame");
  need(s.depth.size() == T * HW, "depth/2x", "depth holds " + std::to_string(s.depth.size()) + " values, expected " +
                                                 std::to_string(T * HW) + " (frames x height x width)");
  need(s.val_covisible.size() == V, "covisible/2x/val", "one covisible mask per validation frame");
  for (const char* d : {"camera", "rgb/2x", "depth/2x", "covisible/2x/val", "splits", "priors/masks", "priors/features"})
    out.dir(d);

  out.file(train_rel, split_json(s.train));
  out.file("splits/val.json", split_json(s.val));
  auto write_frame = [&](const DycheckFrame& f, const Camera& cam, const Image& rgb) {
    const std::string rgb_rel = "rgb/2x/" + f.name + ".png";
    need(rgb.width == cam.width && rgb.height == cam.height && rgb.channels == 3, rgb_rel,
         "the image is not " + size_str(cam.width, cam.height) + " RGB");
    out.file("camera/" + f.name + ".json", camera_json(cam));
    out.png(rgb_rel, rgb);
  };
  double near = std::numeric_limits<double>::infinity(), far = 0;
  for (std::size_t t = 0; t < T; ++t) {
    const std::string depth_rel = "depth/2x/" + s.train[t].name + ".npy";
    need(s.train_cameras[t].width == s.width && s.train_cameras[t].height == s.height, depth_rel,
         "training camera size differs from the scene's width x height");
    write_frame(s.train[t], s.train_cameras[t], s.train_rgb[t]);
    const float* d = s.depth.data() + t * HW;
    for (std::size_t i = 0; i < HW; ++i)
      if (d[i] > 0 && std::isfinite(d[i])) {
        near = std::min(near, static_cast<double>(d[i]));
        far = std::max(far, static_cast<double>(d[i]));
      }
    out.file(depth_rel, npy::to_bytes(d, {s.height, s.width, 1}));
  }
  for (std::size_t v = 0; v < V; ++v) {
    write_frame(s.val[v], s.val_cameras[v], s.val_rgb[v]);
    const Camera& c = s.val_cameras[v];
    const std::string cov_rel = "covisible/2x/val/" + s.val[v].name + ".png";
    need(s.val_covisible[v].size() == static_cast<std::size_t>(c.width) * static_cast<std::size_t>(c.height), cov_rel,
         "covisible mask size differs from the camera's");
    out.png(cov_rel, binary_image(s.val_covisible[v].data(), c.width, c.height));
  }

  // dataset.json, metadata.json, scene.json: what Dycheck's parser reads from them.
  {
    std::string ids, train_ids, val_ids, meta;
    for (std::size_t t = 0; t < T; ++t) train_ids += (t ? ", " : "") + quoted(s.train[t].name);
    for (std::size_t v = 0; v < V; ++v) val_ids += (v ? ", " : "") + quoted(s.val[v].name);
    ids = train_ids + (T && V ? ", " : "") + val_ids;
    auto meta_of = [&](const DycheckFrame& f) {
      meta += (meta.empty() ? "\n  " : ",\n  ") + quoted(f.name) + ": {\"warp_id\": " + std::to_string(f.time) +
              ", \"appearance_id\": " + std::to_string(f.time) + ", \"camera_id\": " + std::to_string(f.camera) + "}";
    };
    for (const auto& f : s.train) meta_of(f);
    for (const auto& f : s.val) meta_of(f);
    out.file("dataset.json", "{\"count\": " + std::to_string(T + V) + ", \"num_exemplars\": " + std::to_string(T) +
                                 ", \"ids\": [" + ids + "], \"train_ids\": [" + train_ids + "], \"val_ids\": [" + val_ids + "]}\n");
    out.file("metadata.json", "{" + meta + "\n}\n");
    if (!(far > 0)) {
      near = 0.1;
      far = 100.0;
    }
    out.file("scene.json", "{\"scale\": 1.0, \"center\": [0.0, 0.0, 0.0], \"near\": " + num(0.9 * near) +
                               ", \"far\": " + num(1.1 * far) + "}\n");
  }

  // Priors: tracks back to the file's track-major order, query_t as time ids.
  {
    const std::string rel = "priors/tracks.npz";
    const DycheckTracks& tr = s.tracks;
    const std::size_t Q = static_cast<std::size_t>(tr.count);
    need(tr.frames == static_cast<int>(T) && tr.uv.size() == T * Q * 2 && tr.visible.size() == T * Q && tr.query_t.size() == Q,
         rel, "track arrays do not match count x frames");
    std::vector<float> uv(Q * T * 2);
    std::vector<std::uint8_t> vis(Q * T);
    std::vector<std::int32_t> qt(Q);
    for (std::size_t q = 0; q < Q; ++q) {
      const std::int32_t k = tr.query_t[q];
      need(k >= 0 && static_cast<std::size_t>(k) < T, rel, "query_t[" + std::to_string(q) + "] is not a training frame index");
      qt[q] = s.train[static_cast<std::size_t>(k)].time;
      for (std::size_t t = 0; t < T; ++t) {
        uv[2 * (q * T + t)] = tr.uv[2 * (t * Q + q)];
        uv[2 * (q * T + t) + 1] = tr.uv[2 * (t * Q + q) + 1];
        vis[q * T + t] = tr.visible[t * Q + q] ? 1 : 0;
      }
    }
    const std::int64_t Qi = static_cast<std::int64_t>(Q), Ti = static_cast<std::int64_t>(T);
    // bool data: one byte 0/1 per value, the same bytes as uint8 0/1 (npy's |b1).
    std::string vis_npy = npy::to_bytes(reinterpret_cast<const bool*>(vis.data()), {Qi, Ti});
    out.file(rel, files::npz_bytes({{"uv", npy::to_bytes(uv.data(), {Qi, Ti, 2})},
                                    {"visible", std::move(vis_npy)},
                                    {"query_t", npy::to_bytes(qt.data(), {Qi})}}));
  }
  need(s.has_mask.size() == T && s.dynamic_mask.size() == T * HW, "priors/masks", "has_mask or dynamic_mask size");
  for (std::size_t t = 0; t < T; ++t)
    if (s.has_mask[t])
      out.png("priors/masks/" + s.train[t].name + ".png", binary_image(s.dynamic_mask.data() + t * HW, s.width, s.height));
  const std::size_t per = static_cast<std::size_t>(s.feature_height) * static_cast<std::size_t>(s.feature_width) *
                          static_cast<std::size_t>(s.feature_dim);
  need(s.has_features.size() == T && s.features.size() == T * per, "priors/features", "has_features or features size");
  for (std::size_t t = 0; t < T; ++t)
    if (s.has_features[t])
      out.file("priors/features/" + s.train[t].name + ".npy",
               npy::to_bytes(s.features.data() + t * per, {s.feature_height, s.feature_width, s.feature_dim}));
}

}  // namespace trainer
