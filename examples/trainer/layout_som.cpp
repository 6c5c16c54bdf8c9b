// examples/trainer/layout_som.cpp — Shape-of-Motion's preprocessed iPhone layout (docs/data.md,
// "Shape-of-Motion"): the reader and the writer. Our own code, following the loader
// vye16/shape-of-motion flow3d/data/iphone_dataset.py::iPhoneDataset (factor 1),
// flow3d/data/colmap.py and flow3d/data/utils.py::parse_tapir_track_info:
// - Cameras: SoM's default camera_type "refined" where its files are there: the COLMAP model
//   flow3d_preprocessed/colmap/sparse/{cameras,images}.bin (images found by "<frame>.png"; w2c =
//   [R(qvec) | tvec]; K from the model's pinhole parameters, distortion ignored, as
//   get_intrinsics_extrinsics does) with the depth aligned to it, depth_type
//   "depth_anything_colmap". colmap/scale.npy (COLMAP units -> metres; SoM applies it in its
//   evaluation) scales the translations and the depth, so the scene is metric like the others;
//   without it the scene stays in COLMAP's units (the trainer's lengths follow the scene's extent).
//   Otherwise camera_type "original": the Nerfies camera/<frame>.json with monocular depth aligned
//   to those metric cameras, aligned_depth_anything_lidar/1x (the depth_type "depth_anything_lidar"
//   and its pairing with camera_type "original" are HiMoR's README's, a project built on SoM; SoM's
//   own depth types are midas, depth_anything, lidar, depth_anything_colmap), or without it the
//   lidar depth/1x/<frame>.npy [H, W, 1] (0 = none).
// - Pixels: SoM's tracks, depth samples and K use integer pixel centres (grid_sample with
//   align_corners=True, get_bkgd_points's arange grid, K as stored). The trainer puts the centre
//   of pixel i at i + 0.5, so track x, y and the principal point get + 0.5 here: every ray is the
//   ray SoM computes.
// - Depth from disparity: depth = 1 / max(disparity, 1e-3), except that a disparity of exactly 0
//   is a hole (no depth, 0) where SoM would put 1000 m: our exporter writes holes that way. SoM
//   clamps depth to 2.5 x the median over frames of each frame's maximum; so do we.
// - Visibility: vis = 1 - sigmoid(occ), conf = 1 - sigmoid(dist); visible iff vis * conf > 0.5.
//   (SoM's further filter, the query frame's mask, is our stage 0's object-mask rule.)
// - Masks: track_anything/1x value / 255 > 0.5 is dynamic (SoM thresholds masks at 0.5).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "npy.hpp"
#include "trainer/colmap_model.hpp"
#include "trainer/layout_io.hpp"
#include "trainer/layouts.hpp"

namespace trainer {

namespace {

namespace fs = std::filesystem;
using layout_io::fail_at;

const char* const kSomPre = "flow3d_preprocessed/";
const char* const kSomLidarDisparity = "flow3d_preprocessed/aligned_depth_anything_lidar/1x/";
const char* const kSomColmapDisparity = "flow3d_preprocessed/aligned_depth_anything_colmap/1x/";
const char* const kSomColmapCameras = "flow3d_preprocessed/colmap/sparse/cameras.bin";
const char* const kSomColmapImages = "flow3d_preprocessed/colmap/sparse/images.bin";
const char* const kSomColmapScale = "flow3d_preprocessed/colmap/scale.npy";

// sigmoid in double (the logits are float32 in the file).
double som_sigmoid(double x) { return 1.0 / (1.0 + std::exp(-x)); }

// parse_tapir_track_info's "visible": (1 - sigmoid(occ)) * (1 - sigmoid(dist)) > 0.5.
bool som_visible(double occ_logit, double dist_logit) {
  return (1.0 - som_sigmoid(occ_logit)) * (1.0 - som_sigmoid(dist_logit)) > 0.5;
}

// One depth frame [H][W] metres: disparity (1 / max(d, 1e-3)) or lidar z (0 = none).
std::vector<float> som_read_depth(const std::string& root, const std::string& rel, bool disparity, int W, int H) {
  const npy::Array a = layout_io::read_npy(root, rel);
  const auto& sh = a.shape;
  const bool ok = (sh.size() == 3 && sh[2] == 1) || sh.size() == 2;
  if (!ok || sh[0] != H || sh[1] != W)
    fail_at(rel, "shape " + npy::shape_string(sh) + ", expected [" + std::to_string(H) + ", " + std::to_string(W) +
                     (disparity ? "]" : ", 1]") + " (the 1x image size)");
  std::vector<float> d = layout_io::float_values(a, rel);
  for (std::size_t i = 0; i < d.size(); ++i) {
    const std::string at = " at pixel (" + std::to_string(i % static_cast<std::size_t>(W)) + ", " +
                           std::to_string(i / static_cast<std::size_t>(W)) + ")";
    if (!std::isfinite(d[i])) fail_at(rel, std::string(disparity ? "disparity" : "depth") + " is not finite" + at);
    if (disparity) {
      // 0 is a hole (no depth), as the lidar's 0; SoM's max(d, 1e-3) would put it at 1000 m.
      d[i] = d[i] == 0.0f ? 0.0f : 1.0f / std::max(d[i], 1e-3f);
    } else if (d[i] < 0) {
      fail_at(rel, "negative depth" + at);
    }
  }
  return d;
}

// track_anything/1x/<frame>.png: one channel (grey or grey + alpha), value / 255 > 0.5 = dynamic.
std::vector<std::uint8_t> som_read_mask(const std::string& root, const std::string& rel, int W, int H) {
  const files::Pixels8 png = layout_io::read_png(root, rel, files::image_of_size(W, H));  // refused unless W x H
  if (png.channels > 2) fail_at(rel, "expected a one-channel mask, found " + std::to_string(png.channels) + " channels");
  std::vector<std::uint8_t> m(static_cast<std::size_t>(W) * static_cast<std::size_t>(H));
  for (std::size_t i = 0; i < m.size(); ++i) m[i] = png.pixels[i * static_cast<std::size_t>(png.channels)] > 127 ? 1 : 0;
  return m;
}

// 2d_tracks/1x/<q>_<t>.npy for every pair of training frames, into s.tracks ([T][Q] with the
// tracks of query frame 0 first, then 1, ...).
void som_read_tracks(const std::string& root, DycheckScene& s, const DycheckReadOptions& options) {
  const std::size_t T = s.train.size();
  const std::string dir = std::string(kSomPre) + "2d_tracks/1x/";
  auto rel_of = [&](std::size_t q, std::size_t t) { return dir + s.train[q].name + "_" + s.train[t].name + ".npy"; };
  // Per query frame: N_q rows (the query's own file), of which keep[q] are kept (rows
  // k * N_q / keep[q]: options.max_tracks spread over the frames, the first frames taking the
  // remainder).
  std::vector<std::int64_t> rows(T), keep(T), first(T);
  std::int64_t Q = 0;
  const std::int64_t cap = options.max_tracks;
  for (std::size_t q = 0; q < T; ++q) {
    const std::string rel = rel_of(q, q);
    const npy::Array a = layout_io::read_npy(root, rel);
    if (a.shape.size() != 2 || a.shape[1] != 4) fail_at(rel, "shape " + npy::shape_string(a.shape) + ", expected [N, 4]");
    rows[q] = a.shape[0];
    const std::int64_t Ti = static_cast<std::int64_t>(T), qi = static_cast<std::int64_t>(q);
    const std::int64_t share = cap / Ti + (qi < cap % Ti ? 1 : 0);
    keep[q] = cap > 0 ? std::min(rows[q], share) : rows[q];
    first[q] = Q;
    Q += keep[q];
    if (Q > std::numeric_limits<int>::max() / 4) fail_at(rel, "too many tracks");
  }
  DycheckTracks& tr = s.tracks;
  tr.count = static_cast<int>(Q);
  tr.frames = static_cast<int>(T);
  tr.uv.assign(T * static_cast<std::size_t>(Q) * 2, 0.0f);
  tr.visible.assign(T * static_cast<std::size_t>(Q), 0);
  tr.query_t.assign(static_cast<std::size_t>(Q), 0);
  const double m = options.track_margin_px;
  for (std::size_t q = 0; q < T; ++q) {
    for (std::int64_t k = 0; k < keep[q]; ++k) tr.query_t[static_cast<std::size_t>(first[q] + k)] = static_cast<std::int32_t>(q);
    for (std::size_t t = 0; t < T; ++t) {
      const std::string rel = rel_of(q, t);
      const npy::Array a = layout_io::read_npy(root, rel);
      if (a.shape != std::vector<std::int64_t>{rows[q], 4})
        fail_at(rel, "shape " + npy::shape_string(a.shape) + ", expected [" + std::to_string(rows[q]) + ", 4] (the rows of " +
                         rel_of(q, q) + ")");
      const std::vector<float> v = layout_io::float_values(a, rel);
      for (std::size_t i = 0; i < v.size(); ++i)  // every row, kept or not
        if (!std::isfinite(v[i])) fail_at(rel, "row " + std::to_string(i / 4) + " column " + std::to_string(i % 4) + " is not finite");
      for (std::int64_t k = 0; k < keep[q]; ++k) {
        const std::int64_t src_row = k * rows[q] / keep[q];
        const float* row = v.data() + 4 * src_row;
        // + 0.5: SoM's integer pixel centres to the trainer's (file comment).
        const double x = static_cast<double>(row[0]) + 0.5, y = static_cast<double>(row[1]) + 0.5;
        const bool vis = som_visible(row[2], row[3]);
        if (vis && (x < -m || y < -m || x > s.width + m || y > s.height + m))
          fail_at(rel, "row " + std::to_string(src_row) + " is visible at (" + std::to_string(row[0]) + ", " + std::to_string(row[1]) +
                           "), more than " + std::to_string(static_cast<int>(m)) + " px outside the image");
        const std::size_t dst = t * static_cast<std::size_t>(Q) + static_cast<std::size_t>(first[q] + k);
        tr.uv[2 * dst] = static_cast<float>(x);
        tr.uv[2 * dst + 1] = static_cast<float>(y);
        tr.visible[dst] = vis ? 1 : 0;
      }
    }
  }
}

// The camera set a scene is read with (file comment): SoM's refined COLMAP cameras where the
// model and the depth aligned to it are both there, else the original Nerfies camera/ JSON.
struct SomCameras {
  bool refined = false;
  double scale = 1.0;  // refined: colmap/scale.npy (COLMAP units -> metres), 1 without the file
  std::map<std::string, Camera> by_image;  // refined: by image name, "<frame>.png"
};

// The pinhole of a COLMAP camera as SoM's get_intrinsics_extrinsics takes it: f, cx, cy for the
// SIMPLE_PINHOLE / SIMPLE_RADIAL / RADIAL models, fx, fy, cx, cy for PINHOLE / OPENCV /
// OPENCV_FISHEYE / FULL_OPENCV (distortion ignored, as SoM does); any other model is refused.
void som_colmap_intrinsics(const colmap::CameraRecord& c, Camera& cam) {
  const std::string model = colmap::model_name(c.model_id);
  if (model == "SIMPLE_PINHOLE" || model == "SIMPLE_RADIAL" || model == "RADIAL") {
    cam.fx = cam.fy = c.params[0];
    cam.cx = c.params[1];
    cam.cy = c.params[2];
  } else if (model == "PINHOLE" || model == "OPENCV" || model == "OPENCV_FISHEYE" || model == "FULL_OPENCV") {
    cam.fx = c.params[0];
    cam.fy = c.params[1];
    cam.cx = c.params[2];
    cam.cy = c.params[3];
  } else {
    fail_at(kSomColmapCameras, "camera " + std::to_string(c.id) + ": model " + model +
                                   " is not supported (Shape-of-Motion reads SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, "
                                   "RADIAL, OPENCV, OPENCV_FISHEYE and FULL_OPENCV)");
  }
  if (!(cam.fx > 0 && cam.fy > 0))
    fail_at(kSomColmapCameras, "camera " + std::to_string(c.id) + ": focal length must be > 0");
  if (c.width == 0 || c.height == 0 || c.width > 1u << 16 || c.height > 1u << 16)
    fail_at(kSomColmapCameras, "camera " + std::to_string(c.id) + ": image size " + std::to_string(c.width) + "x" +
                                   std::to_string(c.height) + " is out of range");
  cam.width = static_cast<int>(c.width);
  cam.height = static_cast<int>(c.height);
}

SomCameras som_cameras(const std::string& root) {
  SomCameras out;
  out.refined = layout_io::has_file(root, kSomColmapCameras) && layout_io::has_folder(root, kSomColmapDisparity);
  if (!out.refined) return out;
  if (layout_io::has_file(root, kSomColmapScale)) {
    const npy::Array a = layout_io::read_npy(root, kSomColmapScale);
    const std::vector<double> v = a.as<double>(kSomColmapScale);
    if (v.size() != 1) fail_at(kSomColmapScale, "expected one value, found shape " + npy::shape_string(a.shape));
    if (!(std::isfinite(v[0]) && v[0] > 0)) fail_at(kSomColmapScale, "the scale must be finite and > 0");
    out.scale = v[0];
  }
  std::vector<colmap::CameraRecord> cameras;
  std::vector<colmap::ImageRecord> images;
  try {
    cameras = colmap::parse_cameras(layout_io::read_bytes(root, kSomColmapCameras));
  } catch (const colmap::FormatError& e) {
    fail_at(kSomColmapCameras, e.what());
  }
  try {
    images = colmap::parse_images(layout_io::read_bytes(root, kSomColmapImages));
  } catch (const colmap::FormatError& e) {
    fail_at(kSomColmapImages, e.what());
  }
  std::map<int, Camera> intrinsics;
  for (const colmap::CameraRecord& c : cameras) som_colmap_intrinsics(c, intrinsics[c.id]);
  for (const colmap::ImageRecord& im : images) {
    const auto k = intrinsics.find(im.camera_id);
    if (k == intrinsics.end())
      fail_at(kSomColmapImages, "image '" + im.name + "': camera " + std::to_string(im.camera_id) + " is not in cameras.bin");
    const Eigen::Quaterniond q(im.qvec[0], im.qvec[1], im.qvec[2], im.qvec[3]);
    if (std::abs(q.norm() - 1.0) > 1e-6)
      fail_at(kSomColmapImages, "image '" + im.name + "': qvec is not a unit quaternion (norm " + std::to_string(q.norm()) + ")");
    Camera cam = k->second;
    // w2c = [R(qvec) | tvec] (SoM: qvec2rotmat, tvec as stored); the scale makes the camera
    // centres -Rᵀt metric, so t scales with them. + 0.5: SoM's integer pixel centres to ours.
    cam.world_to_camera.setIdentity();
    cam.world_to_camera.topLeftCorner<3, 3>() = q.normalized().toRotationMatrix();
    cam.world_to_camera.topRightCorner<3, 1>() = out.scale * Eigen::Vector3d(im.tvec[0], im.tvec[1], im.tvec[2]);
    cam.cx += 0.5;
    cam.cy += 0.5;
    out.by_image[im.name] = cam;
  }
  return out;
}

// A frame's camera at 1x, with SoM's principal point moved to our pixel centres, and the file it
// came from (for messages).
Camera som_read_camera(const std::string& root, const std::string& frame, const SomCameras& cams, std::string* from) {
  if (cams.refined) {
    *from = kSomColmapImages;
    const auto it = cams.by_image.find(frame + ".png");
    if (it == cams.by_image.end()) fail_at(kSomColmapImages, "no image named '" + frame + ".png' (a frame of the splits)");
    return it->second;
  }
  const std::string rel = "camera/" + frame + ".json";
  *from = rel;
  if (!layout_io::has_file(root, rel) && layout_io::has_file(root, kSomColmapCameras))
    fail_at(rel, std::string("missing; the COLMAP cameras (flow3d_preprocessed/colmap/sparse) go with the depth aligned "
                             "to them, ") + kSomColmapDisparity + ", which is missing too");
  Camera c = layout_io::read_nerfies_camera(root, rel, 1);
  c.cx += 0.5;
  c.cy += 0.5;
  return c;
}

}  // namespace

DycheckScene read_som(const std::string& dir, const DycheckReadOptions& options) {
  DycheckScene s;
  s.root = dir;
  s.train = layout_io::read_train_split(dir);
  const std::size_t T = s.train.size();
  const SomCameras cams = som_cameras(dir);
  std::string from;
  for (std::size_t t = 0; t < T; ++t) {
    s.train_cameras.push_back(som_read_camera(dir, s.train[t].name, cams, &from));
    const Camera& c = s.train_cameras.back();
    if (t == 0) {
      s.width = c.width;
      s.height = c.height;
    } else if (c.width != s.width || c.height != s.height) {
      fail_at(from, "image size of frame " + s.train[t].name + " differs from the first training frame's");
    }
    s.train_rgb.push_back(layout_io::read_rgb_png(dir, "rgb/1x/" + s.train[t].name + ".png", c, from, "1x"));
  }

  // Depth (file comment): with the refined cameras the disparity aligned to them, in metres by the
  // scale; else lidar-aligned disparity, else lidar z; then SoM's clamp.
  const bool disparity = cams.refined || layout_io::has_folder(dir, kSomLidarDisparity);
  if (!disparity && !layout_io::has_folder(dir, "depth/1x")) {
    if (layout_io::has_folder(dir, std::string(kSomPre) + "aligned_depth_anything_colmap"))
      fail_at(std::string(kSomPre) + "aligned_depth_anything_colmap",
              "in COLMAP's scale, which needs the COLMAP cameras (flow3d_preprocessed/colmap/sparse/cameras.bin, missing); "
              "add them, or aligned_depth_anything_lidar/1x or depth/1x");
    fail_at(kSomLidarDisparity, "missing, and no lidar depth/1x either");
  }
  const std::string depth_dir = cams.refined ? kSomColmapDisparity : disparity ? kSomLidarDisparity : "depth/1x/";
  const std::size_t HW = static_cast<std::size_t>(s.width) * static_cast<std::size_t>(s.height);
  s.depth.assign(T * HW, 0.0f);
  std::vector<float> frame_max(T, 0.0f);
  for (std::size_t t = 0; t < T; ++t) {
    const std::string rel = depth_dir + s.train[t].name + ".npy";
    std::vector<float> d = som_read_depth(dir, rel, disparity, s.width, s.height);
    if (cams.scale != 1.0)
      for (float& z : d) z = static_cast<float>(static_cast<double>(z) * cams.scale);
    frame_max[t] = *std::max_element(d.begin(), d.end());
    std::copy(d.begin(), d.end(), s.depth.begin() + static_cast<std::ptrdiff_t>(t * HW));
  }
  {
    // torch's median of an even count is the lower middle value.
    std::vector<float> sorted = frame_max;
    std::sort(sorted.begin(), sorted.end());
    const float limit = sorted[(T - 1) / 2] * 2.5f;
    for (float& z : s.depth) z = std::min(z, limit);
  }

  // Validation frames: camera, rgb/1x, covisible/1x/val.
  s.val = layout_io::read_split_file(dir, "splits/val.json");
  for (const DycheckFrame& f : s.val) {
    s.val_cameras.push_back(som_read_camera(dir, f.name, cams, &from));
    const Camera& c = s.val_cameras.back();
    s.val_rgb.push_back(layout_io::read_rgb_png(dir, "rgb/1x/" + f.name + ".png", c, from, "1x"));
    s.val_covisible.push_back(
        layout_io::read_binary_mask(dir, std::string(kSomPre) + "covisible/1x/val/" + f.name + ".png", c.width, c.height));
  }

  // Priors: masks (every training frame), tracks, optional feature maps (our priors/features/).
  s.dynamic_mask.assign(T * HW, 0);
  s.has_mask.assign(T, 1);
  for (std::size_t t = 0; t < T; ++t) {
    const std::vector<std::uint8_t> m =
        som_read_mask(dir, std::string(kSomPre) + "track_anything/1x/" + s.train[t].name + ".png", s.width, s.height);
    std::copy(m.begin(), m.end(), s.dynamic_mask.begin() + static_cast<std::ptrdiff_t>(t * HW));
  }
  som_read_tracks(dir, s, options);
  layout_io::read_feature_files(dir, s);
  return s;
}

void write_som(const std::string& dir, const DycheckScene& s) {
  layout_io::check_scene_to_write(dir, s);
  const std::size_t T = s.train.size(), V = s.val.size();
  const std::size_t HW = static_cast<std::size_t>(s.width) * static_cast<std::size_t>(s.height);
  const DycheckTracks& tr = s.tracks;
  const std::size_t Q = static_cast<std::size_t>(tr.count);
  const std::string pre = kSomPre;
  for (const std::string& d : std::vector<std::string>{"camera", "rgb/1x", "splits", "priors/features", pre + "aligned_depth_anything_lidar/1x",
                              pre + "aligned_depth_anything_colmap/1x", pre + "colmap/sparse",
                              pre + "track_anything/1x", pre + "covisible/1x/val", pre + "2d_tracks/1x"})
    layout_io::make_dir(dir, d);
  layout_io::write_file(dir, "splits/train.json", layout_io::split_file_json(s.train));
  layout_io::write_file(dir, "splits/val.json", layout_io::split_file_json(s.val));
  layout_io::write_file(dir, "extra.json", "{\"fps\": 30.0, \"factor\": 1}\n");  // SoM reads fps from it
  // Cameras, twice as a SoM scene has them: the original Nerfies camera/ JSON and the refined
  // COLMAP model (one PINHOLE camera per frame; the reader takes these). The COLMAP model is in
  // units of kColmapScale metres (metres = units x scale), as a COLMAP reconstruction is in its
  // own units, and colmap/scale.npy says so. Both back to SoM's integer pixel centres.
  constexpr double kColmapScale = 2.0;  // a power of two: the round trip through it is exact
  std::vector<colmap::CameraRecord> colmap_cameras;
  std::vector<colmap::ImageRecord> colmap_images;
  auto write_frame = [&](const DycheckFrame& f, Camera cam, const Image& rgb) {
    cam.cx -= 0.5;
    cam.cy -= 0.5;
    layout_io::write_file(dir, "camera/" + f.name + ".json", layout_io::nerfies_camera_json(cam, 1));
    layout_io::write_png_file(dir, "rgb/1x/" + f.name + ".png", rgb);
    const int id = static_cast<int>(colmap_images.size()) + 1;
    colmap::CameraRecord c;
    c.id = id;
    c.model_id = 1;  // PINHOLE
    c.width = static_cast<std::uint64_t>(cam.width);
    c.height = static_cast<std::uint64_t>(cam.height);
    c.params = {cam.fx, cam.fy, cam.cx, cam.cy};
    colmap_cameras.push_back(c);
    colmap::ImageRecord im;
    im.id = id;
    im.camera_id = id;
    im.name = f.name + ".png";
    const Eigen::Quaterniond q(Eigen::Matrix3d(cam.rotation()));
    im.qvec[0] = q.w();
    im.qvec[1] = q.x();
    im.qvec[2] = q.y();
    im.qvec[3] = q.z();
    for (int k = 0; k < 3; ++k) im.tvec[k] = cam.translation()(k) / kColmapScale;
    colmap_images.push_back(im);
  };
  for (std::size_t t = 0; t < T; ++t) {
    write_frame(s.train[t], s.train_cameras[t], s.train_rgb[t]);
    std::vector<float> disp(HW);
    for (std::size_t i = 0; i < HW; ++i) {
      const float z = s.depth[t * HW + i];
      disp[i] = z > 0 ? 1.0f / z : 0.0f;
    }
    layout_io::write_file(dir, pre + "aligned_depth_anything_lidar/1x/" + s.train[t].name + ".npy",
                          npy::to_bytes(disp.data(), {s.height, s.width}));
    for (float& d : disp) d = static_cast<float>(d * kColmapScale);  // 1 / (z / scale)
    layout_io::write_file(dir, pre + "aligned_depth_anything_colmap/1x/" + s.train[t].name + ".npy",
                          npy::to_bytes(disp.data(), {s.height, s.width}));
    layout_io::write_png_file(dir, pre + "track_anything/1x/" + s.train[t].name + ".png",
                              layout_io::mask_image(s.dynamic_mask.data() + t * HW, s.width, s.height));
  }
  for (std::size_t v = 0; v < V; ++v) {
    write_frame(s.val[v], s.val_cameras[v], s.val_rgb[v]);
    layout_io::write_png_file(dir, pre + "covisible/1x/val/" + s.val[v].name + ".png",
                              layout_io::mask_image(s.val_covisible[v].data(), s.val_cameras[v].width, s.val_cameras[v].height));
  }
  layout_io::write_file(dir, pre + "colmap/sparse/cameras.bin", colmap::cameras_bytes(colmap_cameras));
  layout_io::write_file(dir, pre + "colmap/sparse/images.bin", colmap::images_bytes(colmap_images));
  const double scale = kColmapScale;
  layout_io::write_file(dir, pre + "colmap/scale.npy", npy::to_bytes(&scale, {}));
  // Tracks: one [N_q, 4] file per (query, target) pair; logits +-10 give visible / invisible.
  for (std::size_t q = 0; q < T; ++q) {
    std::vector<std::size_t> rows;
    for (std::size_t k = 0; k < Q; ++k)
      if (static_cast<std::size_t>(tr.query_t[k]) == q) rows.push_back(k);
    for (std::size_t t = 0; t < T; ++t) {
      std::vector<float> v(rows.size() * 4);
      for (std::size_t r = 0; r < rows.size(); ++r) {
        const std::size_t src = t * Q + rows[r];
        v[4 * r] = static_cast<float>(static_cast<double>(tr.uv[2 * src]) - 0.5);
        v[4 * r + 1] = static_cast<float>(static_cast<double>(tr.uv[2 * src + 1]) - 0.5);
        v[4 * r + 2] = tr.visible[src] ? -10.0f : 10.0f;
        v[4 * r + 3] = -10.0f;
      }
      layout_io::write_file(dir, pre + "2d_tracks/1x/" + s.train[q].name + "_" + s.train[t].name + ".npy",
                            npy::to_bytes(v.data(), {static_cast<std::int64_t>(rows.size()), 4}));
    }
  }
  layout_io::write_feature_files(dir, s);
}

}  // namespace trainer
