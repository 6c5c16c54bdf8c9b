// examples/trainer/file_formats.cpp — whole files, PNG and JPEG decoding, .npz archives.
//
// Every function here reads bytes that a user brought (docs/data.md, "Files from users"): sizes
// are checked before anything is allocated for them, and every failure is one line naming the
// file (and the member). PNG is decoded by libpng (Debian's libpng-dev) and JPEG by libjpeg-turbo
// (Debian's libjpeg62-turbo-dev): both are maintained, fuzzed continuously upstream (OSS-Fuzz) and
// kept patched by Debian, where stb_image, used before, says of itself that it is not meant for
// untrusted files (a crafted JPEG wrote out of bounds in it, a 307-byte PNG made it allocate
// 1 GB: tests/fuzz/corpus/). The compressed members of an .npz archive are inflated by zlib
// (Debian's zlib1g-dev), the reference implementation of DEFLATE that numpy's own writer
// (Python's zipfile) uses. ZIP structures: PKWARE APPNOTE.TXT sections 4.3 and 4.5.
//
// libpng and libjpeg report errors by longjmp (their C API): each decoder keeps everything with a
// destructor in a state object owned by its caller, and the function that calls setjmp holds no
// such object, so a longjmp skips nothing that needed destroying.
#include "trainer/file_formats.hpp"

#include "cli_args.hpp"  // cli::escape_line

#include <png.h>
#include <zlib.h>

#include <cstdio>  // jpeglib.h needs FILE and size_t declared first
#include <jpeglib.h>
#include <jerror.h>  // the message codes (JWRN_JPEG_EOF)

#include <algorithm>
#include <cctype>
#include <climits>
#include <csetjmp>
#include <initializer_list>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>

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

ImageLimits image_of_size(int width, int height, std::string expected) {
  ImageLimits l;
  l.sizes.emplace_back(width, height);
  l.expected = std::move(expected);
  return l;
}

namespace {

// The signature decides first, so that a PNG reader never takes a JPEG (and the reverse).
bool starts_with(const std::vector<unsigned char>& b, std::initializer_list<unsigned char> sig) {
  return b.size() >= sig.size() && std::equal(sig.begin(), sig.end(), b.begin());
}

std::string size_text(std::uint64_t w, std::uint64_t h) { return std::to_string(w) + "x" + std::to_string(h); }

// The header's width x height against the caller's limits: "" when admitted, else the problem.
std::string image_size_problem(std::uint64_t w, std::uint64_t h, const ImageLimits& limits) {
  if (w == 0 || h == 0) return "image is " + size_text(w, h) + " (empty)";
  bool listed = limits.sizes.empty();
  for (const auto& [sw, sh] : limits.sizes) listed = listed || (static_cast<std::uint64_t>(sw) == w && static_cast<std::uint64_t>(sh) == h);
  if (!listed) {
    if (!limits.expected.empty()) return "image is " + size_text(w, h) + ", " + limits.expected;
    std::string e;
    for (const auto& [sw, sh] : limits.sizes) e += (e.empty() ? "" : " or ") + size_text(static_cast<std::uint64_t>(sw), static_cast<std::uint64_t>(sh));
    return "image is " + size_text(w, h) + ", expected " + e;
  }
  if (w > limits.max_pixels / h)
    return "image is " + size_text(w, h) + ": more than the " + std::to_string(limits.max_pixels) + " pixels an image may have";
  return {};
}

// ---- PNG (libpng) -------------------------------------------------------------------------------

struct PngState {
  const unsigned char* data = nullptr;
  std::size_t size = 0, pos = 0;
  const ImageLimits* limits = nullptr;
  png_structp png = nullptr;
  png_infop info = nullptr;
  Pixels8 out;
  std::vector<png_bytep> rows;
  std::string problem;   // our refusal (the whole message after "<label>: ")
  char message[256] = {};  // libpng's error message (written without allocating)
};

void png_read_from_memory(png_structp png, png_bytep dst, png_size_t n) {
  auto* st = static_cast<PngState*>(png_get_io_ptr(png));
  if (n > st->size - st->pos) png_error(png, "the file ends early (truncated PNG)");
  std::memcpy(dst, st->data + st->pos, n);
  st->pos += n;
}
void png_error_to_state(png_structp png, png_const_charp msg) {
  auto* st = static_cast<PngState*>(png_get_error_ptr(png));
  std::snprintf(st->message, sizeof st->message, "%s", msg ? msg : "unknown error");
  png_longjmp(png, 1);
}
void png_ignore_warning(png_structp, png_const_charp) {}

// Decodes st->data into st->out; false with st->problem or st->message set. The caller destroys
// st->png / st->info.
bool png_decode_into(PngState* st) {
  st->png = png_create_read_struct(PNG_LIBPNG_VER_STRING, st, png_error_to_state, png_ignore_warning);
  if (st->png == nullptr) {
    st->problem = "cannot start libpng";
    return false;
  }
  st->info = png_create_info_struct(st->png);
  if (st->info == nullptr) {
    st->problem = "cannot start libpng";
    return false;
  }
  if (setjmp(png_jmpbuf(st->png))) return false;  // NOLINT(cert-err52-cpp): libpng's error protocol
  png_set_read_fn(st->png, st, png_read_from_memory);
  png_set_chunk_malloc_max(st->png, 8u << 20);  // ancillary chunks (text, ICC profile): 8 MiB
  // libpng's own size limit (10^6 per side by default) gives way to ours, checked right after
  // IHDR with a message that says what was expected; nothing of the image is allocated before.
  png_set_user_limits(st->png, 0x7fffffffu, 0x7fffffffu);
  png_read_info(st->png, st->info);
  png_uint_32 w = 0, h = 0;
  int depth = 0, colour = 0;
  png_get_IHDR(st->png, st->info, &w, &h, &depth, &colour, nullptr, nullptr, nullptr);
  st->problem = image_size_problem(w, h, *st->limits);
  if (!st->problem.empty()) return false;
  if (depth == 16) {
    st->problem = "16-bit PNG (8-bit expected)";
    return false;
  }
  if (colour == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(st->png);
  if (colour == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(st->png);
  if (png_get_valid(st->png, st->info, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(st->png);
  png_set_interlace_handling(st->png);
  png_read_update_info(st->png, st->info);
  const int channels = png_get_channels(st->png, st->info);
  const std::size_t row = png_get_rowbytes(st->png, st->info);
  if (png_get_bit_depth(st->png, st->info) != 8 || channels < 1 || channels > 4 ||
      row != static_cast<std::size_t>(w) * static_cast<std::size_t>(channels)) {
    st->problem = "unsupported PNG pixel layout";
    return false;
  }
  st->out.width = static_cast<int>(w);
  st->out.height = static_cast<int>(h);
  st->out.channels = channels;
  st->out.pixels.resize(row * h);
  st->rows.resize(h);
  for (png_uint_32 y = 0; y < h; ++y) st->rows[y] = st->out.pixels.data() + row * y;
  png_read_image(st->png, st->rows.data());
  png_read_end(st->png, nullptr);  // the chunks after the image, to IEND: a truncated file is refused
  return true;
}

// ---- JPEG (libjpeg-turbo) ----------------------------------------------------------------------

constexpr int kMaxJpegScans = 1000;  // a progressive JPEG has about 10; thousands only slow us down

struct JpegState {
  jpeg_decompress_struct cinfo{};
  jpeg_error_mgr err{};
  jpeg_progress_mgr progress{};
  std::jmp_buf jump{};
  bool created = false;
  const ImageLimits* limits = nullptr;
  Pixels8 out;
  std::string problem;
  char message[JMSG_LENGTH_MAX + 64] = {};
  long warnings = 0;                        // libjpeg's warnings read through
  char first_warning[JMSG_LENGTH_MAX] = {};  // the text of the first
};

JpegState* jpeg_state(j_common_ptr cinfo) { return static_cast<JpegState*>(cinfo->client_data); }

void jpeg_error_to_state(j_common_ptr cinfo) {
  JpegState* st = jpeg_state(cinfo);
  (*cinfo->err->format_message)(cinfo, st->message);
  std::longjmp(st->jump, 1);  // NOLINT(cert-err52-cpp): libjpeg's error protocol
}
// libjpeg's warnings (level -1) are data it can read past: stray bytes before a marker (which
// some writers leave), a bad Huffman code or an early end of one scan's data (those
// blocks come out flat), an unknown JFIF revision, a bad ICC marker. djpeg, Pillow and OpenCV
// read such files, so they are read here too: the first warning's text is kept for the one note
// decode_jpeg prints, the others are counted. One warning is an error: "Premature end of JPEG
// file" (JWRN_JPEG_EOF), where jpeg_mem_src ran out of bytes and libjpeg would make up the rest
// of the image in grey; Pillow refuses such a file too ("image file is truncated", unless told
// LOAD_TRUNCATED_IMAGES), and a cut-off download or copy is the usual cause, which the user
// should hear about rather than train on a grey band. Trace messages (level >= 0) are ignored.
void jpeg_warning(j_common_ptr cinfo, int level) {
  if (level >= 0) return;
  if (cinfo->err->msg_code == JWRN_JPEG_EOF) jpeg_error_to_state(cinfo);
  JpegState* st = jpeg_state(cinfo);
  if (st->warnings++ == 0) (*cinfo->err->format_message)(cinfo, st->first_warning);
}
void jpeg_count_scans(j_common_ptr cinfo) {
  if (!cinfo->is_decompressor) return;
  const auto* d = reinterpret_cast<j_decompress_ptr>(cinfo);
  if (d->input_scan_number > kMaxJpegScans) {
    JpegState* st = jpeg_state(cinfo);
    std::snprintf(st->message, sizeof st->message, "more than %d scans", kMaxJpegScans);
    std::longjmp(st->jump, 1);  // NOLINT(cert-err52-cpp): libjpeg's error protocol
  }
}

bool jpeg_decode_into(JpegState* st, const unsigned char* data, std::size_t size) {
  st->cinfo.err = jpeg_std_error(&st->err);
  st->err.error_exit = jpeg_error_to_state;
  st->err.emit_message = jpeg_warning;
  st->cinfo.client_data = st;
  if (setjmp(st->jump)) return false;  // NOLINT(cert-err52-cpp): libjpeg's error protocol
  st->created = true;  // jpeg_destroy_decompress is safe on a half-made struct
  jpeg_create_decompress(&st->cinfo);
  st->progress.progress_monitor = jpeg_count_scans;
  st->cinfo.progress = &st->progress;
  st->cinfo.mem->max_memory_to_use = 1L << 30;  // beyond it libjpeg fails (no backing store)
  jpeg_mem_src(&st->cinfo, data, static_cast<unsigned long>(size));
  jpeg_read_header(&st->cinfo, TRUE);
  st->problem = image_size_problem(st->cinfo.image_width, st->cinfo.image_height, *st->limits);
  if (!st->problem.empty()) return false;
  if (st->cinfo.jpeg_color_space == JCS_CMYK || st->cinfo.jpeg_color_space == JCS_YCCK) {
    st->problem = "CMYK JPEG (RGB or grey expected)";
    return false;
  }
  st->cinfo.out_color_space = st->cinfo.num_components == 1 ? JCS_GRAYSCALE : JCS_RGB;
  st->cinfo.dct_method = JDCT_ISLOW;  // djpeg -dct int
  jpeg_start_decompress(&st->cinfo);
  const int channels = st->cinfo.output_components;
  if (st->cinfo.output_width != st->cinfo.image_width || st->cinfo.output_height != st->cinfo.image_height ||
      (channels != 1 && channels != 3)) {
    st->problem = "unsupported JPEG pixel layout";
    return false;
  }
  st->out.width = static_cast<int>(st->cinfo.output_width);
  st->out.height = static_cast<int>(st->cinfo.output_height);
  st->out.channels = channels;
  const std::size_t row = static_cast<std::size_t>(st->out.width) * static_cast<std::size_t>(channels);
  st->out.pixels.resize(row * static_cast<std::size_t>(st->out.height));
  while (st->cinfo.output_scanline < st->cinfo.output_height) {
    JSAMPROW line = st->out.pixels.data() + row * st->cinfo.output_scanline;
    jpeg_read_scanlines(&st->cinfo, &line, 1);
  }
  jpeg_finish_decompress(&st->cinfo);
  return true;
}

}  // namespace

Pixels8 decode_png(const std::vector<unsigned char>& bytes, const std::string& label, const ImageLimits& limits) {
  if (!starts_with(bytes, {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'}))
    throw std::runtime_error(label + ": not a PNG image (no PNG signature)");
  PngState st;
  st.data = bytes.data();
  st.size = bytes.size();
  st.limits = &limits;
  struct Release {
    PngState& s;
    ~Release() {
      if (s.png != nullptr) png_destroy_read_struct(&s.png, s.info != nullptr ? &s.info : nullptr, nullptr);
    }
  } release{st};
  if (!png_decode_into(&st)) {
    if (!st.problem.empty()) throw std::runtime_error(label + ": " + st.problem);
    throw std::runtime_error(label + ": corrupt PNG (libpng: " + st.message + ")");
  }
  return std::move(st.out);
}

Pixels8 decode_jpeg(const std::vector<unsigned char>& bytes, const std::string& label, const ImageLimits& limits,
                    std::FILE* notes) {
  if (!starts_with(bytes, {0xff, 0xd8, 0xff})) throw std::runtime_error(label + ": not a JPEG image (no JPEG start-of-image marker)");
  if (bytes.size() > ULONG_MAX) throw std::runtime_error(label + ": file too large");
  auto st = std::make_unique<JpegState>();
  st->limits = &limits;
  struct Release {
    JpegState& s;
    ~Release() {
      if (s.created) jpeg_destroy_decompress(&s.cinfo);
    }
  } release{*st};
  if (!jpeg_decode_into(st.get(), bytes.data(), bytes.size())) {
    if (!st->problem.empty()) throw std::runtime_error(label + ": " + st->problem);
    throw std::runtime_error(label + ": corrupt JPEG (libjpeg: " + st->message + ")");
  }
  if (st->warnings > 0 && notes != nullptr) {
    std::string note = "[data] " + label + ": libjpeg warning: " + st->first_warning;
    if (st->warnings > 1) note += " (and " + std::to_string(st->warnings - 1) + " more)";
    note = cli::escape_line(note + " (read anyway)") + "\n";
    std::fputs(note.c_str(), notes);
    std::fflush(notes);
  }
  return std::move(st->out);
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
  const std::string& label() const { return label_; }

 private:
  const std::vector<unsigned char>& b_;
  const std::string& label_;
};

// The raw DEFLATE stream (RFC 1951, no zlib header: windowBits -15) of member `name`, `csize`
// bytes at `in`, inflated by zlib into exactly `usize` bytes (the recorded size). The output
// grows as data comes (doubling, never past usize + 1), so a member that records more than it
// holds costs only what it holds; once the .npy header is out, the size it declares must be
// usize, before the rest is inflated. The stream must end (Z_STREAM_END) within the compressed
// bytes and give exactly usize bytes; bytes after its end are ignored, as Python's zipfile does.
// Every failure names the member.
std::vector<unsigned char> inflate_member(const Reader& r, const std::string& name, const unsigned char* in,
                                          std::uint64_t csize, std::uint64_t usize) {
  std::vector<unsigned char> out;
  const std::uint64_t cap = usize + 1;  // one spare byte tells "more than recorded" from "exactly"
  z_stream zs{};
  if (inflateInit2(&zs, -15) != Z_OK) r.fail("cannot start zlib's inflate for member '" + name + "'");
  struct End {
    z_stream& z;
    ~End() { inflateEnd(&z); }
  } end{zs};
  std::uint64_t in_left = csize, produced = 0;
  bool header_checked = false;
  zs.next_in = const_cast<Bytef*>(in);  // zlib's API is not const; it never writes the input
  std::string problem;
  for (;;) {
    // zlib counts in unsigned int: hand it the input in chunks.
    if (zs.avail_in == 0 && in_left > 0) {
      zs.avail_in = static_cast<uInt>(std::min<std::uint64_t>(in_left, UINT_MAX));
      in_left -= zs.avail_in;
    }
    if (produced == out.size() && out.size() < cap) {
      const std::uint64_t grown = std::min<std::uint64_t>(cap, std::max<std::uint64_t>(65536, 2 * out.size()));
      out.resize(static_cast<std::size_t>(grown));
    }
    zs.next_out = out.data() + produced;
    zs.avail_out = static_cast<uInt>(std::min<std::uint64_t>(out.size() - produced, UINT_MAX));
    const int ret = inflate(&zs, Z_NO_FLUSH);
    produced = static_cast<std::uint64_t>(zs.next_out - out.data());
    if (!header_checked && ret != Z_DATA_ERROR) {
      const std::uint64_t declared = npy::declared_size(out.data(), static_cast<std::size_t>(produced), r.label() + " member '" + name + "'");
      if (declared != 0) {
        header_checked = true;
        if (declared != usize)
          r.fail("member '" + name + "': its .npy header declares " + std::to_string(declared) +
                 " bytes, the archive records " + std::to_string(usize));
      }
    }
    if (ret == Z_STREAM_END) break;
    if (ret == Z_OK) continue;  // progress; go on
    if (ret == Z_BUF_ERROR && produced == cap)
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
  if (problem.empty() && produced != usize)
    problem = produced > usize ? "decompresses to more than the recorded " + std::to_string(usize) + " bytes"
                               : "decompresses to " + std::to_string(produced) + " bytes, the archive records " +
                                     std::to_string(usize);
  if (!problem.empty()) r.fail("member '" + name + "': " + problem);
  out.resize(static_cast<std::size_t>(usize));
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
    // The member's bytes, bounded before anything is allocated for them (file_formats.hpp).
    if (method == 0 && csize != usize) r.fail("corrupt archive (stored member '" + name + "' with different sizes)");
    if (method == 8 && usize > 1032 * csize + 1024)
      r.fail("member '" + name + "' records " + std::to_string(usize) + " bytes from " + std::to_string(csize) +
             " compressed (more than DEFLATE's 1032:1; a corrupt or hostile archive)");
    if (usize > kMaxNpzMemberBytes)
      r.fail("member '" + name + "' records " + std::to_string(usize) + " bytes (more than the " +
             std::to_string(kMaxNpzMemberBytes >> 30) + " GiB a member may have)");
    try {
      std::vector<unsigned char> data;
      if (method == 0) {
        data.assign(r.at(data_at), r.at(data_at) + csize);  // within the archive: npy::parse checks its header
      } else {
        data = inflate_member(r, name, r.at(data_at), csize, usize);
      }
      if (crc32(data.data(), data.size()) != crc) r.fail("CRC-32 mismatch in member '" + name + "' (corrupt archive)");
      out.emplace(key, npy::parse(data.data(), data.size(), what));
    } catch (const std::bad_alloc&) {
      r.fail("member '" + name + "': out of memory for its " + std::to_string(usize) + " bytes");
    }
  }
  return out;
}

namespace {
// Appends the `bytes` low bytes of v to s, little-endian (ZIP's byte order).
void put(std::string& s, std::uint64_t v, int bytes) {
  for (int k = 0; k < bytes; ++k) s += static_cast<char>((v >> (8 * k)) & 0xFFu);
}

// Appends the fields a stored member's local file header and its central directory entry share,
// in the order both use: version needed 2.0, no flags, stored, 1980-01-01 00:00, the CRC, both
// sizes (equal: nothing is compressed) and the name's length.
void put_member_fields(std::string& s, std::uint32_t crc, std::uint64_t size, std::uint64_t name_size) {
  put(s, 20, 2);
  put(s, 0, 2);
  put(s, 0, 2);
  put(s, 0, 2);
  put(s, 0x21, 2);
  put(s, crc, 4);
  put(s, size, 4);
  put(s, size, 4);
  put(s, name_size, 2);
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
    // Local file header.
    put(out, kLocalSig, 4);
    put_member_fields(out, crc, data.size(), name.size());
    put(out, 0, 2);  // extra
    out += name;
    out += data;
    // Its central directory entry.
    put(central, kCentralSig, 4);
    put(central, 20, 2);  // made by: MS-DOS attributes, version 2.0
    put_member_fields(central, crc, data.size(), name.size());
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
