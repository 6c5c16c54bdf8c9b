// examples/trainer/layout_io.hpp — the file readers and writers that the on-disk layouts share
// (Dycheck + priors in dycheck.cpp, Shape-of-Motion in layout_som.cpp, MoSca in
// layout_mosca.cpp; docs/data.md). Defined in
// dycheck.cpp. Every `rel` is a path under the scene folder `root`; every reader throws
// DataError("<rel>: <problem>") so that a refused scene names its file.
#pragma once

#include <cstdint>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "npy.hpp"
#include "json_read.hpp"
#include "trainer/camera.hpp"
#include "trainer/dycheck_scene.hpp"
#include "trainer/file_formats.hpp"
#include "trainer/image.hpp"

namespace trainer::layout_io {

// Throws DataError("<rel>: <problem>").
[[noreturn]] void fail_at(const std::string& rel, const std::string& problem);

// Whether root/rel exists (a file or a folder), and whether it is a folder (rel "" = root); no
// error is thrown (an unreadable path counts as absent).
bool has_file(const std::string& root, const std::string& rel);
bool has_folder(const std::string& root, const std::string& rel);
// Whole-file readers (JSON allows NaN/Infinity, as Python writes them).
std::vector<unsigned char> read_bytes(const std::string& root, const std::string& rel);
json::Value read_json(const std::string& root, const std::string& rel);
npy::Array read_npy(const std::string& root, const std::string& rel);
// Images: `limits` gives the sizes the image may have, checked from its header before anything
// is decoded (file_formats.hpp).
files::Pixels8 read_png(const std::string& root, const std::string& rel, const files::ImageLimits& limits);
// A photograph: JPEG where the name ends in .jpg / .jpeg (any case), else PNG. `notes`: where a
// JPEG read through libjpeg's warnings says so (files::decode_jpeg; nullptr: nowhere).
files::Pixels8 read_photo(const std::string& root, const std::string& rel, const files::ImageLimits& limits,
                          std::FILE* notes = stderr);
std::map<std::string, npy::Array> read_npz(const std::string& root, const std::string& rel);
// A float array as float32 values (any float dtype, either memory order); non-float refused.
std::vector<float> float_values(const npy::Array& a, const std::string& rel);

// A Nerfies camera JSON (focal_length, principal_point, orientation R world->camera, position =
// camera centre, image_size [W, H] at 1x) as a Camera at `factor` 1 or 2 (2: sizes rounded half
// to even, K / 2). The principal point is taken as stored.
Camera read_nerfies_camera(const std::string& root, const std::string& rel, int factor);
// splits/<name>.json: frame_names, time_ids, camera_ids (file order).
std::vector<DycheckFrame> read_split_file(const std::string& root, const std::string& rel);
// splits/train.json sorted by time id: at least one frame, every time id once.
std::vector<DycheckFrame> read_train_split(const std::string& root);
// 8-bit RGB(A) PNG (or JPEG, by the name: read_photo) of the camera's size as [H][W][3] values
// / 255; `scale` words the message.
Image read_rgb_png(const std::string& root, const std::string& rel, const Camera& cam, const std::string& camera_rel,
                   const char* scale);
// A 0/255 one-channel PNG of width x height as 0/1 (any other value refused, naming its pixel).
std::vector<std::uint8_t> read_binary_mask(const std::string& root, const std::string& rel, int width, int height);
// priors/features/<frame>.npy of every training frame that has one (optional per frame).
void read_feature_files(const std::string& root, DycheckScene& scene);

// Writers: folders, whole files, PNGs (values in [0, 1] quantised to 8 bits).
void make_dir(const std::string& root, const std::string& rel);
void write_file(const std::string& root, const std::string& rel, const std::string& bytes);
void write_png_file(const std::string& root, const std::string& rel, const Image& image);
// The Nerfies camera JSON of a camera at `factor` (the inverse of read_nerfies_camera).
std::string nerfies_camera_json(const Camera& cam, int factor);
std::string split_file_json(const std::vector<DycheckFrame>& frames);
// A 0/1 mask [H][W] as a one-channel image (0 / 1.0).
Image mask_image(const std::uint8_t* mask, int width, int height);
// The writers' precondition: every per-frame array of `scene` has its frames' sizes; else
// DataError("<root>: the scene to write is inconsistent").
void check_scene_to_write(const std::string& root, const DycheckScene& scene);
// priors/features/<frame>.npy (float32 [h, w, C]) of every training frame with features.
void write_feature_files(const std::string& root, const DycheckScene& scene);

// tr sized for `frames` x `count` samples ([T][Q] uv, visible; [Q] query_t), all zero.
void size_tracks(DycheckTracks& tr, std::int64_t frames, std::int64_t count);

}  // namespace trainer::layout_io
