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

// Pixels of an 8-bit image: [height][width][channels], channels 1 (grey), 2 (grey + alpha),
// 3 (RGB) or 4 (RGBA); a palette PNG comes as RGB(A). A PNG's exactly as stored.
struct Pixels8 {
  int width = 0, height = 0, channels = 0;
  std::vector<std::uint8_t> pixels;
};
// Decodes a PNG image held in memory; 16-bit PNGs and other formats (JPEG included) are refused.
Pixels8 decode_png(const std::vector<unsigned char>& bytes, const std::string& label);
// Decodes a baseline or progressive JPEG held in memory (stb_image's decoder: within the usual
// one or two levels of libjpeg's integer IDCT); other formats are refused. Only readers of
// photographs use it (MoSca's images/): masks and maps stay lossless PNG.
Pixels8 decode_jpeg(const std::vector<unsigned char>& bytes, const std::string& label);
// Whether a file name ends in .jpg or .jpeg (any case): the readers that accept JPEG pick the
// decoder by the name, as MoSca's glob does.
bool is_jpeg_name(const std::string& name);

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
