// Tests of examples/common/npy.hpp (and the case-directory loader built on it): round trips for
// every supported dtype, byte-exact agreement with the NumPy format, and clear errors for
// corrupt, truncated and unsupported files.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "case_dir.hpp"
#include "npy.hpp"
#include "output_set.hpp"
#include "support/errors.hpp"
#include "support/files.hpp"

namespace fs = std::filesystem;

namespace {
fs::path temp_dir(const std::string& name) {
  const fs::path p = fs::temp_directory_path() / ("smg_test_npy_" + name);
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}
using smg::test::write_bytes;
std::string read_bytes(const fs::path& p) { return smg::test::slurp(p); }
std::string npy_error_of(const std::string& path) {
  return smg::test::error_message<npy::Error>([&] { npy::read(path); });
}
// A v1.0 file exactly as numpy.save writes it (header padded with spaces to 64 bytes, '\n').
std::string numpy_file(const std::string& dict, const std::string& data) {
  std::string header = dict;
  const std::size_t total = 10 + header.size() + 1;
  header.append((64 - total % 64) % 64, ' ');
  header += '\n';
  std::string out = "\x93NUMPY";
  out += '\x01';
  out += '\x00';
  out += static_cast<char>(header.size() & 0xff);
  out += static_cast<char>(header.size() >> 8);
  return out + header + data;
}
template <class T>
void round_trip(const fs::path& dir, const std::string& name, std::vector<T> values,
                std::vector<std::int64_t> shape) {
  const std::string path = (dir / name).string();
  npy::write(path, values, shape);
  const npy::Array a = npy::read(path);
  CHECK(a.dtype == npy::dtype_of<T>());
  CHECK(a.shape == shape);
  CHECK(a.as<T>() == values);
}
}  // namespace

TEST_CASE("npy round trips for float32, float64, int32, int64, uint8 and bool-as-uint8") {
  const fs::path dir = temp_dir("roundtrip");
  round_trip<float>(dir, "f.npy", {1.5f, -2.f, 3.25f, std::numeric_limits<float>::max(), 0.f, -0.f}, {2, 3});
  round_trip<double>(dir, "d.npy", {1e-300, -1e300, 0.1, 7.0}, {4});
  round_trip<std::int32_t>(dir, "i.npy", {-1, 0, 2147483647, -2147483647 - 1}, {2, 1, 2});
  round_trip<std::int64_t>(dir, "l.npy", {-1, 0, 1LL << 40}, {3, 1});
  round_trip<std::uint8_t>(dir, "u.npy", {0, 1, 255}, {3});
  round_trip<double>(dir, "empty.npy", {}, {0, 3});
  round_trip<double>(dir, "scalar.npy", {42.0}, {});
  fs::remove_all(dir);
}

TEST_CASE("npy writer output is byte-identical to numpy.save") {
  const fs::path dir = temp_dir("bytes");
  const std::vector<double> v = {1.0, 2.0, 3.0, 4.0, 5.0, 6.0};
  npy::write((dir / "a.npy").string(), v, {2, 3});
  const std::string data(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(double));
  CHECK(read_bytes(dir / "a.npy") ==
        numpy_file("{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }", data));
  const std::vector<std::int32_t> w = {7, 8};
  npy::write((dir / "b.npy").string(), w, {2});
  CHECK(read_bytes(dir / "b.npy") ==
        numpy_file("{'descr': '<i4', 'fortran_order': False, 'shape': (2,), }",
                   std::string(reinterpret_cast<const char*>(w.data()), 8)));
  fs::remove_all(dir);
}

TEST_CASE("npy reads numpy's bool arrays and version 2.0 headers") {
  const fs::path dir = temp_dir("bool");
  write_bytes(dir / "b.npy", numpy_file("{'descr': '|b1', 'fortran_order': False, 'shape': (3,), }",
                                        std::string("\x01\x00\x01", 3)));
  const npy::Array a = npy::read((dir / "b.npy").string());
  CHECK(a.dtype == npy::DType::b1);
  CHECK(a.as<int>() == std::vector<int>{1, 0, 1});

  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (1,), }";
  header.append((64 - (12 + header.size() + 1) % 64) % 64, ' ');
  header += '\n';
  std::string v2 = "\x93NUMPY";
  v2 += '\x02';
  v2 += '\x00';
  v2 += static_cast<char>(header.size());
  v2 += std::string(3, '\0');
  const float one = 1.f;
  v2 += header + std::string(reinterpret_cast<const char*>(&one), 4);
  write_bytes(dir / "v2.npy", v2);
  CHECK(npy::read((dir / "v2.npy").string()).as<float>() == std::vector<float>{1.f});
  fs::remove_all(dir);
}

TEST_CASE("npy errors: corrupt, truncated and unsupported files name the file and the problem") {
  const fs::path dir = temp_dir("corrupt");
  const std::string ok_dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (2,), }";
  const std::string data16(16, '\0');
  auto path = [&](const char* n) { return (dir / n).string(); };

  CHECK(npy_error_of(path("missing.npy")) == path("missing.npy") + ": cannot open");
  write_bytes(dir / "magic.npy", "PK\x03\x04 this is a zip");
  CHECK(npy_error_of(path("magic.npy")) == path("magic.npy") + ": not an .npy file (bad magic)");
  write_bytes(dir / "short.npy", "\x93NUM");
  CHECK(npy_error_of(path("short.npy")) == path("short.npy") + ": truncated (no npy preamble)");
  const std::string full = numpy_file(ok_dict, data16);
  write_bytes(dir / "trunc_header.npy", full.substr(0, 40));
  CHECK(npy_error_of(path("trunc_header.npy")) == path("trunc_header.npy") + ": truncated header");
  write_bytes(dir / "trunc_data.npy", full.substr(0, full.size() - 3));
  CHECK(npy_error_of(path("trunc_data.npy")) ==
        path("trunc_data.npy") + ": truncated data (13 of 16 bytes for shape [2])");
  write_bytes(dir / "long.npy", full + "xx");
  CHECK(npy_error_of(path("long.npy")) ==
        path("long.npy") + ": corrupt file (2 bytes after the data of shape [2])");
  // Fortran order is read (transposed to C order; a 1-D array is the same in both), with the
  // same size checks as C order.
  write_bytes(dir / "fortran.npy",
              numpy_file("{'descr': '<f8', 'fortran_order': True, 'shape': (2,), }", data16));
  CHECK(npy_error_of(path("fortran.npy")) == "");
  CHECK(npy::read(path("fortran.npy")).bytes == std::vector<unsigned char>(data16.begin(), data16.end()));
  write_bytes(dir / "fortran_short.npy",
              numpy_file("{'descr': '<f8', 'fortran_order': True, 'shape': (2, 1), }", data16.substr(0, 12)));
  CHECK(npy_error_of(path("fortran_short.npy")) ==
        path("fortran_short.npy") + ": truncated data (12 of 16 bytes for shape [2, 1])");
  write_bytes(dir / "fortran_bad.npy",
              numpy_file("{'descr': '<f8', 'fortran_order': Maybe, 'shape': (2,), }", data16));
  CHECK(npy_error_of(path("fortran_bad.npy")) == path("fortran_bad.npy") + ": corrupt header (fortran_order Maybe)");
  write_bytes(dir / "big.npy", numpy_file("{'descr': '>f8', 'fortran_order': False, 'shape': (2,), }", data16));
  CHECK(npy_error_of(path("big.npy")) ==
        path("big.npy") + ": big-endian dtype >f8 is not supported (use little-endian)");
  write_bytes(dir / "complex.npy", numpy_file("{'descr': '<c8', 'fortran_order': False, 'shape': (2,), }", data16));
  CHECK(npy_error_of(path("complex.npy")).find("unsupported dtype <c8") != std::string::npos);
  write_bytes(dir / "noshape.npy", numpy_file("{'descr': '<f8', 'fortran_order': False, }", data16));
  CHECK(npy_error_of(path("noshape.npy")) == path("noshape.npy") + ": corrupt header (no 'shape')");
  write_bytes(dir / "badshape.npy", numpy_file("{'descr': '<f8', 'fortran_order': False, 'shape': (2, x), }", data16));
  CHECK(npy_error_of(path("badshape.npy")).find("corrupt header (shape") != std::string::npos);
  write_bytes(dir / "badbool.npy", numpy_file("{'descr': '|b1', 'fortran_order': False, 'shape': (2,), }", "\x01\x07"));
  CHECK(npy_error_of(path("badbool.npy")) == path("badbool.npy") + ": corrupt bool data (byte value 7)");
  write_bytes(dir / "v9.npy", std::string("\x93NUMPY\x09\x00", 8) + std::string(60, ' '));
  CHECK(npy_error_of(path("v9.npy")) == path("v9.npy") + ": unsupported npy version 9");
  fs::remove_all(dir);
}

TEST_CASE("a float array is never silently read as integers") {
  const fs::path dir = temp_dir("kinds");
  npy::write((dir / "f.npy").string(), std::vector<double>{1.5}, {1});
  CHECK_THROWS_WITH_AS(npy::read((dir / "f.npy").string()).as<std::int64_t>("f.npy"),
                       "f.npy: dtype float64 where an integer or bool array is expected", npy::Error);
  fs::remove_all(dir);
}

TEST_CASE("CaseDir: dtype, shape, NaN and 0/1 checks name the file") {
  const fs::path dir = temp_dir("case");
  npy::write((dir / "positions.npy").string(), std::vector<float>(2 * 4 * 3, 0.5f), {2, 4, 3});
  npy::write((dir / "idx.npy").string(), std::vector<double>(4, 1.0), {4});
  std::vector<double> with_nan(6, 0.0);
  with_nan[4] = std::numeric_limits<double>::quiet_NaN();
  npy::write((dir / "nan.npy").string(), with_nan, {2, 3});
  npy::write((dir / "vis.npy").string(), std::vector<std::uint8_t>{0, 1, 2, 1}, {2, 2});
  const cli::CaseDir c(dir);
  const auto x = c.load<double>("positions.npy", {{"T"}, {"N"}, {"", 3}});
  CHECK(x.shape == std::vector<std::int64_t>{2, 4, 3});
  CHECK(x.data[5] == 0.5);
  const std::string d = dir.string() + "/";
  CHECK_THROWS_WITH(c.load<double>("positions.npy", {{"T", 3}, {"N"}, {"", 3}}),
                    (d + "positions.npy: expected shape [T=3, N=any, 3], got [2, 4, 3]").c_str());
  CHECK_THROWS_WITH(c.load<std::int64_t>("idx.npy", {{"N"}}),
                    (d + "idx.npy: dtype float64, expected int32 or int64").c_str());
  CHECK_THROWS_WITH(c.load<double>("nan.npy", {{""}, {""}}), (d + "nan.npy: NaN at index [1, 1]").c_str());
  CHECK_THROWS_WITH(c.load<std::uint8_t>("vis.npy", {{"T"}, {"N"}}),
                    (d + "vis.npy: value 2 at index [1, 0] (expected 0 or 1)").c_str());
  CHECK_THROWS_WITH(c.load<double>("absent.npy", {{"N"}}), (d + "absent.npy: missing required file").c_str());
  CHECK_FALSE(c.load_optional<double>("absent.npy", {{"N"}}).has_value());
  fs::remove_all(dir);
}

TEST_CASE("OutputSet writes all files or none") {
  const fs::path dir = temp_dir("outputs");
  cli::OutputSet ok;
  ok.add("a.npy", std::vector<double>{1, 2}, {2});
  ok.add("b.npy", std::vector<std::int32_t>{3}, {1});
  ok.commit(dir / "out");
  CHECK(fs::exists(dir / "out" / "a.npy"));
  CHECK(fs::exists(dir / "out" / "b.npy"));

  cli::OutputSet bad;
  bad.add("c.npy", std::vector<double>{1, 2}, {2});
  bad.add("d.npy", std::vector<double>{1, 2, 3}, {2});  // wrong count: fails after c.npy
  CHECK_THROWS_AS(bad.commit(dir / "fresh"), npy::Error);
  CHECK_FALSE(fs::exists(dir / "fresh"));  // the folder it created is gone again
  CHECK_THROWS_AS(bad.commit(dir / "out"), npy::Error);
  CHECK_FALSE(fs::exists(dir / "out" / "c.npy"));
  CHECK_FALSE(fs::exists(dir / "out" / ".c.npy.partial"));
  fs::remove_all(dir);
}

TEST_CASE("npy: float16 is read and converted to float exactly; parse() reads an image in memory") {
  // 1.0, -2.5, 65504 (max half), 2^-24 (smallest subnormal), +inf, NaN, -0.
  const std::uint16_t h[7] = {0x3C00, 0xC100, 0x7BFF, 0x0001, 0x7C00, 0x7E00, 0x8000};
  const std::string file = numpy_file("{'descr': '<f2', 'fortran_order': False, 'shape': (7,), }",
                                      std::string(reinterpret_cast<const char*>(h), sizeof h));
  const auto* data = reinterpret_cast<const unsigned char*>(file.data());
  const npy::Array a = npy::parse(data, file.size(), "mem.npy");
  CHECK(a.dtype == npy::DType::f16);
  const std::vector<float> v = a.as<float>();
  CHECK(v[0] == 1.0f);
  CHECK(v[1] == -2.5f);
  CHECK(v[2] == 65504.0f);
  CHECK(v[3] == std::ldexp(1.0f, -24));
  CHECK(std::isinf(v[4]));
  CHECK(std::isnan(v[5]));
  CHECK((v[6] == 0.0f && std::signbit(v[6])));
  CHECK_THROWS_WITH_AS(a.as<std::int32_t>("h"), "h: dtype float16 where an integer or bool array is expected", npy::Error);
  // The same checks as read(): truncation, trailing bytes, Fortran order.
  CHECK_THROWS_WITH_AS(npy::parse(data, file.size() - 1, "mem.npy"),
                       "mem.npy: truncated data (13 of 14 bytes for shape [7])", npy::Error);
  const std::string longer = file + "x";
  CHECK_THROWS_WITH_AS(npy::parse(reinterpret_cast<const unsigned char*>(longer.data()), longer.size(), "m"),
                       "m: corrupt file (1 bytes after the data of shape [7])", npy::Error);
  // Fortran order [2, 3] int32: the file holds column after column; read() gives rows.
  const std::int32_t cols[6] = {0, 3, 1, 4, 2, 5};
  const std::string f = numpy_file("{'descr': '<i4', 'fortran_order': True, 'shape': (2, 3), }",
                                   std::string(reinterpret_cast<const char*>(cols), sizeof cols));
  const npy::Array fa = npy::parse(reinterpret_cast<const unsigned char*>(f.data()), f.size(), "f.npy");
  CHECK(fa.shape == std::vector<std::int64_t>{2, 3});
  CHECK(fa.as<std::int32_t>() == std::vector<std::int32_t>{0, 1, 2, 3, 4, 5});
  CHECK_THROWS_WITH_AS(npy::parse(reinterpret_cast<const unsigned char*>(f.data()), f.size() - 1, "f.npy"),
                       "f.npy: truncated data (23 of 24 bytes for shape [2, 3])", npy::Error);
  CHECK_THROWS_WITH_AS(npy::parse(data, 5, "s.npy"), "s.npy: truncated (no npy preamble)", npy::Error);
  // to_bytes writes what read() reads.
  const float vals[3] = {1.5f, -2.0f, 3.25f};
  const std::string bytes = npy::to_bytes(vals, {3});
  const npy::Array b = npy::parse(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), "b");
  CHECK(b.as<float>() == std::vector<float>{1.5f, -2.0f, 3.25f});
}
