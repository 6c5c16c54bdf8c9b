// examples/trainer/file_formats.cpp — whole files, PNG decoding, .npz archives.
//
// The one translation unit of the trainer library that compiles stb_image (Debian's
// libstb-dev), static, for PNG and JPEG decoding only. The compressed members of an .npz archive are
// inflated by zlib (Debian's zlib1g-dev), the reference implementation of DEFLATE that numpy's
// own writer (Python's zipfile) uses. ZIP structures: PKWARE APPNOTE.TXT sections 4.3 and 4.5.
#include "trainer/file_formats.hpp"

#if !__has_include(<stb/stb_image.h>)
#error "the example trainer needs stb_image.h (Debian: apt-get install libstb-dev)"
#endif

#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#define STBI_ONLY_PNG
#define STBI_ONLY_JPEG
#include <stb/stb_image.h>

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <climits>
#include <initializer_list>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>

namespace trainer::files {

std::vector<unsigned char> read_bytes(const std::string& path, const std::string& label) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) throw std::runtime_error(label + ": file is missing");
  if (!fs::is_regular_file(st)) throw std::runtime_error(label + ": not a regular file");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error(label + ": cannot open");
  std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (f.bad()) throw std::runtime_error(label + ": cannot read");
  return bytes;
}

namespace {

// stb decodes whichever format it finds: the signature decides first, so that a PNG reader never
// takes a JPEG (and the reverse).
bool starts_with(const std::vector<unsigned char>& b, std::initializer_list<unsigned char> sig) {
  return b.size() >= sig.size() && std::equal(sig.begin(), sig.end(), b.begin());
}

Pixels8 decode_8bit(const std::vector<unsigned char>& bytes, const std::string& label, const char* format) {
  if (bytes.size() > static_cast<std::size_t>(INT_MAX)) throw std::runtime_error(label + ": file too large");
  const auto* data = reinterpret_cast<const stbi_uc*>(bytes.data());
  const int len = static_cast<int>(bytes.size());
  int w = 0, h = 0, c = 0;
  if (!stbi_info_from_memory(data, len, &w, &h, &c))
    throw std::runtime_error(label + ": not a " + format + " image (" + stbi_failure_reason() + ")");
  if (stbi_is_16_bit_from_memory(data, len)) throw std::runtime_error(label + ": 16-bit " + format + " (8-bit expected)");
  std::unique_ptr<stbi_uc, void (*)(void*)> pixels(stbi_load_from_memory(data, len, &w, &h, &c, 0), stbi_image_free);
  if (!pixels) throw std::runtime_error(label + ": corrupt " + format + " (" + stbi_failure_reason() + ")");
  Pixels8 out;
  out.width = w;
  out.height = h;
  out.channels = c;
  out.pixels.assign(pixels.get(), pixels.get() + static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * static_cast<std::size_t>(c));
  return out;
}

}  // namespace

Pixels8 decode_png(const std::vector<unsigned char>& bytes, const std::string& label) {
  if (!starts_with(bytes, {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'}))
    throw std::runtime_error(label + ": not a PNG image (no PNG signature)");
  return decode_8bit(bytes, label, "PNG");
}

Pixels8 decode_jpeg(const std::vector<unsigned char>& bytes, const std::string& label) {
  if (!starts_with(bytes, {0xff, 0xd8, 0xff})) throw std::runtime_error(label + ": not a JPEG image (no JPEG start-of-image marker)");
  return decode_8bit(bytes, label, "JPEG");
}

bool is_jpeg_name(const std::string& name) {
  std::string ext = name.substr(name.find_last_of('.') == std::string::npos ? name.size() : name.find_last_of('.'));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  return ext == ".jpg" || ext == ".jpeg";
}

std::uint32_t crc32(const unsigned char* data, std::size_t n, std::uint32_t crc) {
  // zlib's crc32 takes an unsigned int count: feed it in chunks.
  uLong c = crc;
  while (n > 0) {
    const uInt chunk = static_cast<uInt>(std::min<std::size_t>(n, UINT_MAX));
    c = ::crc32(c, data, chunk);
    data += chunk;
    n -= chunk;
  }
  return static_cast<std::uint32_t>(c);
}

namespace {

// Little-endian reads with bounds checks against the whole archive.
class Reader {
 public:
  Reader(const std::vector<unsigned char>& b, const std::string& label) : b_(b), label_(label) {}
  [[noreturn]] void fail(const std::string& what) const { throw npy::Error(label_ + ": " + what); }
  void need(std::uint64_t at, std::uint64_t n, const char* what) const {
    if (at > b_.size() || n > b_.size() - at) fail(std::string("truncated archive (") + what + " past the end)");
  }
  std::uint64_t u(std::uint64_t at, int bytes) const {
    need(at, static_cast<std::uint64_t>(bytes), "field");
    std::uint64_t v = 0;
    for (int k = bytes - 1; k >= 0; --k) v = (v << 8) | b_[static_cast<std::size_t>(at) + static_cast<std::size_t>(k)];
    return v;
  }
  std::size_t size() const { return b_.size(); }
  const unsigned char* at(std::uint64_t p) const { return b_.data() + p; }

 private:
  const std::vector<unsigned char>& b_;
  const std::string& label_;
};

// The raw DEFLATE stream (RFC 1951, no zlib header: windowBits -15) of member `name`, `csize`
// bytes at `in`, inflated by zlib into exactly `usize` bytes. The stream must end (Z_STREAM_END)
// within the compressed bytes and give exactly the recorded size; bytes after its end are
// ignored, as Python's zipfile does. Every failure names the member.
std::vector<unsigned char> inflate_member(const Reader& r, const std::string& name, const unsigned char* in,
                                          std::uint64_t csize, std::uint64_t usize) {
  // One spare output byte tells "more data than recorded" from "exactly the recorded size".
  std::vector<unsigned char> out(static_cast<std::size_t>(usize) + 1);
  z_stream zs{};
  if (inflateInit2(&zs, -15) != Z_OK) r.fail("cannot start zlib's inflate for member '" + name + "'");
  std::uint64_t in_left = csize, out_left = out.size();
  zs.next_in = const_cast<Bytef*>(in);  // zlib's API is not const; it never writes the input
  zs.next_out = out.data();
  std::string problem;
  for (;;) {
    // zlib counts in unsigned int: hand it the buffers in chunks.
    if (zs.avail_in == 0 && in_left > 0) {
      zs.avail_in = static_cast<uInt>(std::min<std::uint64_t>(in_left, UINT_MAX));
      in_left -= zs.avail_in;
    }
    if (zs.avail_out == 0 && out_left > 0) {
      zs.avail_out = static_cast<uInt>(std::min<std::uint64_t>(out_left, UINT_MAX));
      out_left -= zs.avail_out;
    }
    const int ret = inflate(&zs, Z_NO_FLUSH);
    if (ret == Z_STREAM_END) break;
    if (ret == Z_OK) continue;  // progress; go on
    if (ret == Z_BUF_ERROR && zs.avail_out == 0 && out_left == 0)
      problem = "decompresses to more than the recorded " + std::to_string(usize) + " bytes";
    else if (ret == Z_BUF_ERROR && zs.avail_in == 0 && in_left == 0)
      problem = "deflate data ends early (truncated member)";
    else if (ret == Z_DATA_ERROR)
      problem = std::string("corrupt deflate data (zlib: ") + (zs.msg ? zs.msg : "invalid stream") + ")";
    else if (ret == Z_MEM_ERROR)
      problem = "out of memory while inflating";
    else
      problem = "zlib's inflate failed (code " + std::to_string(ret) + ")";
    break;
  }
  const std::uint64_t produced = zs.total_out;
  inflateEnd(&zs);
  if (problem.empty() && produced != usize)
    problem = produced > usize ? "decompresses to more than the recorded " + std::to_string(usize) + " bytes"
                               : "decompresses to " + std::to_string(produced) + " bytes, the archive records " +
                                     std::to_string(usize);
  if (!problem.empty()) r.fail("member '" + name + "': " + problem);
  out.pop_back();
  return out;
}

constexpr std::uint32_t kLocalSig = 0x04034b50, kCentralSig = 0x02014b50, kEndSig = 0x06054b50;
constexpr std::uint32_t kZip64EndSig = 0x06064b50, kZip64LocatorSig = 0x07064b50;

}  // namespace

std::map<std::string, npy::Array> parse_npz(const std::vector<unsigned char>& bytes, const std::string& label) {
  const Reader r(bytes, label);
  // End of central directory record: the last signature within 22 + 65535 bytes of the end.
  if (bytes.size() < 22) r.fail("not an .npz archive (too short for a ZIP file)");
  std::uint64_t eocd = UINT64_MAX;
  const std::uint64_t lowest = bytes.size() > 22 + 65535 ? bytes.size() - 22 - 65535 : 0;
  for (std::uint64_t p = bytes.size() - 22 + 1; p-- > lowest;)
    if (r.u(p, 4) == kEndSig && p + 22 + r.u(p + 20, 2) == bytes.size()) {
      eocd = p;
      break;
    }
  if (eocd == UINT64_MAX) {
    if (bytes.size() >= 4 && r.u(0, 4) == kLocalSig) r.fail("truncated archive (no end of central directory)");
    r.fail("not an .npz archive (no ZIP end of central directory)");
  }
  if (r.u(eocd + 4, 2) != 0 || r.u(eocd + 6, 2) != 0) r.fail("multi-disk archives are not supported");
  std::uint64_t entries = r.u(eocd + 10, 2), cd_size = r.u(eocd + 12, 4), cd_offset = r.u(eocd + 16, 4);
  if (entries == 0xFFFF || cd_size == 0xFFFFFFFF || cd_offset == 0xFFFFFFFF) {
    if (eocd < 20 || r.u(eocd - 20, 4) != kZip64LocatorSig) r.fail("corrupt archive (ZIP64 locator missing)");
    const std::uint64_t z = r.u(eocd - 20 + 8, 8);
    if (r.u(z, 4) != kZip64EndSig) r.fail("corrupt archive (bad ZIP64 end of central directory)");
    entries = r.u(z + 32, 8);
    cd_size = r.u(z + 40, 8);
    cd_offset = r.u(z + 48, 8);
  }
  r.need(cd_offset, cd_size, "central directory");

  std::map<std::string, npy::Array> out;
  std::uint64_t p = cd_offset;
  for (std::uint64_t e = 0; e < entries; ++e) {
    if (r.u(p, 4) != kCentralSig) r.fail("corrupt archive (bad central directory entry " + std::to_string(e) + ")");
    const std::uint64_t flags = r.u(p + 8, 2), method = r.u(p + 10, 2), crc = r.u(p + 16, 4);
    std::uint64_t csize = r.u(p + 20, 4), usize = r.u(p + 24, 4), local = r.u(p + 42, 4);
    const std::uint64_t name_len = r.u(p + 28, 2), extra_len = r.u(p + 30, 2), comment_len = r.u(p + 32, 2);
    r.need(p + 46, name_len + extra_len + comment_len, "central directory entry");
    const std::string name(reinterpret_cast<const char*>(r.at(p + 46)), static_cast<std::size_t>(name_len));
    // ZIP64 extended information (header 0x0001): the 64-bit values of the fields set to all ones.
    for (std::uint64_t x = p + 46 + name_len; x + 4 <= p + 46 + name_len + extra_len;) {
      const std::uint64_t id = r.u(x, 2), len = r.u(x + 2, 2);
      if (x + 4 + len > p + 46 + name_len + extra_len) r.fail("corrupt archive (extra field of '" + name + "')");
      if (id == 0x0001) {
        std::uint64_t q = x + 4;
        const std::uint64_t end = q + len;
        auto take = [&](std::uint64_t& field) {
          if (field != 0xFFFFFFFF) return;
          if (q + 8 > end) r.fail("corrupt archive (short ZIP64 field of '" + name + "')");
          field = r.u(q, 8);
          q += 8;
        };
        take(usize);
        take(csize);
        take(local);
      }
      x += 4 + len;
    }
    p += 46 + name_len + extra_len + comment_len;

    const std::string what = label + " member '" + name + "'";
    if (flags & 1u) r.fail("member '" + name + "' is encrypted");
    if (method != 0 && method != 8)
      r.fail("member '" + name + "' uses compression method " + std::to_string(method) + " (only stored and deflate are supported)");
    if (name.size() < 5 || name.compare(name.size() - 4, 4, ".npy") != 0) r.fail("member '" + name + "' is not an .npy file");
    const std::string key = name.substr(0, name.size() - 4);
    if (out.count(key)) r.fail("duplicate member '" + name + "'");

    if (r.u(local, 4) != kLocalSig) r.fail("corrupt archive (bad local header of '" + name + "')");
    const std::uint64_t data_at = local + 30 + r.u(local + 26, 2) + r.u(local + 28, 2);
    r.need(data_at, csize, "member data");
    std::vector<unsigned char> data;
    if (method == 0) {
      if (csize != usize) r.fail("corrupt archive (stored member '" + name + "' with different sizes)");
      data.assign(r.at(data_at), r.at(data_at) + csize);
    } else {
      // DEFLATE expands at most ~1032:1, so a larger recorded size is a corrupt field; checking it
      // first keeps a flipped size byte from allocating gigabytes before the decoder fails.
      if (usize > 1032 * csize + 1024)
        r.fail("corrupt archive (member '" + name + "' records " + std::to_string(usize) + " bytes from " +
               std::to_string(csize) + " compressed)");
      data = inflate_member(r, name, r.at(data_at), csize, usize);
    }
    if (crc32(data.data(), data.size()) != crc) r.fail("CRC-32 mismatch in member '" + name + "' (corrupt archive)");
    out.emplace(key, npy::parse(data.data(), data.size(), what));
  }
  return out;
}

namespace {
void put(std::string& s, std::uint64_t v, int bytes) {
  for (int k = 0; k < bytes; ++k) s += static_cast<char>((v >> (8 * k)) & 0xFFu);
}
}  // namespace

std::string npz_bytes(const std::vector<std::pair<std::string, std::string>>& members) {
  std::string out, central;
  for (const auto& [key, data] : members) {
    const std::string name = key + ".npy";
    if (data.size() >= 0xFFFFFFFFu || out.size() >= 0xFFFFFFFFu)
      throw std::runtime_error("npz: member '" + name + "' too large for an archive without ZIP64");
    const std::uint32_t crc = crc32(reinterpret_cast<const unsigned char*>(data.data()), data.size());
    const std::uint64_t offset = out.size();
    // Local file header: version 2.0, no flags, stored, 1980-01-01 00:00.
    put(out, kLocalSig, 4);
    put(out, 20, 2);
    put(out, 0, 2);
    put(out, 0, 2);
    put(out, 0, 2);
    put(out, 0x21, 2);
    put(out, crc, 4);
    put(out, data.size(), 4);
    put(out, data.size(), 4);
    put(out, name.size(), 2);
    put(out, 0, 2);
    out += name;
    out += data;
    // Its central directory entry.
    put(central, kCentralSig, 4);
    put(central, 20, 2);  // made by: MS-DOS attributes, version 2.0
    put(central, 20, 2);
    put(central, 0, 2);
    put(central, 0, 2);
    put(central, 0, 2);
    put(central, 0x21, 2);
    put(central, crc, 4);
    put(central, data.size(), 4);
    put(central, data.size(), 4);
    put(central, name.size(), 2);
    put(central, 0, 2);  // extra
    put(central, 0, 2);  // comment
    put(central, 0, 2);  // disk
    put(central, 0, 2);  // internal attributes
    put(central, 0, 4);  // external attributes
    put(central, offset, 4);
    central += name;
  }
  if (members.size() >= 0xFFFF || out.size() >= 0xFFFFFFFFu)
    throw std::runtime_error("npz: archive too large for a ZIP file without ZIP64");
  const std::uint64_t cd_offset = out.size();
  out += central;
  put(out, kEndSig, 4);
  put(out, 0, 2);
  put(out, 0, 2);
  put(out, members.size(), 2);
  put(out, members.size(), 2);
  put(out, central.size(), 4);
  put(out, cd_offset, 4);
  put(out, 0, 2);
  return out;
}

}  // namespace trainer::files
