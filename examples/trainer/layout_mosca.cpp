// examples/trainer/layout_mosca.cpp — MoSca's preprocessed iPhone layout (docs/data.md, "MoSca"):
// the reader and the writer. Our own code, following JiahuiLei/MoSca
// lib_prior/prior_loading.py::Saved2D (images, sensor depth, tracks, epipolar error, DEVA
// instances), data_utils/iphone_helpers.py::load_iphone_cameras (Nerfies JSON cameras) and
// profile/iphone/iphone_prep.yaml (epi_th 0.001):
// - Frames: the sorted stems of images/*.{png,jpg,jpeg} ("{camera}_{time:05d}"; camera 0 trains);
//   evaluation: test_images/*.{png,jpg,jpeg} with test_cameras/<stem>.json and
//   test_covisible/<stem>.png.
// - Pixels: MoSca indexes depth with the tracks' integer pixel indices and builds K from the
//   JSON's principal point, i.e. integer pixel centres, as Shape-of-Motion; the trainer puts the
//   centre of pixel i at i + 0.5, so track x, y and the principal point get + 0.5 here. The JSON
//   may be at full resolution with half-size images (the iPhone release): MoSca keeps fov and
//   cx / W, so the camera is halved then (factor 2).
// - Depth: sensor_depth/<stem>.npz key `dep` [H, W], clipped to [1e-3, 1000]; 0 (or anything
//   outside (1e-3, 1000)) is invalid, 0 for the trainer. Saved2D's depth-edge filter is not applied.
// - Tracks: every *bootstapir*.npz in the folder (sorted by name), `tracks` [T, N, 2 or 3] and
//   `visibility` [T, N] concatenated along N; visibility cleared where the truncated pixel index
//   is outside the image (as Saved2D); x, y kept sub-pixel (Saved2D truncates them). The query
//   frame is `queries`[:, 0] where present (TAPIR's (t, y, x)), else the first visible frame.
//   Saved2D's min_valid_cnt (4) filter is left to stage 0's own track rules.
// - Dynamic masks: epi/error/*.npy [H, W] > epi_th (0.001, MoSca's iPhone setting), read as
//   lib_prior/epi_error/epi_analysis.py::load_epi_error reads them: sorted by name, one per image,
//   in the images' order. MoSca's writer (`thread` there) names each `<image file name>.npy`
//   (`0_00000.png.npy`); `<stem>.npy` is accepted too; a map whose name belongs to another image,
//   or a count that differs from the images', is refused. Without epi/error every pixel is
//   dynamic (said in one stderr line).
// - Semantics: vos_deva/Annotations/<stem>.png instance ids (R + 256 G + 65536 B, 0 unknown)
//   become one-hot descriptors (one channel per non-zero id, at most 64) on a grid subsampled to
//   at most 128 px on its long side; our priors/features/ take precedence when present.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "npy.hpp"
#include "trainer/layout_io.hpp"
#include "trainer/layouts.hpp"

namespace trainer {

namespace {

namespace fs = std::filesystem;
using layout_io::fail_at;

constexpr float kMoscaEpiTh = 0.001f;     // profile/iphone/iphone_prep.yaml epi_th
constexpr int kMoscaMaxInstances = 64;    // the trainer's feature channel limit

// Sorted file names in root/rel ending in `ext` (rel "" = the scene folder itself).
std::vector<std::string> mosca_list(const std::string& root, const std::string& rel, const std::string& ext) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(fs::path(root) / rel, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string n = it->path().filename().string();
    if (n.size() > ext.size() && n.compare(n.size() - ext.size(), ext.size(), ext) == 0) names.push_back(n);
  }
  std::sort(names.begin(), names.end());
  return names;
}

// "{camera}_{time:05d}" -> camera, time; other stems: camera 0, time = index.
DycheckFrame mosca_frame(const std::string& stem, int index) {
  DycheckFrame f{stem, 0, index};
  const std::size_t u = stem.find('_');
  if (u != std::string::npos && u > 0 && u + 1 < stem.size() &&
      stem.find_first_not_of("0123456789", 0) == u && stem.find_first_not_of("0123456789", u + 1) == std::string::npos) {
    f.camera = std::stoi(stem.substr(0, u));
    f.time = std::stoi(stem.substr(u + 1));
  }
  return f;
}

// The images of <rel>/: *.png, *.jpg, *.jpeg (any case of the extension), sorted by file name as
// Saved2D.load_rgb sorts them (lib_prior/prior_loading.py), as {stem, file name}. A stem with two
// files (a.png and a.jpg) is refused: which one is the frame?
std::vector<std::pair<std::string, std::string>> mosca_images(const std::string& root, const std::string& rel) {
  std::map<std::string, std::string> by_stem, by_file;
  for (const char* ext : {".png", ".PNG", ".jpg", ".JPG", ".jpeg", ".JPEG"})
    for (const std::string& n : mosca_list(root, rel, ext)) {
      const std::string stem = n.substr(0, n.size() - std::char_traits<char>::length(ext));
      const auto [it, fresh] = by_stem.emplace(stem, n);
      if (!fresh) fail_at(rel + "/" + n, "two images of frame " + stem + " (" + it->second + " too)");
      by_file.emplace(n, stem);
    }
  std::vector<std::pair<std::string, std::string>> out;
  out.reserve(by_file.size());
  for (const auto& [file, stem] : by_file) out.emplace_back(stem, file);
  return out;
}

// A camera from a Nerfies JSON, at the factor that matches its image (module comment), moved to
// the trainer's pixel centres.
Camera mosca_read_camera(const std::string& root, const std::string& rel, const std::string& image_rel) {
  Camera c = layout_io::read_nerfies_camera(root, rel, 1);
  const Camera half = layout_io::read_nerfies_camera(root, rel, 2);
  // The image may only be of either size: refused from its header, before it is decoded.
  files::ImageLimits limits;
  limits.sizes = {{c.width, c.height}, {half.width, half.height}};
  limits.expected = "but " + rel + " says " + std::to_string(c.width) + "x" + std::to_string(c.height) + " (nor half of it)";
  // No notes: the caller decodes the image again for its pixels (read_rgb_png), and that read
  // prints libjpeg's note, once per file.
  const files::Pixels8 png = layout_io::read_photo(root, image_rel, limits, nullptr);
  if (c.width != png.width || c.height != png.height) c = half;
  c.cx += 0.5;
  c.cy += 0.5;
  return c;
}

// sensor_depth/<stem>.npz key `dep` [H, W] (module comment).
std::vector<float> mosca_read_depth(const std::string& root, const std::string& rel, int W, int H) {
  const std::map<std::string, npy::Array> z = layout_io::read_npz(root, rel);
  const auto it = z.find("dep");
  if (it == z.end()) fail_at(rel, "no array `dep` (MoSca's sensor depth key)");
  const auto& sh = it->second.shape;
  if (!(sh.size() == 2 || (sh.size() == 3 && sh[2] == 1)) || sh[0] != H || sh[1] != W)
    fail_at(rel, "dep has shape " + npy::shape_string(sh) + ", expected [" + std::to_string(H) + ", " + std::to_string(W) + "]");
  std::vector<float> d = layout_io::float_values(it->second, rel);
  for (std::size_t i = 0; i < d.size(); ++i) {
    if (std::isnan(d[i]))
      fail_at(rel, "dep is NaN at pixel (" + std::to_string(i % static_cast<std::size_t>(W)) + ", " +
                       std::to_string(i / static_cast<std::size_t>(W)) + ")");
    d[i] = (d[i] > 1e-3f && d[i] < 1000.0f) ? d[i] : 0.0f;  // clip to [1e-3, 1000]; the ends are invalid
  }
  return d;
}

// One [H, W] float map: epi/error/<stem>.npy > epi_th = dynamic.
std::vector<std::uint8_t> mosca_read_epi(const std::string& root, const std::string& rel, int W, int H) {
  const npy::Array a = layout_io::read_npy(root, rel);
  if (a.shape != std::vector<std::int64_t>{H, W})
    fail_at(rel, "shape " + npy::shape_string(a.shape) + ", expected [" + std::to_string(H) + ", " + std::to_string(W) + "]");
  const std::vector<float> e = layout_io::float_values(a, rel);
  std::vector<std::uint8_t> m(e.size());
  for (std::size_t i = 0; i < e.size(); ++i) m[i] = e[i] > kMoscaEpiTh ? 1 : 0;  // NaN: static
  return m;
}

// A mask PNG (any channel count) as first channel > 0: MoSca's test_covisible rule.
std::vector<std::uint8_t> mosca_read_positive(const std::string& root, const std::string& rel, int W, int H) {
  const files::Pixels8 png = layout_io::read_png(root, rel, files::image_of_size(W, H));  // refused unless W x H
  std::vector<std::uint8_t> m(static_cast<std::size_t>(W) * static_cast<std::size_t>(H));
  for (std::size_t i = 0; i < m.size(); ++i) m[i] = png.pixels[i * static_cast<std::size_t>(png.channels)] > 0 ? 1 : 0;
  return m;
}

// Every *bootstapir*.npz, concatenated along N, into s.tracks (module comment).
void mosca_read_tracks(const std::string& root, DycheckScene& s) {
  const std::int64_t T = static_cast<std::int64_t>(s.train.size());
  std::vector<std::string> files;
  for (const std::string& n : mosca_list(root, "", ".npz"))
    if (n.find("bootstapir") != std::string::npos) files.push_back(n);
  if (files.empty()) fail_at("*bootstapir*.npz", "no track file in the scene folder");
  struct Part {
    std::vector<float> xy, queries;
    std::vector<std::uint8_t> vis;
    std::int64_t n = 0, c = 2;
  };
  std::vector<Part> parts;
  std::int64_t Q = 0;
  for (const std::string& rel : files) {
    std::map<std::string, npy::Array> z = layout_io::read_npz(root, rel);
    if (!z.count("tracks") || !z.count("visibility")) fail_at(rel, "needs arrays `tracks` [T, N, 2] and `visibility` [T, N]");
    const npy::Array &tk = z.at("tracks"), &vi = z.at("visibility");
    if (tk.shape.size() != 3 || tk.shape[0] != T || (tk.shape[2] != 2 && tk.shape[2] != 3))
      fail_at(rel, "tracks has shape " + npy::shape_string(tk.shape) + ", expected [" + std::to_string(T) + ", N, 2] (" +
                       std::to_string(T) + " frames in images/)");
    if (vi.shape != std::vector<std::int64_t>{T, tk.shape[1]})
      fail_at(rel, "visibility has shape " + npy::shape_string(vi.shape) + ", expected [" + std::to_string(T) + ", " +
                       std::to_string(tk.shape[1]) + "] (that of tracks)");
    if (!npy::is_boolish(vi.dtype)) fail_at(rel, std::string("visibility is ") + npy::dtype_name(vi.dtype) + ", expected bool");
    Part p;
    p.n = tk.shape[1];
    p.c = tk.shape[2];
    p.xy = layout_io::float_values(tk, rel);
    p.vis = vi.as<std::uint8_t>();
    for (std::size_t i = 0; i < p.xy.size(); ++i)
      if (!std::isfinite(p.xy[i])) fail_at(rel, "tracks is not finite at flat index " + std::to_string(i));
    const auto qi = z.find("queries");
    if (qi != z.end()) {
      if (qi->second.shape != std::vector<std::int64_t>{p.n, 3})
        fail_at(rel, "queries has shape " + npy::shape_string(qi->second.shape) + ", expected [" + std::to_string(p.n) + ", 3]");
      p.queries = qi->second.as<float>();
    }
    Q += p.n;
    parts.push_back(std::move(p));
  }
  if (Q > (1 << 28)) fail_at(files.front(), "too many tracks");
  DycheckTracks& tr = s.tracks;
  layout_io::size_tracks(tr, T, Q);
  std::int64_t k0 = 0;
  for (std::size_t f = 0; f < parts.size(); ++f) {
    const Part& p = parts[f];
    for (std::int64_t k = 0; k < p.n; ++k) {
      std::int32_t first = -1;
      for (std::int64_t t = 0; t < T; ++t) {
        const float* xy = p.xy.data() + (t * p.n + k) * p.c;
        const std::size_t dst = static_cast<std::size_t>(t * Q + k0 + k);
        // Saved2D: the truncated pixel index must lie in the image.
        const bool inside = xy[0] > -1.0f && xy[1] > -1.0f && xy[0] < static_cast<float>(s.width) && xy[1] < static_cast<float>(s.height);
        tr.uv[2 * dst] = static_cast<float>(static_cast<double>(xy[0]) + 0.5);
        tr.uv[2 * dst + 1] = static_cast<float>(static_cast<double>(xy[1]) + 0.5);
        tr.visible[dst] = (p.vis[static_cast<std::size_t>(t * p.n + k)] != 0 && inside) ? 1 : 0;
        if (tr.visible[dst] && first < 0) first = static_cast<std::int32_t>(t);
      }
      std::int32_t q = std::max(first, 0);
      if (!p.queries.empty()) {
        const float qt = p.queries[static_cast<std::size_t>(3 * k)];
        if (!(qt >= 0 && qt < static_cast<float>(T)) || qt != std::floor(qt))
          fail_at(files[f], "queries row " + std::to_string(k) + " has frame " + std::to_string(qt) + ", expected 0 .. " +
                                std::to_string(T - 1));
        q = static_cast<std::int32_t>(qt);
      }
      tr.query_t[static_cast<std::size_t>(k0 + k)] = q;
    }
    k0 += p.n;
  }
}

// vos_deva/Annotations/<stem>.png -> one-hot features (module comment).
void mosca_read_instances(const std::string& root, DycheckScene& s) {
  const std::string dir = "vos_deva/Annotations/";
  const std::size_t T = s.train.size();
  std::vector<std::vector<std::uint32_t>> ids(T);
  std::map<std::uint32_t, int> channel;
  for (std::size_t t = 0; t < T; ++t) {
    const std::string rel = dir + s.train[t].name + ".png";
    if (!layout_io::has_file(root, rel)) continue;
    const files::Pixels8 png = layout_io::read_png(root, rel, files::image_of_size(s.width, s.height));
    if (png.channels < 3) fail_at(rel, "expected RGB instance colours, found " + std::to_string(png.channels) + " channel(s)");
    const std::size_t n = static_cast<std::size_t>(png.width) * static_cast<std::size_t>(png.height), c = static_cast<std::size_t>(png.channels);
    ids[t].resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint8_t* px = png.pixels.data() + i * c;
      ids[t][i] = std::uint32_t(px[0]) + 256u * px[1] + 65536u * px[2];  // RGB2INST
      if (ids[t][i] != 0 && !channel.count(ids[t][i])) {
        if (static_cast<int>(channel.size()) == kMoscaMaxInstances)
          fail_at(rel, "more than " + std::to_string(kMoscaMaxInstances) + " instance ids in vos_deva/Annotations");
        channel.emplace(ids[t][i], 0);
      }
    }
  }
  if (channel.empty()) return;
  int next = 0;
  for (auto& kv : channel) kv.second = next++;
  const int stride = std::max(1, (std::max(s.width, s.height) + 127) / 128);
  s.feature_width = (s.width + stride - 1) / stride;
  s.feature_height = (s.height + stride - 1) / stride;
  s.feature_dim = next;
  const std::size_t per = static_cast<std::size_t>(s.feature_width) * static_cast<std::size_t>(s.feature_height) * static_cast<std::size_t>(next);
  s.features.assign(T * per, 0.0f);
  s.has_features.assign(T, 0);
  for (std::size_t t = 0; t < T; ++t) {
    if (ids[t].empty()) continue;
    s.has_features[t] = 1;
    for (int y = 0; y < s.feature_height; ++y)
      for (int x = 0; x < s.feature_width; ++x) {
        const std::uint32_t id = ids[t][static_cast<std::size_t>(y * stride) * static_cast<std::size_t>(s.width) + static_cast<std::size_t>(x * stride)];
        if (id != 0)
          s.features[t * per + (static_cast<std::size_t>(y) * static_cast<std::size_t>(s.feature_width) + static_cast<std::size_t>(x)) *
                                   static_cast<std::size_t>(next) + static_cast<std::size_t>(channel.at(id))] = 1.0f;
      }
  }
}

}  // namespace

DycheckScene read_mosca(const std::string& dir) {
  DycheckScene s;
  s.root = dir;
  std::vector<std::string> stems, files;
  for (const auto& [stem, file] : mosca_images(dir, "images")) {
    stems.push_back(stem);
    files.push_back(file);
  }
  if (stems.empty()) fail_at("images", "no images (*.png, *.jpg, *.jpeg)");
  for (std::size_t t = 0; t < stems.size(); ++t) s.train.push_back(mosca_frame(stems[t], static_cast<int>(t)));
  const std::size_t T = s.train.size();
  for (std::size_t t = 0; t < T; ++t) {
    const std::string cam_rel = "cameras/" + stems[t] + ".json", img_rel = "images/" + files[t];
    s.train_cameras.push_back(mosca_read_camera(dir, cam_rel, img_rel));
    const Camera& c = s.train_cameras.back();
    if (t == 0) {
      s.width = c.width;
      s.height = c.height;
    } else if (c.width != s.width || c.height != s.height) {
      fail_at(img_rel, "image size differs from the first frame's");
    }
    s.train_rgb.push_back(layout_io::read_rgb_png(dir, img_rel, c, cam_rel, "the images/"));
  }
  const std::size_t HW = static_cast<std::size_t>(s.width) * static_cast<std::size_t>(s.height);
  s.depth.assign(T * HW, 0.0f);
  for (std::size_t t = 0; t < T; ++t) {
    const std::vector<float> d = mosca_read_depth(dir, "sensor_depth/" + stems[t] + ".npz", s.width, s.height);
    std::copy(d.begin(), d.end(), s.depth.begin() + static_cast<std::ptrdiff_t>(t * HW));
  }

  // Evaluation: test_images/ with test_cameras/ and test_covisible/.
  for (const auto& [stem, file] : mosca_images(dir, "test_images")) {
    s.val.push_back(mosca_frame(stem, 0));
    const std::string cam_rel = "test_cameras/" + stem + ".json", img_rel = "test_images/" + file;
    s.val_cameras.push_back(mosca_read_camera(dir, cam_rel, img_rel));
    const Camera& c = s.val_cameras.back();
    s.val_rgb.push_back(layout_io::read_rgb_png(dir, img_rel, c, cam_rel, "the test_images/"));
    s.val_covisible.push_back(mosca_read_positive(dir, "test_covisible/" + stem + ".png", c.width, c.height));
  }

  // Dynamic masks from the epipolar error, else everything dynamic.
  s.has_mask.assign(T, 1);
  s.dynamic_mask.assign(T * HW, 1);
  if (layout_io::has_folder(dir, "epi/error")) {
    // As load_epi_error: sorted(glob("epi/error/*.npy")), one per image in the images' order.
    const std::vector<std::string> maps = mosca_list(dir, "epi/error", ".npy");
    if (maps.size() != T)
      fail_at("epi/error", std::to_string(maps.size()) + " epipolar error maps (*.npy) for " + std::to_string(T) +
                               " images in images/ (MoSca writes one per image, named <image file name>.npy)");
    for (std::size_t t = 0; t < T; ++t) {
      const std::string rel = "epi/error/" + maps[t];
      if (maps[t] != files[t] + ".npy" && maps[t] != stems[t] + ".npy")
        fail_at(rel, "sorted as the map of images/" + files[t] + ", expected " + files[t] + ".npy (MoSca's name) or " + stems[t] +
                         ".npy");
      const std::vector<std::uint8_t> m = mosca_read_epi(dir, rel, s.width, s.height);
      std::copy(m.begin(), m.end(), s.dynamic_mask.begin() + static_cast<std::ptrdiff_t>(t * HW));
    }
  } else {
    std::fprintf(stderr, "[data] %s: no epi/error/: every pixel is taken as dynamic\n", dir.c_str());
  }
  mosca_read_tracks(dir, s);
  layout_io::read_feature_files(dir, s);
  if (s.feature_dim == 0 && layout_io::has_folder(dir, "vos_deva/Annotations")) mosca_read_instances(dir, s);
  return s;
}

void write_mosca(const std::string& dir, const DycheckScene& s) {
  layout_io::check_scene_to_write(dir, s);
  const std::size_t T = s.train.size(), HW = static_cast<std::size_t>(s.width) * static_cast<std::size_t>(s.height);
  for (const char* d : {"images", "cameras", "sensor_depth", "epi/error", "test_images", "test_cameras", "test_covisible", "priors/features"})
    layout_io::make_dir(dir, d);
  // Cameras at the images' size, back to integer pixel centres.
  auto camera_json = [](Camera cam) {
    cam.cx -= 0.5;
    cam.cy -= 0.5;
    return layout_io::nerfies_camera_json(cam, 1);
  };
  for (std::size_t t = 0; t < T; ++t) {
    const std::string& n = s.train[t].name;
    layout_io::write_file(dir, "cameras/" + n + ".json", camera_json(s.train_cameras[t]));
    layout_io::write_png_file(dir, "images/" + n + ".png", s.train_rgb[t]);
    layout_io::write_file(dir, "sensor_depth/" + n + ".npz",
                          files::npz_bytes({{"dep", npy::to_bytes(s.depth.data() + t * HW, {s.height, s.width})}}));
    std::vector<float> err(HW);  // the mask as an epipolar error on either side of epi_th
    for (std::size_t i = 0; i < HW; ++i) err[i] = s.dynamic_mask[t * HW + i] ? 1.0f : 0.0f;
    // MoSca's name: the image file's name + ".npy" (epi_analysis.py, `thread`).
    layout_io::write_file(dir, "epi/error/" + n + ".png.npy", npy::to_bytes(err.data(), {s.height, s.width}));
  }
  for (std::size_t v = 0; v < s.val.size(); ++v) {
    const std::string& n = s.val[v].name;
    const Camera& c = s.val_cameras[v];
    layout_io::write_file(dir, "test_cameras/" + n + ".json", camera_json(c));
    layout_io::write_png_file(dir, "test_images/" + n + ".png", s.val_rgb[v]);
    layout_io::write_png_file(dir, "test_covisible/" + n + ".png", layout_io::mask_image(s.val_covisible[v].data(), c.width, c.height));
  }
  // One track file: tracks [T, Q, 2] at integer pixel centres, visibility [T, Q], queries (t, y, x).
  const DycheckTracks& tr = s.tracks;
  const std::size_t Q = static_cast<std::size_t>(tr.count);
  std::vector<float> xy(T * Q * 2), queries(Q * 3);
  const std::unique_ptr<bool[]> vis(new bool[T * Q]);
  for (std::size_t i = 0; i < T * Q; ++i) {
    xy[2 * i] = static_cast<float>(static_cast<double>(tr.uv[2 * i]) - 0.5);
    xy[2 * i + 1] = static_cast<float>(static_cast<double>(tr.uv[2 * i + 1]) - 0.5);
    vis[i] = tr.visible[i] != 0;
  }
  for (std::size_t k = 0; k < Q; ++k) {
    const std::size_t at = static_cast<std::size_t>(tr.query_t[k]) * Q + k;
    queries[3 * k] = static_cast<float>(tr.query_t[k]);
    queries[3 * k + 1] = xy[2 * at + 1];
    queries[3 * k + 2] = xy[2 * at];
  }
  const std::int64_t Ti = static_cast<std::int64_t>(T), Qi = static_cast<std::int64_t>(Q);
  layout_io::write_file(dir, "uniform_dep=sensor_bootstapir_tap.npz",
                        files::npz_bytes({{"tracks", npy::to_bytes(xy.data(), {Ti, Qi, 2})},
                                          {"visibility", npy::to_bytes(vis.get(), {Ti, Qi})},
                                          {"queries", npy::to_bytes(queries.data(), {Qi, 3})}}));
  layout_io::write_feature_files(dir, s);
}

}  // namespace trainer
