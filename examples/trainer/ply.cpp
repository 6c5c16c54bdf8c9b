// examples/trainer/ply.cpp — per-frame 3DGS PLY files (ply.hpp).
#include "trainer/ply.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "trainer/util.hpp"

namespace trainer {

namespace {

// The 17 properties, in 3DGS's order (GaussianModel.construct_list_of_attributes for degree 0).
constexpr const char* kPlyProperties[] = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                                          "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"};
constexpr int kPlyWidth = static_cast<int>(sizeof(kPlyProperties) / sizeof(kPlyProperties[0]));

// A float's four bytes, least significant first, whatever the host's byte order.
void put_le(float v, unsigned char* out) {
  std::uint32_t bits = 0;
  std::memcpy(&bits, &v, sizeof bits);
  for (int b = 0; b < 4; ++b) out[b] = static_cast<unsigned char>((bits >> (8 * b)) & 0xffu);
}

}  // namespace

void write_gaussians_ply(const std::string& path, const std::vector<float>& means, const std::vector<float>& quats,
                         const std::vector<float>& log_scales, const std::vector<float>& opacity,
                         const std::vector<float>& colors) {
  const std::size_t G = opacity.size();
  if (means.size() != 3 * G || quats.size() != 4 * G || log_scales.size() != 3 * G || colors.size() != 3 * G)
    throw std::invalid_argument("write_gaussians_ply: tables of different lengths for " + path);
  std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(G) + "\n";
  for (const char* p : kPlyProperties) header += std::string("property float ") + p + "\n";
  header += "end_header\n";
  std::vector<unsigned char> body(G * kPlyWidth * 4);
  for (std::size_t g = 0; g < G; ++g) {
    float row[kPlyWidth] = {};
    for (int k = 0; k < 3; ++k) row[k] = means[3 * g + k];  // x y z; nx ny nz stay 0
    for (int k = 0; k < 3; ++k) row[6 + k] = static_cast<float>((colors[3 * g + k] - 0.5) / kShC0);
    row[9] = opacity[g];
    for (int k = 0; k < 3; ++k) row[10 + k] = log_scales[3 * g + k];
    const double w = quats[4 * g], x = quats[4 * g + 1], y = quats[4 * g + 2], z = quats[4 * g + 3];
    const double n = std::sqrt(w * w + x * x + y * y + z * z);
    const double q[4] = {w, x, y, z};
    for (int k = 0; k < 4; ++k) row[13 + k] = n > 0 ? static_cast<float>(q[k] / n) : (k == 0 ? 1.0f : 0.0f);
    for (int k = 0; k < kPlyWidth; ++k) put_le(row[k], &body[(g * kPlyWidth + static_cast<std::size_t>(k)) * 4]);
  }
  std::ofstream f(path, std::ios::binary);
  f.write(header.data(), static_cast<std::streamsize>(header.size()));
  f.write(reinterpret_cast<const char*>(body.data()), static_cast<std::streamsize>(body.size()));
  if (!f) throw std::runtime_error("cannot write " + path);
}

std::vector<std::string> write_ply_frames(const std::string& out, const GaussianModel<float>& model,
                                          const Nodes& nodes) {
  const std::filesystem::path dir = std::filesystem::path(out) / "ply";
  std::filesystem::create_directories(dir);
  // The folder holds this run's frames only: frames of an earlier, longer run are removed.
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (name.rfind("frame_", 0) == 0 && e.path().extension() == ".ply") std::filesystem::remove(e.path());
  }
  NodeState<float> ns;
  ns.assign(nodes);
  std::vector<float> means, quats;
  std::vector<std::string> written;
  for (int t = 0; t < nodes.frames; ++t) {
    pose_model(model, ns, t, &means, &quats);
    const std::string path = (dir / ("frame_" + std::to_string(t) + ".ply")).string();
    write_gaussians_ply(path, means, quats, model.table.log_scales, model.table.opacity, model.table.colors);
    written.push_back(path);
  }
  return written;
}

}  // namespace trainer
