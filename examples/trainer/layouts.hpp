// examples/trainer/layouts.hpp — the on-disk scene layouts that `smg_trainer --data` reads
// (docs/data.md): our Dycheck + priors layout (dycheck.hpp), Shape-of-Motion's preprocessed iPhone
// layout (layout_som.cpp) and MoSca's (layout_mosca.cpp). Each adapter fills the same
// DycheckScene, so everything from dataset_from_dycheck onwards is shared.
#pragma once

#include <string>

#include "trainer/dycheck.hpp"

namespace trainer {

enum class DataLayout { dycheck, som, mosca };

// One line for the user: which layout, which files carry depth and tracks.
const char* data_layout_description(DataLayout layout);

// The layout of a scene folder, from its contents:
//   Shape-of-Motion: flow3d_preprocessed/;
//   MoSca: sensor_depth/ + cameras/ + a *bootstapir*.npz file in the folder;
//   Dycheck + priors: neither of those, with priors/, splits/ or camera/.
// Throws DataError ("<dir>: ...", saying what was looked for) for a missing folder, a folder that
// matches none, or one that matches two (e.g. flow3d_preprocessed/ beside priors/tracks.npz).
DataLayout detect_data_layout(const std::string& dir);

// Reads a scene of the detected layout (layout_out: which one).
DycheckScene read_data_scene(const std::string& dir, DataLayout* layout_out = nullptr);

// Shape-of-Motion (vye16/shape-of-motion, flow3d/data/iphone_dataset.py::iPhoneDataset with
// camera_type "original", factor 1; docs/data.md): rgb/1x, camera/ (Nerfies JSON),
// flow3d_preprocessed/{aligned_depth_anything_lidar/1x (disparity) | depth/1x (lidar)},
// track_anything/1x, covisible/1x/val, 2d_tracks/1x/<q>_<t>.npy. The scene comes back at 1x in
// trainer pixels (centre of pixel i at i + 0.5): SoM's integer-centred track coordinates and
// principal point get + 0.5. Throws DataError("<file>: <problem>").
DycheckScene read_som(const std::string& dir, const DycheckReadOptions& options = {});

// Writes `scene` (taken as 1x) in the Shape-of-Motion layout read by read_som: disparity
// 1 / depth (0 where depth is 0), track files with logits +-10 reproducing `visible` through
// parse_tapir_track_info, tracks grouped by query frame (read_som gives them back in that order:
// stable-sorted by query_t). priors/features/ is written when the scene has feature maps.
void write_som(const std::string& dir, const DycheckScene& scene);

// MoSca (JiahuiLei/MoSca lib_prior/prior_loading.py::Saved2D, data_utils/iphone_helpers.py;
// docs/data.md): images/*.png, cameras/ (Nerfies JSON at the images' size or twice it),
// sensor_depth/<stem>.npz `dep`, every *bootstapir*.npz (tracks [T, N, 2], visibility [T, N]),
// epi/error/<stem>.npy > 0.001 as the dynamic mask (all dynamic without it), test_images/ +
// test_cameras/ + test_covisible/ for evaluation, vos_deva/Annotations instance ids as one-hot
// features. Integer pixel centres in the files, + 0.5 here (as read_som). Throws
// DataError("<file>: <problem>").
DycheckScene read_mosca(const std::string& dir);

// Writes `scene` in the MoSca layout read by read_mosca: cameras at the images' size, dep in
// stored .npz archives, the dynamic mask as an epipolar error of 1 / 0, one
// uniform_dep=sensor_bootstapir_tap.npz with the tracks in the scene's order and queries
// (t, y, x); priors/features/ when the scene has feature maps.
void write_mosca(const std::string& dir, const DycheckScene& scene);

}  // namespace trainer
