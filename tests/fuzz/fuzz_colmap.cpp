// tests/fuzz/fuzz_colmap.cpp — COLMAP's binary model (Shape-of-Motion's
// flow3d_preprocessed/colmap/sparse/): the same bytes as cameras.bin and as images.bin.
#include <vector>

#include "fuzz_target.hpp"
#include "trainer/colmap_model.hpp"

SMG_FUZZ_TARGET(colmap)(const std::uint8_t* data, std::size_t size) {
  const std::vector<unsigned char> bytes(data, data + size);
  try {
    (void)trainer::colmap::parse_cameras(bytes);
  } catch (const trainer::colmap::FormatError&) {
  }
  try {
    (void)trainer::colmap::parse_images(bytes);
  } catch (const trainer::colmap::FormatError&) {
  }
  return 0;
}
