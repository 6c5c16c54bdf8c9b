// The 3DGS PLY writer (examples/trainer/ply.hpp): the header of the original 3DGS code, 17
// little-endian floats per Gaussian, colours as SH degree 0, opacity and scales as stored,
// unit quaternions (w, x, y, z). Third-party readers of a trainer run: tests/pipeline/
// test_ply_readers.py (numpy as 3DGS, meshio) and tests/ply_viewer (a 3DGS viewer from npm).
#include <doctest/doctest.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "trainer/ply.hpp"

namespace {

float ply_le_float(const std::vector<unsigned char>& bytes, std::size_t at) {
  std::uint32_t bits = 0;
  for (int b = 0; b < 4; ++b) bits |= static_cast<std::uint32_t>(bytes[at + static_cast<std::size_t>(b)]) << (8 * b);
  float v = 0;
  std::memcpy(&v, &bits, sizeof v);
  return v;
}

}  // namespace

TEST_CASE("write_gaussians_ply: 3DGS's header and rows") {
  const std::vector<float> means = {1, 2, 3, -4, 5.5f, 6};
  const std::vector<float> quats = {2, 0, 0, 0, 0, 3, 0, 4};  // normalised on write
  const std::vector<float> log_scales = {-3, -2.5f, -2, 0.5f, 0, -1};
  const std::vector<float> opacity = {0.25f, -7};
  const std::vector<float> colors = {0.5f, 1, 0, 0.2f, 0.4f, 0.9f};
  const std::filesystem::path path = std::filesystem::temp_directory_path() / "smg_test_ply_writer.ply";
  trainer::write_gaussians_ply(path.string(), means, quats, log_scales, opacity, colors);
  std::ifstream f(path, std::ios::binary);
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  std::filesystem::remove(path);

  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 2\n"
      "property float x\nproperty float y\nproperty float z\n"
      "property float nx\nproperty float ny\nproperty float nz\n"
      "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\n"
      "property float scale_0\nproperty float scale_1\nproperty float scale_2\n"
      "property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\n";
  REQUIRE(bytes.size() == header.size() + 2 * 17 * 4);
  CHECK(std::string(bytes.begin(), bytes.begin() + static_cast<long>(header.size())) == header);
  const auto at = [&](int row, int col) { return ply_le_float(bytes, header.size() + 4u * (17u * row + col)); };
  for (int g = 0; g < 2; ++g) {
    for (int k = 0; k < 3; ++k) {
      CHECK(at(g, k) == means[3 * g + k]);
      CHECK(at(g, 3 + k) == 0.0f);
      // 3DGS's colour of degree 0: C0 * f_dc + 0.5
      CHECK(trainer::kShC0 * at(g, 6 + k) + 0.5 == doctest::Approx(colors[3 * g + k]).epsilon(1e-6));
      CHECK(at(g, 10 + k) == log_scales[3 * g + k]);
    }
    CHECK(at(g, 9) == opacity[g]);
  }
  CHECK(at(0, 6) == 0.0f);  // rgb 0.5 is f_dc 0
  const float q0[4] = {1, 0, 0, 0}, q1[4] = {0, 0.6f, 0, 0.8f};
  for (int k = 0; k < 4; ++k) {
    CHECK(at(0, 13 + k) == doctest::Approx(q0[k]).epsilon(1e-7));
    CHECK(at(1, 13 + k) == doctest::Approx(q1[k]).epsilon(1e-7));
  }
  CHECK_THROWS_AS(trainer::write_gaussians_ply(path.string(), means, quats, log_scales, {0.0f}, colors),
                  std::invalid_argument);
}
