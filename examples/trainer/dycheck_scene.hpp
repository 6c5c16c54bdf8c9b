// examples/trainer/dycheck_scene.hpp — a scene in the Dycheck iPhone layout plus SMG's priors as
// it is held in memory (docs/data.md), and the error its files raise. Its own file so that the
// readers and writers the layouts share (layout_io.hpp) and the Dycheck layout (dycheck.hpp) both
// build on it, one way: dycheck.cpp defines layout_io.hpp's functions, layout_io.hpp needs only
// these types.
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

}  // namespace trainer
