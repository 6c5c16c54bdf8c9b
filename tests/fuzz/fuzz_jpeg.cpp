// tests/fuzz/fuzz_jpeg.cpp — trainer::files::decode_jpeg (libjpeg-turbo; MoSca's images/*.jpg)
// with no expected size, only the pixel bound: the loosest limits any reader passes (every scene reader also fixes the size). The
// bound here is 2^22 pixels (12 MiB as RGB), so that each run stays fast; the production bound
// is checked by the same code (image_size_problem) with a larger number.
#include <stdexcept>
#include <vector>

#include "fuzz_target.hpp"
#include "trainer/file_formats.hpp"

SMG_FUZZ_TARGET(jpeg)(const std::uint8_t* data, std::size_t size) {
  trainer::files::ImageLimits limits;
  limits.max_pixels = std::uint64_t{1} << 22;
  try {
    // No notes: a libjpeg warning read through would print one line per input.
    (void)trainer::files::decode_jpeg(std::vector<unsigned char>(data, data + size), "fuzz.jpg", limits, nullptr);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
