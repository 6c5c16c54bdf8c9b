// examples/trainer/dycheck.hpp — a scene on disk in the Dycheck iPhone layout plus SMG's priors
// (docs/data.md): reading with full validation, and writing (the exporter of the procedural
// scene uses the writer, so both sides of the format live in one place).
//
// Layout (docs/data.md sections 1 and 2), read at factor 2 ("2x"):
//   camera/<frame>.json, rgb/2x/<frame>.png, depth/2x/<frame>.npy (training frames),
//   covisible/2x/val/<frame>.png (validation frames), splits/{train,val}.json,
//   priors/tracks.npz, priors/masks/<frame>.png, priors/features/<frame>.npy.
// Frame names are "{camera}_{time:05d}". Cameras are stored at 1x in the files and converted
// here: focal length and principal point halved, image size halved and rounded. Pixel (i, j) has
// its centre at (i + 0.5, j + 0.5) in both the files and trainer::Camera.
//
// Every problem found while reading throws DataError with one line "<file>: <problem>" (the file
// as a path under the scene folder), before anything is trained. Extra keys in the JSON files and
// extra files in the folders are tolerated.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "trainer/camera.hpp"
#include "trainer/image.hpp"

namespace trainer {

// A problem with a scene on disk; what() is "<file>: <problem>".
class DataError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A frame's name in the split files: "{camera}_{time:05d}".
std::string dycheck_frame_name(int camera, int time);

struct DycheckFrame {
  std::string name;  // "{camera}_{time:05d}", as listed in the split file
  int camera = 0;    // camera_ids entry of the split
  int time = 0;      // time_ids entry of the split
};

// priors/tracks.npz, in the trainer's sample-major order (the file is track-major [Q][T]).
struct DycheckTracks {
  int count = 0;                       // Q
  int frames = 0;                      // T: the training times, in DycheckScene::train order
  std::vector<float> uv;               // [T][Q][2] 2x pixel coordinates, centre convention
  std::vector<std::uint8_t> visible;   // [T][Q] the tracker's visibility (0/1)
  std::vector<std::int32_t> query_t;   // [Q] index into DycheckScene::train (converted from the
                                       // file's time id)
};

struct DycheckScene {
  std::string root;  // the scene folder as given

  // Training frames: splits/train.json, sorted by time id (every time id once; camera ids any).
  // All training frames share one image size (width x height at 2x).
  int width = 0, height = 0;
  std::vector<DycheckFrame> train;       // [T]
  std::vector<Camera> train_cameras;     // [T] at 2x
  std::vector<Image> train_rgb;          // [T] [H][W][3] in [0, 1] (8-bit values / 255)
  std::vector<float> depth;              // [T][H][W] metres (projective z), 0 = invalid

  // Validation frames: splits/val.json in file order (time ids may have gaps; a val time id
  // need not be a training time id). Each frame has its own camera and image size.
  std::vector<DycheckFrame> val;               // [V]
  std::vector<Camera> val_cameras;             // [V] at 2x
  std::vector<Image> val_rgb;                  // [V] [H][W][3]
  std::vector<std::vector<std::uint8_t>> val_covisible;  // [V] [H][W] 0/1 (covisible / 255)

  // Priors (training camera, 2x). A training frame without a mask or feature file is "missing"
  // for that prior: has_mask / has_features is 0 there and its slice is all zeros.
  DycheckTracks tracks;
  std::vector<std::uint8_t> dynamic_mask;      // [T][H][W] 0/1 (255 in the file = dynamic)
  std::vector<std::uint8_t> has_mask;          // [T]
  int feature_width = 0, feature_height = 0;   // w, h of the feature grid (the same every frame)
  int feature_dim = 0;                         // C, 1 .. 64
  std::vector<float> features;                 // [T][h][w][C] as stored (float16 -> float)
  std::vector<std::uint8_t> has_features;      // [T]

  int frames() const { return static_cast<int>(train.size()); }
};

struct DycheckReadOptions {
  bool read_val = true;               // read validation cameras, images and covisible masks
  // Track samples reported visible may lie at most this far outside the image (pixels at 2x,
  // a tracker's extrapolation); farther, or NaN/Inf anywhere, is an error naming tracks.npz.
  double track_margin_px = 64.0;
  // Shape-of-Motion layout only (read_som): its tracks are a grid of queries in every frame's
  // mask (often millions in all), so at most this many are kept, spread evenly over the query
  // frames and, within a frame, over its rows (as SoM's get_tracks_3d samples num_samples of
  // them, deterministically here). 0 keeps every track.
  int max_tracks = 20000;
};

// Reads and validates a scene (docs/data.md). Throws DataError ("<file>: <problem>") on a missing
// or unreadable file, an inconsistent one (sizes, frame names, time ids, splits), non-zero
// distortion, a non-finite value, depth < 0, a track far outside the image, a feature map of a
// different size than the others, or C outside 1 .. 64.
DycheckScene read_dycheck(const std::string& dir, const DycheckReadOptions& options = {});

// Writes `scene` in the layout into `dir` (created if missing; existing files of the layout are
// replaced): camera JSONs at 1x (the inverse of the 2x conversion: focal length and principal
// point doubled, size doubled), 8-bit PNGs, float32 depth [H,W,1], splits, dataset.json,
// scene.json, tracks.npz (uncompressed), masks, features (float32 [h,w,C]). Frames whose
// has_mask / has_features is 0 get no file. Throws DataError naming the file it cannot write.
void write_dycheck(const std::string& dir, const DycheckScene& scene);

}  // namespace trainer
