// examples/trainer/file_formats.hpp — the file formats of a scene on disk (docs/data.md) below
// the layout: whole-file reading, 8-bit PNG decoding (libpng), JPEG decoding (libjpeg-turbo) and
// .npz archives (ZIP, as numpy.savez and numpy.savez_compressed write them; deflated members
// inflated by zlib). Every reader faces files that users bring: each size is checked before
// anything is allocated for it (docs/data.md, "Files from users").
//
// Every reading function takes a `label` (the file as the caller wants it named, e.g.
// "priors/tracks.npz") and throws std::runtime_error("<label>: <problem>") — npy::Error for the
// .npy and .npz parts — on anything it cannot read exactly.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
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
// 3 (RGB) or 4 (RGBA); a palette PNG comes as RGB(A), a PNG's tRNS colour as an alpha channel.
struct Pixels8 {
  int width = 0, height = 0, channels = 0;
  std::vector<std::uint8_t> pixels;
};

// The most pixels (width x height) an image may have: 2^26 = 67 108 864 (8192 x 8192; 256 MiB as
// RGBA 8-bit), far above any camera the trainer reads (Dycheck's iPhone frames are 720 x 960 at 1x).
constexpr std::uint64_t kMaxImagePixels = std::uint64_t{1} << 26;

// What the caller knows of an image before decoding it. The decoders read the header first and
// refuse an image whose width x height is not one of `sizes` (when given), or has more than
// `max_pixels` pixels, before a pixel buffer is allocated: a 300-byte file cannot claim gigabytes.
struct ImageLimits {
  std::vector<std::pair<int, int>> sizes;  // allowed {width, height}; empty: any within max_pixels
  std::string expected;                    // the refusal's tail after "image is WxH, " (empty:
                                           // "expected WxH" from `sizes`)
  std::uint64_t max_pixels = kMaxImagePixels;
};
// Limits for exactly one size.
ImageLimits image_of_size(int width, int height, std::string expected = {});

// Decodes an 8-bit PNG held in memory with libpng; 16-bit PNGs and other formats (JPEG included)
// are refused, as is any libpng error or a file that ends early: "<label>: corrupt PNG (libpng:
// ...)". libpng's warnings (a bad ancillary chunk) are not printed; the image is read.
Pixels8 decode_png(const std::vector<unsigned char>& bytes, const std::string& label, const ImageLimits& limits = {});
// Decodes a baseline or progressive JPEG held in memory with libjpeg-turbo (integer IDCT, as
// `djpeg -dct int`): grey gives 1 channel, colour 3; CMYK is refused. libjpeg's errors are
// refused ("<label>: corrupt JPEG (libjpeg: ...)"), as are more than 1000 scans and a file that
// ends early (libjpeg's "Premature end of JPEG file" warning: it would fill the rest with grey).
// Its other warnings (data it reads past, such as stray bytes before a marker) do not stop it, as
// djpeg, Pillow and OpenCV read past them: the image is read and one line goes to `notes` (nullptr:
// none), "[data] <label>: libjpeg warning: <the first> [(and N more)] (read anyway)".
// Only readers of photographs use it (MoSca's images/): masks and maps stay lossless PNG.
Pixels8 decode_jpeg(const std::vector<unsigned char>& bytes, const std::string& label, const ImageLimits& limits = {},
                    std::FILE* notes = stderr);
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
// Bounds, checked before a member's buffer is allocated (a deflate bomb is refused, not inflated):
// a deflated member's recorded size at most 1032 x its compressed size + 1 KiB (DEFLATE's largest
// ratio) and at most kMaxNpzMemberBytes; the recorded size equal to what the member's own .npy
// header (inflated first) declares; the output never grows past the recorded size.
constexpr std::uint64_t kMaxNpzMemberBytes = std::uint64_t{1} << 32;  // 4 GiB
std::map<std::string, npy::Array> parse_npz(const std::vector<unsigned char>& bytes, const std::string& label);

// An uncompressed .npz archive (every member stored, like numpy.savez) from (key, .npy file
// bytes) pairs; member k is named key + ".npy". Each member must stay below 4 GiB (no ZIP64).
std::string npz_bytes(const std::vector<std::pair<std::string, std::string>>& members);

}  // namespace trainer::files
