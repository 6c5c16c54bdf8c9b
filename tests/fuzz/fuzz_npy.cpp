// tests/fuzz/fuzz_npy.cpp — npy::parse (every .npy the trainer reads: depth, features, SoM's
// tracks and disparity, MoSca's epipolar error) and npy::declared_size (the npz inflater's check).
#include <string>

#include "fuzz_target.hpp"
#include "npy.hpp"

SMG_FUZZ_TARGET(npy)(const std::uint8_t* data, std::size_t size) {
  try {
    const npy::Array a = npy::parse(data, size, "fuzz.npy");
    if (npy::is_float(a.dtype)) (void)a.as<float>("fuzz.npy");
    else (void)a.as<std::int64_t>("fuzz.npy");
  } catch (const npy::Error&) {
  }
  try {
    (void)npy::declared_size(data, size, "fuzz.npy");
  } catch (const npy::Error&) {
  }
  return 0;
}
