// examples/trainer/colmap_model.cpp — COLMAP's binary sparse model (colmap_model.hpp).
#include "trainer/colmap_model.hpp"

#include <cmath>
#include <cstring>
#include <type_traits>

namespace trainer::colmap {

namespace {

struct ModelInfo {
  const char* name;
  int params;
};
// COLMAP's models in id order (src/colmap/sensor/models.h).
constexpr ModelInfo kModels[] = {
    {"SIMPLE_PINHOLE", 3}, {"PINHOLE", 4},  {"SIMPLE_RADIAL", 4},         {"RADIAL", 5},
    {"OPENCV", 8},         {"OPENCV_FISHEYE", 8}, {"FULL_OPENCV", 12},   {"FOV", 5},
    {"SIMPLE_RADIAL_FISHEYE", 4}, {"RADIAL_FISHEYE", 5}, {"THIN_PRISM_FISHEYE", 12},
    {"RAD_TAN_THIN_PRISM_FISHEYE", 16}};
constexpr int kModelCount = static_cast<int>(sizeof kModels / sizeof kModels[0]);

// Little-endian reads with a bounds check on every one (the host is little-endian: the trainer
// reads .npy files the same way; npy.hpp checks it).
class Reader {
 public:
  explicit Reader(const std::vector<unsigned char>& b) : b_(b) {}
  template <class T>
  T get(const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (pos_ > b_.size() || b_.size() - pos_ < sizeof(T))
      throw FormatError(std::string("truncated at byte ") + std::to_string(pos_) + " (reading " + what + ")");
    T v;
    std::memcpy(&v, b_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  void skip(std::uint64_t n, const char* what) {
    if (n > b_.size() - pos_)
      throw FormatError(std::string("truncated at byte ") + std::to_string(pos_) + " (reading " + what + ")");
    pos_ += static_cast<std::size_t>(n);
  }
  std::string cstring(const char* what) {
    const std::size_t start = pos_;
    while (pos_ < b_.size() && b_[pos_] != 0) ++pos_;
    if (pos_ == b_.size())
      throw FormatError(std::string("truncated at byte ") + std::to_string(start) + " (reading " + what + ")");
    std::string s(reinterpret_cast<const char*>(b_.data() + start), pos_ - start);
    ++pos_;  // the '\0'
    return s;
  }
  void expect_end() const {
    if (pos_ != b_.size())
      throw FormatError(std::to_string(b_.size() - pos_) + " bytes after the last record");
  }
  std::size_t pos() const { return pos_; }

 private:
  const std::vector<unsigned char>& b_;
  std::size_t pos_ = 0;
};

template <class T>
void put(std::string& out, T v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof(T));
}

double finite(double v, const std::string& what) {
  if (!std::isfinite(v)) throw FormatError(what + " is not finite");
  return v;
}

}  // namespace

const char* model_name(int id) { return id >= 0 && id < kModelCount ? kModels[id].name : nullptr; }
int model_param_count(int id) { return id >= 0 && id < kModelCount ? kModels[id].params : -1; }

namespace {

// A COLMAP binary file: a uint64 count of records of at least `min_bytes` each (a count beyond
// the file is a corrupt header, refused before anything is allocated), each record read by
// `one`, and nothing after the last. Both files have this frame; only their records differ.
template <class Record, class ReadOne>
std::vector<Record> parse_records(const std::vector<unsigned char>& bytes, const char* what, std::size_t min_bytes,
                                  ReadOne one) {
  Reader r(bytes);
  const std::uint64_t n = r.get<std::uint64_t>(("the " + std::string(what) + " count").c_str());
  if (n > bytes.size() / min_bytes)
    throw FormatError(std::string(what) + " count " + std::to_string(n) + " does not fit the file");
  std::vector<Record> out;
  for (std::uint64_t k = 0; k < n; ++k) out.push_back(one(r));
  r.expect_end();
  return out;
}

}  // namespace

std::vector<CameraRecord> parse_cameras(const std::vector<unsigned char>& bytes) {
  // Each camera takes at least 24 bytes.
  return parse_records<CameraRecord>(bytes, "camera", 24, [](Reader& r) {
    CameraRecord c;
    c.id = r.get<std::int32_t>("camera_id");
    c.model_id = r.get<std::int32_t>("model_id");
    c.width = r.get<std::uint64_t>("width");
    c.height = r.get<std::uint64_t>("height");
    const int np = model_param_count(c.model_id);
    const std::string who = "camera " + std::to_string(c.id);
    if (np < 0) throw FormatError(who + ": unknown camera model id " + std::to_string(c.model_id));
    for (int p = 0; p < np; ++p) c.params.push_back(finite(r.get<double>("params"), who + " parameter " + std::to_string(p)));
    return c;
  });
}

std::vector<ImageRecord> parse_images(const std::vector<unsigned char>& bytes) {
  // Each image takes at least 4 + 56 + 4 + 1 + 8 bytes.
  return parse_records<ImageRecord>(bytes, "image", 73, [&bytes](Reader& r) {
    ImageRecord im;
    im.id = r.get<std::int32_t>("image_id");
    const std::string who = "image " + std::to_string(im.id);
    for (double& q : im.qvec) q = finite(r.get<double>("qvec"), who + " qvec");
    for (double& t : im.tvec) t = finite(r.get<double>("tvec"), who + " tvec");
    im.camera_id = r.get<std::int32_t>("camera_id");
    im.name = r.cstring("the image name");
    const std::uint64_t points = r.get<std::uint64_t>("the 2D point count");
    if (points > (bytes.size() - r.pos()) / 24) throw FormatError(who + ": 2D point count " + std::to_string(points) + " does not fit the file");
    r.skip(points * 24, "2D points");
    return im;
  });
}

namespace {

// The writers' side of parse_records: the uint64 count, then each record written by `one`.
template <class Record, class PutOne>
std::string records_bytes(const std::vector<Record>& records, PutOne one) {
  std::string out;
  put<std::uint64_t>(out, records.size());
  for (const Record& rec : records) one(out, rec);
  return out;
}

}  // namespace

std::string cameras_bytes(const std::vector<CameraRecord>& cameras) {
  return records_bytes(cameras, [](std::string& out, const CameraRecord& c) {
    put<std::int32_t>(out, c.id);
    put<std::int32_t>(out, c.model_id);
    put<std::uint64_t>(out, c.width);
    put<std::uint64_t>(out, c.height);
    for (double p : c.params) put<double>(out, p);
  });
}

std::string images_bytes(const std::vector<ImageRecord>& images) {
  return records_bytes(images, [](std::string& out, const ImageRecord& im) {
    put<std::int32_t>(out, im.id);
    for (double q : im.qvec) put<double>(out, q);
    for (double t : im.tvec) put<double>(out, t);
    put<std::int32_t>(out, im.camera_id);
    out += im.name;
    out += '\0';
    put<std::uint64_t>(out, 0);  // no 2D points
  });
}

}  // namespace trainer::colmap
