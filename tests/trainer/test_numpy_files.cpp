// Files numpy itself wrote (issue 23): np.savez_compressed / np.savez archives and Fortran-order
// .npy files, read by trainer::files::parse_npz (zlib's inflate) and npy::read / npy::parse.
// The checked-in fixtures (tests/data/numpy, made by make_fixtures.py there: 128 KiB in all) are formulas of the
// C-order flat index k, recomputed here independently of any reader; the test-time archives
// (make_random.py, where /usr/bin/python3 has numpy) are compared with numpy's own tobytes().
#include <doctest/doctest.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "npy.hpp"
#include "support/errors.hpp"
#include "support/files.hpp"
#include "trainer/file_formats.hpp"

namespace {

namespace fs = std::filesystem;

const std::string kNumpyDir = std::string(SMG_TEST_DATA_DIR) + "/numpy";

// One fixture array: dtype, shape and its value at C-order flat index k (make_fixtures.py's
// table; every value is exact in double).
struct NumpyFixture {
  npy::DType dtype;
  std::vector<std::int64_t> shape;
  std::function<double(std::int64_t)> value;
};

double knuth_top20(std::int64_t k) {
  return static_cast<double>(((static_cast<std::uint64_t>(k) * 2654435761ull) % 4294967296ull) >> 12);
}

const std::map<std::string, NumpyFixture>& numpy_archive_table() {
  static const std::map<std::string, NumpyFixture> t = {
      {"f32", {npy::DType::f32, {4, 3, 2}, [](std::int64_t k) { return k * 0.5; }}},
      {"f64", {npy::DType::f64, {5, 7}, [](std::int64_t k) { return (static_cast<double>(k) - 17) / 8.0; }}},
      {"b1", {npy::DType::b1, {6, 10}, [](std::int64_t k) { return k % 7 == 3 ? 1.0 : 0.0; }}},
      {"i32", {npy::DType::i32, {17}, [](std::int64_t k) { return static_cast<double>(k * -3 + 5); }}},
      {"i64", {npy::DType::i64, {3, 4}, [](std::int64_t k) { return static_cast<double>(k * 1000000007); }}},
      {"empty", {npy::DType::f32, {0, 3}, [](std::int64_t) { return 0.0; }}},
      {"scalar", {npy::DType::i64, {}, [](std::int64_t k) { return static_cast<double>(k + 42); }}},
      {"visible", {npy::DType::b1, {36, 100}, [](std::int64_t k) { return (k * 7 + (k / 100) * 3) % 11 < 6 ? 1.0 : 0.0; }}},
      {"big", {npy::DType::i32, {24000}, knuth_top20}},
  };
  return t;
}

const std::map<std::string, NumpyFixture>& numpy_fortran_table() {
  static const std::map<std::string, NumpyFixture> t = {
      {"fortran_f64_2d", {npy::DType::f64, {4, 5}, [](std::int64_t k) { return k * 0.25 - 3; }}},
      {"fortran_f32_3d", {npy::DType::f32, {2, 3, 4}, [](std::int64_t k) { return k * 1.5; }}},
      {"fortran_bool_2d", {npy::DType::b1, {3, 5}, [](std::int64_t k) { return k % 3 == 1 ? 1.0 : 0.0; }}},
      {"fortran_bool_3d", {npy::DType::b1, {2, 3, 4}, [](std::int64_t k) { return k % 4 == 2 ? 1.0 : 0.0; }}},
      {"fortran_i32_3d", {npy::DType::i32, {3, 2, 4}, [](std::int64_t k) { return static_cast<double>(k * -7 + 11); }}},
      {"fortran_i64_2d", {npy::DType::i64, {2, 7}, [](std::int64_t k) { return static_cast<double>(k * 1000000000000); }}},
      {"fortran_u8_4d", {npy::DType::u8, {2, 3, 2, 2}, [](std::int64_t k) { return static_cast<double>(k % 251); }}},
      {"fortran_f16_2d", {npy::DType::f16, {3, 4}, [](std::int64_t k) { return k * 0.5; }}},
  };
  return t;
}

// Every element of `a` against the fixture's formula; returns the number of mismatches.
int numpy_mismatches(const npy::Array& a, const NumpyFixture& f) {
  CHECK(a.dtype == f.dtype);
  CHECK(a.shape == f.shape);
  const std::vector<double> v = a.as<double>();
  std::int64_t n = 1;
  for (const auto d : f.shape) n *= d;
  CHECK(static_cast<std::int64_t>(v.size()) == n);
  int bad = 0;
  for (std::size_t k = 0; k < v.size(); ++k)
    if (v[k] != f.value(static_cast<std::int64_t>(k))) ++bad;
  return bad;
}

std::vector<unsigned char> numpy_fixture_bytes(const std::string& name) {
  return trainer::files::read_bytes(kNumpyDir + "/" + name, name);
}

// Offset of member `name`'s central directory entry (signature PK\1\2, name at +46).
std::size_t numpy_central_entry(const std::vector<unsigned char>& z, const std::string& name) {
  for (std::size_t p = 0; p + 46 + name.size() <= z.size(); ++p)
    if (z[p] == 'P' && z[p + 1] == 'K' && z[p + 2] == 1 && z[p + 3] == 2 &&
        std::string(z.begin() + static_cast<std::ptrdiff_t>(p + 46), z.begin() + static_cast<std::ptrdiff_t>(p + 46 + name.size())) == name)
      return p;
  FAIL("no central directory entry for " << name);
  return 0;
}
std::uint64_t numpy_le(const std::vector<unsigned char>& z, std::size_t at, int bytes) {
  std::uint64_t v = 0;
  for (int k = bytes - 1; k >= 0; --k) v = (v << 8) | z[at + static_cast<std::size_t>(k)];
  return v;
}
void numpy_put_le(std::vector<unsigned char>& z, std::size_t at, std::uint64_t v, int bytes) {
  for (int k = 0; k < bytes; ++k) z[at + static_cast<std::size_t>(k)] = static_cast<unsigned char>((v >> (8 * k)) & 0xFFu);
}

std::string npz_error(const std::vector<unsigned char>& z) {
  return smg::test::error_message<npy::Error>([&] { trainer::files::parse_npz(z, "priors/tracks.npz"); }, "no error");
}

}  // namespace

TEST_CASE("numpy files: np.savez_compressed members (float, bool, int, empty, scalar, > 64 KiB) read exactly") {
  const std::vector<unsigned char> z = numpy_fixture_bytes("compressed.npz");
  // What numpy wrote: every member deflated (method 8), flags 0, with numpy's ZIP64 extra field in
  // the local header; 'visible' is the shape (3728 bytes, a well-compressible member) and
  // 'big' deflates to more than 64 KiB.
  const std::size_t vis = numpy_central_entry(z, "visible.npy"), big = numpy_central_entry(z, "big.npy");
  CHECK(numpy_le(z, vis + 8, 2) == 0);
  CHECK(numpy_le(z, vis + 10, 2) == 8);
  CHECK(numpy_le(z, vis + 24, 4) == 3728);
  CHECK(numpy_le(z, vis + 20, 4) < 1000);
  CHECK(numpy_le(z, big + 20, 4) > 65536);
  const std::size_t local = numpy_le(z, vis + 42, 4);
  CHECK(numpy_le(z, local + 28, 2) == 20);  // the ZIP64 extra field: id, size, two 8-byte sizes

  const auto arrays = trainer::files::parse_npz(z, "compressed.npz");
  CHECK(arrays.size() == numpy_archive_table().size() + 1);
  for (const auto& entry : numpy_archive_table()) {
    const std::string& name = entry.first;  // (a structured binding cannot be CAPTUREd in C++17)
    CAPTURE(name);
    REQUIRE(arrays.count(name) == 1);
    CHECK(numpy_mismatches(arrays.at(name), entry.second) == 0);
  }
  // A Fortran-order member (np.asfortranarray) comes back in C order.
  CHECK(numpy_mismatches(arrays.at("fortran"), numpy_fortran_table().at("fortran_f32_3d")) == 0);
}

TEST_CASE("numpy files: np.savez (stored members, one in Fortran order)") {
  const std::vector<unsigned char> z = numpy_fixture_bytes("stored.npz");
  CHECK(numpy_le(z, numpy_central_entry(z, "f64.npy") + 10, 2) == 0);
  const auto arrays = trainer::files::parse_npz(z, "stored.npz");
  CHECK(arrays.size() == 4);
  for (const char* name : {"f64", "b1", "i32"}) {
    CAPTURE(name);
    CHECK(numpy_mismatches(arrays.at(name), numpy_archive_table().at(name)) == 0);
  }
  CHECK(numpy_mismatches(arrays.at("fortran"), numpy_fortran_table().at("fortran_i32_3d")) == 0);
}

TEST_CASE("numpy files: np.savez_compressed into a pipe (flag bit 3, sizes in data descriptors)") {
  const std::vector<unsigned char> z = numpy_fixture_bytes("streamed.npz");
  const std::size_t e = numpy_central_entry(z, "visible.npy");
  CHECK(numpy_le(z, e + 8, 2) == 8);  // bit 3: CRC-32 and sizes follow the data
  const std::size_t local = numpy_le(z, e + 42, 4);
  CHECK(numpy_le(z, local + 14, 4) == 0);  // CRC-32 0 in the local header
  const auto arrays = trainer::files::parse_npz(z, "streamed.npz");
  CHECK(arrays.size() == 3);
  for (const char* name : {"f64", "visible", "i64"}) {
    CAPTURE(name);
    CHECK(numpy_mismatches(arrays.at(name), numpy_archive_table().at(name)) == 0);
  }
}

TEST_CASE("numpy files: Fortran-order .npy of every dtype, ranks 2 to 4, read in C order (file and memory)") {
  for (const auto& entry : numpy_fortran_table()) {
    const std::string& name = entry.first;
    const NumpyFixture& f = entry.second;
    CAPTURE(name);
    const std::string path = kNumpyDir + "/" + name + ".npy";
    CHECK(smg::test::slurp(path).find("'fortran_order': True") != std::string::npos);
    CHECK(numpy_mismatches(npy::read(path), f) == 0);
    const std::vector<unsigned char> b = numpy_fixture_bytes(name + ".npy");
    CHECK(numpy_mismatches(npy::parse(b.data(), b.size(), name), f) == 0);
  }
}

TEST_CASE("numpy files: a broken member is an error naming the archive and the member") {
  const std::vector<unsigned char> good = numpy_fixture_bytes("compressed.npz");
  const std::size_t e = numpy_central_entry(good, "visible.npy");
  const std::uint64_t csize = numpy_le(good, e + 20, 4), usize = numpy_le(good, e + 24, 4);
  const std::size_t local = numpy_le(good, e + 42, 4);
  const std::size_t data = local + 30 + numpy_le(good, local + 26, 2) + numpy_le(good, local + 28, 2);
  const std::string p = "priors/tracks.npz: member 'visible.npy'";
  auto patched = [&](const std::function<void(std::vector<unsigned char>&)>& f) {
    std::vector<unsigned char> z = good;
    f(z);
    return npz_error(z);
  };
  CHECK(npz_error(good) == "no error");
  // Truncated member: the recorded compressed size cut in half.
  CHECK(patched([&](auto& z) { numpy_put_le(z, e + 20, csize / 2, 4); }) == p + ": deflate data ends early (truncated member)");
  CHECK(patched([&](auto& z) { numpy_put_le(z, e + 16, numpy_le(z, e + 16, 4) ^ 1u, 4); }) ==
        "priors/tracks.npz: CRC-32 mismatch in member 'visible.npy' (corrupt archive)");
  // A recorded size that differs from the one the member's .npy header declares: refused once the
  // header is inflated, before the rest (file_formats.hpp, the bounded inflater).
  CHECK(patched([&](auto& z) { numpy_put_le(z, e + 24, usize - 1, 4); }) == p + ": its .npy header declares 3728 bytes, the archive records 3727");
  CHECK(patched([&](auto& z) { numpy_put_le(z, e + 24, usize + 1, 4); }) == p + ": its .npy header declares 3728 bytes, the archive records 3729");
  CHECK(patched([&](auto& z) { numpy_put_le(z, e + 10, 12, 2); }) ==
        "priors/tracks.npz: member 'visible.npy' uses compression method 12 (only stored and deflate are supported)");
  // A final block of the reserved type 3 (the first three bits of the stream: 1, 11).
  CHECK(patched([&](auto& z) { z[data] = 0x07; }) == p + ": corrupt deflate data (zlib: invalid block type)");
  CHECK(patched([&](auto& z) { numpy_put_le(z, e + 24, usize * 2000, 4); }) ==
        "priors/tracks.npz: member 'visible.npy' records 7456000 bytes from " + std::to_string(csize) +
            " compressed (more than DEFLATE's 1032:1; a corrupt or hostile archive)");
}

TEST_CASE("numpy files: archives numpy writes at test time (random, several sizes) are read element for element") {
  if (std::system("/usr/bin/python3 -c 'import numpy' >/dev/null 2>&1") != 0) {
    MESSAGE("skipped: no /usr/bin/python3 with numpy (Debian: apt-get install python3-numpy); the checked-in "
            "fixtures above still ran");
    return;
  }
  const fs::path work = fs::temp_directory_path() / "smg_test_trainer_numpy_random";
  fs::remove_all(work);
  const std::string script = kNumpyDir + "/make_random.py";
  for (const int seed : {1, 2}) {
    CAPTURE(seed);
    REQUIRE(std::system(("/usr/bin/python3 " + script + " " + work.string() + " " + std::to_string(seed)).c_str()) == 0);
    const auto arrays =
        trainer::files::parse_npz(trainer::files::read_bytes((work / "random.npz").string(), "random.npz"), "random.npz");
    std::ifstream manifest(work / "manifest.txt");
    std::string line;
    std::size_t members = 0;
    while (std::getline(manifest, line)) {
      std::istringstream s(line);
      std::string name, dtype;
      s >> name >> dtype;
      std::vector<std::int64_t> shape;
      for (std::int64_t d = 0; s >> d;) shape.push_back(d);
      CAPTURE(name);
      REQUIRE(arrays.count(name) == 1);
      const npy::Array& a = arrays.at(name);
      CHECK(a.shape == shape);
      const std::string expected = smg::test::slurp(work / (name + ".bin"));
      CHECK(a.bytes.size() == expected.size());
      CHECK(std::string(a.bytes.begin(), a.bytes.end()) == expected);  // every element, bit for bit
      ++members;
    }
    CHECK(members == arrays.size());
    CHECK(members == 29);  // 4 sizes x 6 kinds + 5 shaped arrays (make_random.py)
  }
  fs::remove_all(work);
}
