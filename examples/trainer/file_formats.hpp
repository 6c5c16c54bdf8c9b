// examples/trainer/file_formats.hpp — the file formats of a scene on disk (docs/data.md) below
// the layout: whole-file reading, 8-bit PNG decoding (stb_image) and .npz archives (ZIP, as
// numpy.savez and numpy.savez_compressed write them; deflated members inflated by zlib).
//
// Every reading function takes a `label` (the file as the caller wants it named, e.g.
// "priors/tracks.npz") and throws std::runtime_error("<label>: <problem>") — npy::Error for the
// .npy and .npz parts — on anything it cannot read exactly.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "npy.hpp"

namespace trainer::files {

// The whole content of a regular file. Throws "<label>: file is missing" when nothing is at
// `path`, "<label>: not a regular file", or "<label>: cannot read".
std::vector<unsigned char> read_bytes(const std::string& path, const std::string& label);

// Pixels of an 8-bit PNG exactly as stored: [height][width][channels], channels 1 (grey),
// 2 (grey + alpha), 3 (RGB) or 4 (RGBA); a palette image comes as RGB(A).
struct Png8 {
  int width = 0, height = 0, channels = 0;
  std::vector<std::uint8_t> pixels;
};
// Decodes a PNG image held in memory; 16-bit PNGs and other formats are refused.
Png8 decode_png(const std::vector<unsigned char>& bytes, const std::string& label);

// CRC-32 (ISO 3309 / ZIP, polynomial 0xEDB88320; zlib's crc32) of n bytes, continuing from `crc`
// (0 to start).
std::uint32_t crc32(const unsigned char* data, std::size_t n, std::uint32_t crc = 0);

// The arrays of an .npz archive held in memory, keyed by member name without ".npy" ("uv"), each
// in C order (a Fortran-order member is transposed, npy.hpp). Members stored (method 0) or
// deflated (method 8, raw DEFLATE inflated by zlib, which must end exactly at the recorded
// uncompressed size); the CRC-32 of every member is checked; ZIP64 size and offset fields (and
// numpy's ZIP64 extra field in the local header) are followed. Encrypted members, other methods,
// members that are not .npy files, duplicate names and any inconsistency of the archive are
// errors "<label>: member '<name>': <problem>" or "<label>: <problem>".
std::map<std::string, npy::Array> parse_npz(const std::vector<unsigned char>& bytes, const std::string& label);

// An uncompressed .npz archive (every member stored, like numpy.savez) from (key, .npy file
// bytes) pairs; member k is named key + ".npy". Each member must stay below 4 GiB (no ZIP64).
std::string npz_bytes(const std::vector<std::pair<std::string, std::string>>& members);

}  // namespace trainer::files
