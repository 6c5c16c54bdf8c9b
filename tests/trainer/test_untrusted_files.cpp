// The readers of files users bring, on hostile inputs (docs/data.md, "Files from users"): the
// regression inputs of tests/fuzz/corpus (a JPEG that wrote out of bounds in stb_image, a 307-byte
// PNG that made it allocate 1 GB, deflate bombs written by tests/fuzz/make_seeds.py) and image
// sizes refused from the header, before anything is decoded.
#include <doctest/doctest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "npy.hpp"
#include "support/files.hpp"
#include "trainer/file_formats.hpp"

namespace {

namespace fs = std::filesystem;
using trainer::files::ImageLimits;
using trainer::files::Pixels8;

std::vector<unsigned char> untrusted_corpus_file(const std::string& rel) {
  const fs::path p = fs::path(SMG_TEST_DATA_DIR) / ".." / "fuzz" / "corpus" / rel;
  return trainer::files::read_bytes(p.string(), rel);
}

template <class F>
std::string untrusted_error(F&& f) {
  try {
    f();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "no error";
}

// A one-member ZIP whose deflated member `name` records `usize` bytes (ZIP64 fields) from
// `csize` bytes of data (zeros: never inflated when the sizes are refused).
std::vector<unsigned char> untrusted_zip64(const std::string& name, std::uint64_t csize, std::uint64_t usize) {
  std::string z;
  auto put = [&z](std::uint64_t v, int bytes) {
    for (int k = 0; k < bytes; ++k) z += static_cast<char>((v >> (8 * k)) & 0xFFu);
  };
  put(0x04034b50, 4), put(45, 2), put(0, 2), put(8, 2), put(0, 4), put(0, 4);
  put(0xFFFFFFFF, 4), put(0xFFFFFFFF, 4), put(name.size(), 2), put(0, 2);
  z += name;
  z += std::string(static_cast<std::size_t>(csize), '\0');
  const std::uint64_t cd = z.size();
  put(0x02014b50, 4), put(45, 2), put(45, 2), put(0, 2), put(8, 2), put(0, 4), put(0, 4);
  put(0xFFFFFFFF, 4), put(0xFFFFFFFF, 4), put(name.size(), 2), put(20, 2), put(0, 2), put(0, 2), put(0, 2), put(0, 4), put(0, 4);
  z += name;
  put(0x0001, 2), put(16, 2), put(usize, 8), put(csize, 8);
  const std::uint64_t cd_size = z.size() - cd;
  put(0x06054b50, 4), put(0, 2), put(0, 2), put(1, 2), put(1, 2), put(cd_size, 4), put(cd, 4), put(0, 2);
  return {z.begin(), z.end()};
}

bool untrusted_starts_with(const std::string& s, const std::string& prefix) { return s.compare(0, prefix.size(), prefix) == 0; }

}  // namespace

TEST_CASE("PNG (libpng): the 1 GB allocation input is refused from its header; sizes are checked before decoding") {
  // As found: its IHDR's CRC is stale (stb_image never checks it); libpng refuses that first.
  const std::vector<unsigned char> found = untrusted_corpus_file("png/regression-png_1gb_alloc.png");
  CHECK(found.size() == 307);
  CHECK(untrusted_error([&] { trainer::files::decode_png(found, "a.png"); }) == "a.png: corrupt PNG (libpng: IHDR: CRC error)");
  // With the CRC made right (tests/fuzz/make_seeds.py): the pixel bound refuses it from the header.
  const std::vector<unsigned char> bomb = untrusted_corpus_file("png/regression-png_1gb_alloc-crc.png");
  CHECK(untrusted_error([&] { trainer::files::decode_png(bomb, "a.png"); }) ==
        "a.png: image is 16x16712460: more than the 67108864 pixels an image may have");
  // What every scene reader passes: the camera's size.
  CHECK(untrusted_error([&] { trainer::files::decode_png(bomb, "a.png", trainer::files::image_of_size(16, 12)); }) ==
        "a.png: image is 16x16712460, expected 16x12");
  CHECK(untrusted_error([&] {
          trainer::files::decode_png(bomb, "a.png", trainer::files::image_of_size(16, 12, "camera/a.json gives 16x12 at 2x"));
        }) == "a.png: image is 16x16712460, camera/a.json gives 16x12 at 2x");
  // A good PNG of the wrong size: refused with the size, not decoded.
  const std::vector<unsigned char> rgba = untrusted_corpus_file("png/rgba.png");
  ImageLimits two;
  two.sizes = {{32, 24}, {8, 6}};
  CHECK(untrusted_error([&] { trainer::files::decode_png(rgba, "b.png", two); }) == "b.png: image is 16x12, expected 32x24 or 8x6");
  two.sizes.emplace_back(16, 12);
  const Pixels8 p = trainer::files::decode_png(rgba, "b.png", two);
  CHECK(p.width == 16);
  CHECK(p.height == 12);
  CHECK(p.channels == 4);
  ImageLimits tight;
  tight.max_pixels = 16 * 12 - 1;
  CHECK(untrusted_error([&] { trainer::files::decode_png(rgba, "b.png", tight); }) ==
        "b.png: image is 16x12: more than the 191 pixels an image may have");
}

TEST_CASE("PNG (libpng): palette + tRNS as RGBA, 2-bit grey expanded, 16-bit and truncated files refused") {
  const Pixels8 pal = trainer::files::decode_png(untrusted_corpus_file("png/palette-trns.png"), "p.png");
  REQUIRE(pal.channels == 4);
  REQUIRE(pal.pixels.size() == 4 * 3 * 4);
  // Row 0: indices 0, 1, 2, 1 -> red (alpha 0x80), green (0xff), blue (no tRNS entry: 255), green.
  CHECK(std::vector<int>(pal.pixels.begin(), pal.pixels.begin() + 8) == std::vector<int>{255, 0, 0, 128, 0, 255, 0, 255});
  CHECK(int(pal.pixels[8 + 2]) == 255);
  CHECK(int(pal.pixels[8 + 3]) == 255);
  const Pixels8 grey = trainer::files::decode_png(untrusted_corpus_file("png/grey2.png"), "g.png");
  REQUIRE(grey.channels == 1);
  // 2-bit levels 0, 1, 2, 3, 3 scaled to 8 bits (x 85).
  CHECK(std::vector<int>(grey.pixels.begin(), grey.pixels.begin() + 5) == std::vector<int>{0, 85, 170, 255, 255});
  CHECK(untrusted_error([&] { trainer::files::decode_png(untrusted_corpus_file("png/rgb16.png"), "w.png"); }) ==
        "w.png: 16-bit PNG (8-bit expected)");
  std::vector<unsigned char> cut = untrusted_corpus_file("png/rgba.png");
  cut.resize(cut.size() - 20);
  CHECK(untrusted_starts_with(untrusted_error([&] { trainer::files::decode_png(cut, "c.png"); }), "c.png: corrupt PNG (libpng: "));
}

TEST_CASE("JPEG (libjpeg-turbo): the stb_image out-of-bounds input is refused as corrupt; truncation is an error") {
  const std::vector<unsigned char> oob = untrusted_corpus_file("jpeg/regression-jpeg_huffman_oob.jpg");
  CHECK(oob.size() == 840);
  const std::string e = untrusted_error([&] { trainer::files::decode_jpeg(oob, "images/0_00000.jpg"); });
  MESSAGE(e);
  CHECK(untrusted_starts_with(e, "images/0_00000.jpg: corrupt JPEG (libjpeg: "));
  const std::vector<unsigned char> good = untrusted_corpus_file("jpeg/baseline.jpg");
  const Pixels8 p = trainer::files::decode_jpeg(good, "g.jpg", trainer::files::image_of_size(16, 12));
  CHECK(p.channels == 3);
  CHECK(p.pixels.size() == 16 * 12 * 3);
  CHECK(untrusted_error([&] { trainer::files::decode_jpeg(good, "g.jpg", trainer::files::image_of_size(32, 24)); }) ==
        "g.jpg: image is 16x12, expected 32x24");
  // libjpeg would pad a truncated file with grey and warn ("Premature end of JPEG file"); that
  // warning is an error here, as Pillow refuses a truncated file.
  const std::vector<unsigned char> cut(good.begin(), good.end() - 100);
  CHECK(untrusted_error([&] { trainer::files::decode_jpeg(cut, "t.jpg"); }) == "t.jpg: corrupt JPEG (libjpeg: Premature end of JPEG file)");
}

// The bytes with `extra` inserted before the first `marker` (0xFF, code) after the SOI.
std::vector<unsigned char> untrusted_jpeg_with_extra(const std::vector<unsigned char>& b, unsigned char code, unsigned char extra) {
  for (std::size_t i = 2; i + 1 < b.size(); ++i) {
    if (b[i] == 0xFF && b[i + 1] == code) {
      std::vector<unsigned char> out(b.size() + 1);  // (not vector::insert: a false -Wstringop-overflow in GCC 12)
      std::copy(b.begin(), b.begin() + static_cast<std::ptrdiff_t>(i), out.begin());
      out[i] = extra;
      std::copy(b.begin() + static_cast<std::ptrdiff_t>(i), b.end(), out.begin() + static_cast<std::ptrdiff_t>(i) + 1);
      return out;
    }
  }
  FAIL("no marker 0xFF " << static_cast<int>(code));
  return b;
}

// What decode_jpeg wrote to its notes stream, and its pixels (or the refusal).
struct UntrustedJpegRead {
  Pixels8 pixels;
  std::string error;
  std::string notes;
};
UntrustedJpegRead untrusted_read_jpeg(const std::vector<unsigned char>& b, const std::string& label) {
  UntrustedJpegRead r;
  std::FILE* f = std::tmpfile();
  REQUIRE(f != nullptr);
  try {
    r.pixels = trainer::files::decode_jpeg(b, label, {}, f);
  } catch (const std::runtime_error& e) {
    r.error = e.what();
  }
  std::rewind(f);
  for (int ch; (ch = std::fgetc(f)) != EOF;) r.notes += static_cast<char>(ch);
  std::fclose(f);
  return r;
}

TEST_CASE("JPEG (libjpeg-turbo): a warning is read through with one note naming the file; regression inputs stay refused") {
  // Issue 47: a valid JPEG with one stray byte before its DQT marker (0xFF 0xDB), which Pillow,
  // OpenCV and djpeg decode, was refused ("1 extraneous bytes before marker 0xdb").
  const std::vector<unsigned char> good = untrusted_corpus_file("jpeg/baseline.jpg");
  const UntrustedJpegRead clean = untrusted_read_jpeg(good, "images/0_00000.jpg");
  REQUIRE(clean.error.empty());
  CHECK(clean.notes.empty());
  const std::vector<unsigned char> stray = untrusted_jpeg_with_extra(good, 0xDB, 0x00);
  CHECK(stray.size() == good.size() + 1);
  const UntrustedJpegRead read = untrusted_read_jpeg(stray, "images/0_00000.jpg");
  CHECK(read.error.empty());
  CHECK(read.notes ==
        "[data] images/0_00000.jpg: libjpeg warning: Corrupt JPEG data: 1 extraneous bytes before marker 0xdb (read anyway)\n");
  CHECK(read.pixels.width == clean.pixels.width);
  CHECK(read.pixels.height == clean.pixels.height);
  CHECK(read.pixels.channels == clean.pixels.channels);
  CHECK(read.pixels.pixels == clean.pixels.pixels);  // the same pixels: the byte is outside the image data

  // Several warnings: still one line, the first named and the others counted; the label escaped.
  const std::vector<unsigned char> two = untrusted_jpeg_with_extra(untrusted_jpeg_with_extra(stray, 0xC0, 0x00), 0xC0, 0x00);
  const UntrustedJpegRead twice = untrusted_read_jpeg(two, "images/a\nb.jpg");
  CHECK(twice.error.empty());
  CHECK(twice.notes == "[data] images/a\\nb.jpg: libjpeg warning: Corrupt JPEG data: 1 extraneous bytes before marker 0xdb "
                       "(and 1 more) (read anyway)\n");
  CHECK(twice.pixels.pixels == clean.pixels.pixels);

  // Warnings before a file's early end: refused, and no note.
  const std::vector<unsigned char> cut(stray.begin(), stray.end() - 100);
  const UntrustedJpegRead truncated = untrusted_read_jpeg(cut, "t.jpg");
  CHECK(truncated.error == "t.jpg: corrupt JPEG (libjpeg: Premature end of JPEG file)");
  CHECK(truncated.notes.empty());
  // Cut after the last scan (the EOI marker missing): refused as well.
  const UntrustedJpegRead no_eoi = untrusted_read_jpeg({good.begin(), good.end() - 2}, "e.jpg");
  CHECK(no_eoi.error == "e.jpg: corrupt JPEG (libjpeg: Premature end of JPEG file)");

  // Every regression input of the fuzz corpus is still refused, with no note.
  int regressions = 0;
  for (const auto& entry : fs::directory_iterator(fs::path(SMG_TEST_DATA_DIR) / ".." / "fuzz" / "corpus" / "jpeg")) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("regression-", 0) != 0) continue;
    ++regressions;
    CAPTURE(name);
    const UntrustedJpegRead r = untrusted_read_jpeg(untrusted_corpus_file("jpeg/" + name), name);
    CHECK(untrusted_starts_with(r.error, name + ": corrupt JPEG (libjpeg: "));
    CHECK(r.notes.empty());
  }
  CHECK(regressions >= 1);
}

TEST_CASE("npz: deflate bombs are refused before they are inflated; a consistent one is read within its bound") {
  // 1 GiB recorded from 115 bytes of deflate data: more than DEFLATE's 1032:1.
  const std::string ratio = untrusted_error([] { trainer::files::parse_npz(untrusted_corpus_file("npz/bomb-ratio.npz"), "priors/tracks.npz"); });
  CHECK(ratio == "priors/tracks.npz: member 'uv.npy' records 1073741824 bytes from 115 compressed (more than DEFLATE's "
                 "1032:1; a corrupt or hostile archive)");
  // 1 MiB recorded (within the ratio), a header declaring 4 TB: refused once the header is out.
  CHECK(untrusted_error([] { trainer::files::parse_npz(untrusted_corpus_file("npz/bomb-header.npz"), "priors/tracks.npz"); }) ==
        "priors/tracks.npz: member 'uv.npy': its .npy header declares 4000000000128 bytes, the archive records 1048576");
  // A real bomb whose sizes agree (1 MiB of zeros in about 1 KiB) is data, read as such.
  const std::vector<unsigned char> zeros = untrusted_corpus_file("npz/bomb-zeros.npz");
  CHECK(zeros.size() < 2048);
  const auto arrays = trainer::files::parse_npz(zeros, "z.npz");
  REQUIRE(arrays.count("uv") == 1);
  CHECK(arrays.at("uv").shape == std::vector<std::int64_t>{262144});
  // The member bound: 4 GiB + 1 recorded from 4.2 MB (within DEFLATE's ratio) is refused from the
  // sizes alone, before anything is allocated or inflated.
  CHECK(trainer::files::kMaxNpzMemberBytes == (std::uint64_t{1} << 32));
  const std::uint64_t big = (std::uint64_t{1} << 32) + 1, csize = big / 1000;
  CHECK(untrusted_error([&] { trainer::files::parse_npz(untrusted_zip64("uv.npy", csize, big), "t.npz"); }) ==
        "t.npz: member 'uv.npy' records 4294967297 bytes (more than the 4 GiB a member may have)");
  // The same archive recording 1032 x + 1 KiB + 1: the ratio refuses it.
  CHECK(untrusted_starts_with(untrusted_error([&] { trainer::files::parse_npz(untrusted_zip64("uv.npy", 1000, 1032 * 1000 + 1025), "t.npz"); }),
                              "t.npz: member 'uv.npy' records 1033025 bytes from 1000 compressed"));
}

TEST_CASE("npy::declared_size: the whole image's size from its header, 0 until the header is complete") {
  const std::vector<float> v(6, 1.0f);
  const std::string b = npy::to_bytes(v.data(), {2, 3});
  const auto* p = reinterpret_cast<const unsigned char*>(b.data());
  CHECK(npy::declared_size(p, b.size(), "x") == b.size());
  CHECK(npy::declared_size(p, 11, "x") == 0);
  CHECK(npy::declared_size(p, b.size() - 24, "x") == b.size());  // the header alone suffices
  const std::string bad = "\x93NUMPX";
  CHECK_THROWS_WITH_AS(npy::declared_size(reinterpret_cast<const unsigned char*>(bad.data()), bad.size(), "x"),
                       "x: not an .npy file (bad magic)", npy::Error);
}
