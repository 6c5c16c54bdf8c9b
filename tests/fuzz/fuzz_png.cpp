// tests/fuzz/fuzz_png.cpp — trainer::files::decode_png (libpng) with no expected size, only the
// pixel bound: the loosest limits any reader passes (every scene reader also fixes the size). The
// bound here is 2^22 pixels (16 MiB as RGBA), so that each run stays fast; the production bound
// is checked by the same code (image_size_problem) with a larger number.
#include <stdexcept>
#include <vector>

#include "fuzz_target.hpp"
#include "trainer/file_formats.hpp"

SMG_FUZZ_TARGET(png)(const std::uint8_t* data, std::size_t size) {
  trainer::files::ImageLimits limits;
  limits.max_pixels = std::uint64_t{1} << 22;
  try {
    (void)trainer::files::decode_png(std::vector<unsigned char>(data, data + size), "fuzz.png", limits);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
