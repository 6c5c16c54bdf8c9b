// examples/trainer/colmap_model.hpp — COLMAP's binary sparse model, the two files
// Shape-of-Motion's refined cameras come from (flow3d_preprocessed/colmap/sparse/{cameras,images}.bin;
// layout_som.cpp reads them, its writer writes them). Our own code, following COLMAP's format
// (src/colmap/scene/reconstruction_io.cc, Read/WriteCamerasBinary and Read/WriteImagesBinary; the
// same as scripts/python/read_write_model.py), little-endian throughout:
//
//   cameras.bin  uint64 count; per camera: int32 camera_id, int32 model_id, uint64 width,
//                uint64 height, double params[n(model_id)]
//   images.bin   uint64 count; per image: int32 image_id, double qvec[4] (w, x, y, z: world ->
//                camera), double tvec[3], int32 camera_id, the name's bytes and a '\0', uint64
//                points2D, then points2D x (double x, double y, int64 point3D_id)
//
// Parsing checks every length against the bytes (a truncated or padded file is an error), the
// model id against COLMAP's table, and finiteness; the caller names the file in its message.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace trainer::colmap {

// A problem in a model file; what() is the problem only (the caller adds the file).
class FormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct CameraRecord {
  int id = 0;
  int model_id = 0;
  std::uint64_t width = 0, height = 0;  // pixels of the images COLMAP was given
  std::vector<double> params;           // as many as the model takes (model_param_count)
};

struct ImageRecord {
  int id = 0;
  double qvec[4] = {1, 0, 0, 0};  // w, x, y, z: the rotation world -> camera
  double tvec[3] = {0, 0, 0};     // world -> camera translation
  int camera_id = 0;
  std::string name;               // the image file's name, e.g. "0_00000.png"
};

// COLMAP's camera models by id (0 SIMPLE_PINHOLE ... 11 RAD_TAN_THIN_PRISM_FISHEYE): the name,
// or nullptr for an unknown id, and the number of parameters (-1 for an unknown id).
const char* model_name(int model_id);
int model_param_count(int model_id);

// Parse the bytes of cameras.bin / images.bin. Throws FormatError.
std::vector<CameraRecord> parse_cameras(const std::vector<unsigned char>& bytes);
std::vector<ImageRecord> parse_images(const std::vector<unsigned char>& bytes);

// The bytes of cameras.bin / images.bin (images without 2D points).
std::string cameras_bytes(const std::vector<CameraRecord>& cameras);
std::string images_bytes(const std::vector<ImageRecord>& images);

}  // namespace trainer::colmap
