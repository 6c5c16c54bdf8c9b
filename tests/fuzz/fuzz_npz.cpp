// tests/fuzz/fuzz_npz.cpp — trainer::files::parse_npz (priors/tracks.npz, MoSca's
// sensor_depth/*.npz and *bootstapir*.npz): ZIP structures, ZIP64, zlib's inflate, the bounds of
// the bounded inflater, then npy::parse of each member.
#include <vector>

#include "fuzz_target.hpp"
#include "npy.hpp"
#include "trainer/file_formats.hpp"

SMG_FUZZ_TARGET(npz)(const std::uint8_t* data, std::size_t size) {
  try {
    (void)trainer::files::parse_npz(std::vector<unsigned char>(data, data + size), "fuzz.npz");
  } catch (const npy::Error&) {
  }
  return 0;
}
