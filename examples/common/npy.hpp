// examples/common/npy.hpp — minimal, strict .npy reader/writer (NumPy format 1.0/2.0/3.0).
//
// Part of the examples, not the library: smg itself works on views over caller memory; this is
// how smg_cli and the example programs get such memory from NumPy files.
// Supported: little-endian float16 (read only, converted to float)/float32/float64/int32/int64/
// uint8/bool, in C or Fortran order (a Fortran-order file is transposed to C order when read, as
// numpy.load does transparently; arrays are always written in C order). Everything else
// (big-endian, object arrays, truncated or over-long files, bad headers) is an npy::Error whose
// message names the file and the problem.
// parse() reads an .npy image already in memory (a member of an .npz archive); to_bytes() makes
// one.
#pragma once

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

namespace npy {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class DType { f16, f32, f64, i32, i64, u8, b1 };

inline const char* dtype_name(DType d) {
  switch (d) {
    case DType::f16: return "float16";
    case DType::f32: return "float32";
    case DType::f64: return "float64";
    case DType::i32: return "int32";
    case DType::i64: return "int64";
    case DType::u8: return "uint8";
    case DType::b1: return "bool";
  }
  return "?";
}
inline std::size_t dtype_size(DType d) {
  switch (d) {
    case DType::f16: return 2;
    case DType::f32: case DType::i32: return 4;
    case DType::f64: case DType::i64: return 8;
    case DType::u8: case DType::b1: return 1;
  }
  return 0;
}
inline bool is_float(DType d) { return d == DType::f16 || d == DType::f32 || d == DType::f64; }
inline bool is_integer(DType d) { return d == DType::i32 || d == DType::i64; }
inline bool is_boolish(DType d) { return d == DType::u8 || d == DType::b1; }

template <class T> constexpr DType dtype_of();
template <> constexpr DType dtype_of<float>() { return DType::f32; }
template <> constexpr DType dtype_of<double>() { return DType::f64; }
template <> constexpr DType dtype_of<std::int32_t>() { return DType::i32; }
template <> constexpr DType dtype_of<std::int64_t>() { return DType::i64; }
template <> constexpr DType dtype_of<std::uint8_t>() { return DType::u8; }
template <> constexpr DType dtype_of<bool>() { return DType::b1; }

// IEEE 754 binary16 (bit pattern) to float, exactly (every half value is a float).
inline float half_to_float(std::uint16_t h) {
  const unsigned exponent = (h >> 10) & 0x1fu, mantissa = h & 0x3ffu;
  float v;
  if (exponent == 0) v = std::ldexp(static_cast<float>(mantissa), -24);  // zero, subnormal
  else if (exponent == 31) v = mantissa ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity();
  else v = std::ldexp(static_cast<float>(mantissa | 0x400u), static_cast<int>(exponent) - 25);
  return (h & 0x8000u) ? -v : v;
}

inline std::string shape_string(const std::vector<std::int64_t>& shape) {
  std::ostringstream s;
  s << "[";
  for (std::size_t i = 0; i < shape.size(); ++i) s << (i ? ", " : "") << shape[i];
  s << "]";
  return s.str();
}

// An array read from disk: dtype, shape and the raw little-endian bytes.
struct Array {
  DType dtype = DType::f64;
  std::vector<std::int64_t> shape;
  std::vector<unsigned char> bytes;

  // Element count; throws npy::Error on a negative dimension or an overflowing product.
  std::int64_t size() const;
  // Converted copy. Float arrays convert to float or double; integer and bool arrays to any
  // integer type (or to float/double); a float array never silently becomes an integer one.
  template <class T>
  std::vector<T> as(const std::string& what = "array") const {
    constexpr bool want_float = std::is_floating_point_v<T>;
    if (!want_float && is_float(dtype))
      throw Error(what + ": dtype " + dtype_name(dtype) + " where an integer or bool array is expected");
    const std::int64_t n = size();
    if (static_cast<std::uint64_t>(n) > bytes.size() / dtype_size(dtype))
      throw Error(what + ": " + std::to_string(bytes.size()) + " data bytes for shape " +
                  shape_string(shape));
    std::vector<T> out(static_cast<std::size_t>(n));
    const unsigned char* p = bytes.data();
    for (std::size_t k = 0; k < out.size(); ++k) {
      switch (dtype) {
        case DType::f16: {
          std::uint16_t v;
          std::memcpy(&v, p + 2 * k, 2);
          out[k] = static_cast<T>(half_to_float(v));
          break;
        }
        case DType::f32: { float v; std::memcpy(&v, p + 4 * k, 4); out[k] = static_cast<T>(v); break; }
        case DType::f64: { double v; std::memcpy(&v, p + 8 * k, 8); out[k] = static_cast<T>(v); break; }
        case DType::i32: {
          std::int32_t v;
          std::memcpy(&v, p + 4 * k, 4);
          if constexpr (std::is_integral_v<T> && sizeof(T) < 4) {
            if (v < static_cast<std::int32_t>(std::numeric_limits<T>::min()) ||
                v > static_cast<std::int32_t>(std::numeric_limits<T>::max()))
              throw Error(what + ": value " + std::to_string(v) + " at flat index " + std::to_string(k) +
                          " does not fit in the target integer type");
          }
          out[k] = static_cast<T>(v);
          break;
        }
        case DType::i64: {
          std::int64_t v;
          std::memcpy(&v, p + 8 * k, 8);
          if constexpr (std::is_integral_v<T>) {
            if (v < static_cast<std::int64_t>(std::numeric_limits<T>::min()) ||
                (v > 0 && static_cast<std::uint64_t>(v) > static_cast<std::uint64_t>(std::numeric_limits<T>::max())))
              throw Error(what + ": value " + std::to_string(v) + " at flat index " + std::to_string(k) +
                          " does not fit in " + (sizeof(T) == 4 ? "int32" : "the target integer type"));
          }
          out[k] = static_cast<T>(v);
          break;
        }
        case DType::u8: case DType::b1: out[k] = static_cast<T>(p[k]); break;
      }
    }
    return out;
  }
};

namespace detail {
// a * b into out; false on overflow of std::uint64_t.
inline bool mul_u64(std::uint64_t a, std::uint64_t b, std::uint64_t& out) {
  if (a != 0 && b > std::numeric_limits<std::uint64_t>::max() / a) return false;
  out = a * b;
  return true;
}
// Element count of `shape`, checked: every dimension >= 0 and the product (and the product
// times `elem_size`) representable in int64 (and in size_t). Throws Error("<what>: ...").
inline std::int64_t checked_count(const std::vector<std::int64_t>& shape, std::size_t elem_size,
                                  const std::string& what) {
  const std::uint64_t limit = std::min<std::uint64_t>(
      static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()),
      static_cast<std::uint64_t>(std::numeric_limits<std::size_t>::max()));
  std::uint64_t n = 1;
  for (const auto d : shape) {
    if (d < 0) throw Error(what + ": negative dimension in shape " + shape_string(shape));
    if (!mul_u64(n, static_cast<std::uint64_t>(d), n) || n > limit)
      throw Error(what + ": shape " + shape_string(shape) + " overflows the element count");
  }
  std::uint64_t bytes = 0;
  if (!mul_u64(n, elem_size == 0 ? 1 : elem_size, bytes) || bytes > limit)
    throw Error(what + ": shape " + shape_string(shape) + " overflows the byte count");
  return static_cast<std::int64_t>(n);
}
inline bool host_is_little_endian() {
  const std::uint16_t one = 1;
  unsigned char c;
  std::memcpy(&c, &one, 1);
  return c == 1;
}
inline std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\n");
  return s.substr(b, e - b + 1);
}
// Value of 'key' in the header dict, as raw text up to the next top-level comma or brace.
inline std::string dict_value(const std::string& header, const std::string& key,
                              const std::string& path) {
  const std::string k1 = "'" + key + "'";
  auto pos = header.find(k1);
  if (pos == std::string::npos) throw Error(path + ": corrupt header (no '" + key + "')");
  pos = header.find(':', pos + k1.size());
  if (pos == std::string::npos) throw Error(path + ": corrupt header (no value for '" + key + "')");
  ++pos;
  int depth = 0;
  std::size_t end = pos;
  for (; end < header.size(); ++end) {
    const char c = header[end];
    if (c == '(' || c == '[') ++depth;
    else if (c == ')' || c == ']') --depth;
    else if ((c == ',' || c == '}') && depth == 0) break;
  }
  return trim(header.substr(pos, end - pos));
}
inline DType parse_descr(const std::string& v, const std::string& path) {
  if (v.size() < 3 || (v.front() != '\'' && v.front() != '"'))
    throw Error(path + ": corrupt header (descr " + v + ")");
  const std::string d = v.substr(1, v.size() - 2);
  if (d == "<f2") return DType::f16;
  if (d == "<f4") return DType::f32;
  if (d == "<f8") return DType::f64;
  if (d == "<i4") return DType::i32;
  if (d == "<i8") return DType::i64;
  if (d == "|u1" || d == "<u1") return DType::u8;
  if (d == "|b1") return DType::b1;
  if (!d.empty() && d[0] == '>')
    throw Error(path + ": big-endian dtype " + d + " is not supported (use little-endian)");
  throw Error(path + ": unsupported dtype " + d +
              " (supported: float16, float32, float64, int32, int64, uint8, bool)");
}
inline std::vector<std::int64_t> parse_shape(const std::string& v, const std::string& path) {
  if (v.size() < 2 || v.front() != '(' || v.back() != ')')
    throw Error(path + ": corrupt header (shape " + v + ")");
  std::vector<std::int64_t> shape;
  std::string inner = v.substr(1, v.size() - 2);
  std::stringstream ss(inner);
  std::string item;
  while (std::getline(ss, item, ',')) {
    item = trim(item);
    if (item.empty()) continue;
    if (item[0] == '-') throw Error(path + ": negative dimension in shape " + v);
    for (char c : item)
      if (c < '0' || c > '9') throw Error(path + ": corrupt header (shape " + v + ")");
    if (item.size() > 15) throw Error(path + ": corrupt header (shape dimension too large)");
    shape.push_back(std::stoll(item));
  }
  return shape;
}
// dtype and shape from the header dict text; returns whether the data is in Fortran order.
// Throws Error("<path>: ...").
inline bool parse_header_dict(const std::string& header, const std::string& path, Array& a) {
  if (header.find('{') == std::string::npos || header.find('}') == std::string::npos)
    throw Error(path + ": corrupt header (no dict)");
  a.dtype = parse_descr(dict_value(header, "descr", path), path);
  const std::string fo = dict_value(header, "fortran_order", path);
  if (fo != "True" && fo != "False") throw Error(path + ": corrupt header (fortran_order " + fo + ")");
  a.shape = parse_shape(dict_value(header, "shape", path), path);
  return fo == "True";
}
// Reorders a.bytes from Fortran order (first index fastest) to C order (last index fastest),
// element by element (dtype_size bytes), for any rank; ranks 0 and 1 are the same in both.
inline void fortran_to_c(Array& a) {
  const std::size_t rank = a.shape.size();
  if (rank < 2 || a.bytes.empty()) return;
  const std::size_t e = dtype_size(a.dtype);
  // Fortran strides (in elements) of each index.
  std::vector<std::size_t> stride(rank, 1);
  for (std::size_t k = 1; k < rank; ++k) stride[k] = stride[k - 1] * static_cast<std::size_t>(a.shape[k - 1]);
  std::vector<unsigned char> c(a.bytes.size());
  std::vector<std::size_t> index(rank, 0);
  const std::size_t count = a.bytes.size() / e;
  std::size_t from = 0;  // Fortran offset of `index`
  for (std::size_t to = 0; to < count; ++to) {
    std::memcpy(c.data() + to * e, a.bytes.data() + from * e, e);
    // Next C-order index: the last index runs fastest.
    for (std::size_t k = rank; k-- > 0;) {
      if (++index[k] < static_cast<std::size_t>(a.shape[k])) {
        from += stride[k];
        break;
      }
      from -= stride[k] * (index[k] - 1);
      index[k] = 0;
    }
  }
  a.bytes.swap(c);
}
inline void check_bool_bytes(const Array& a, const std::string& path) {
  if (a.dtype == DType::b1)
    for (auto c : a.bytes)
      if (c > 1) throw Error(path + ": corrupt bool data (byte value " + std::to_string(c) + ")");
}

// The preamble of an .npy image: its own length (10 bytes for version 1.0, 12 for 2.0 and 3.0)
// and the header length it declares.
struct Preamble {
  std::uint64_t length = 0;
  std::uint64_t header_len = 0;
};

// Reads the preamble of the in-memory .npy image whose first `size` bytes are at `data`, for
// declared_size and parse alike. std::nullopt says "need more bytes": the bytes end before the
// preamble or the header it declares, which declared_size answers with 0 and parse with an error.
// Throws Error("<what>: ...") on a bad magic (checked on as many of its 6 bytes as there are, so a
// partial image fails early) or an unsupported version.
inline std::optional<Preamble> read_preamble(const unsigned char* data, std::size_t size, const std::string& what) {
  if (std::memcmp(data, "\x93NUMPY", std::min<std::size_t>(size, 6)) != 0) throw Error(what + ": not an .npy file (bad magic)");
  if (size < 10) return std::nullopt;
  const int major = data[6];
  Preamble p;
  if (major == 1) {
    p.header_len = data[8] | (data[9] << 8);
    p.length = 10;
  } else if (major == 2 || major == 3) {
    if (size < 12) return std::nullopt;
    p.header_len = data[8] | (data[9] << 8) | (data[10] << 16) | (static_cast<std::uint64_t>(data[11]) << 24);
    p.length = 12;
  } else {
    throw Error(what + ": unsupported npy version " + std::to_string(major));
  }
  if (p.length + p.header_len > size) return std::nullopt;
  return p;
}
}  // namespace detail

inline std::int64_t Array::size() const { return detail::checked_count(shape, dtype_size(dtype), "array"); }

// Reads a whole .npy file. Throws npy::Error("<path>: <problem>"). Only regular files are read
// (a FIFO, device or directory is refused before it is opened, so nothing can block). Every size
// (header length, element count, byte count) is checked for overflow and against the file size
// before anything is allocated. max_bytes > 0: an array whose data exceeds it is refused (the
// caller's memory limit) before it is read.
inline Array read(const std::string& path, std::uint64_t max_bytes = 0) {
  if (!detail::host_is_little_endian()) throw Error(path + ": this reader needs a little-endian host");
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) throw Error(path + ": cannot open");
  if (!fs::is_regular_file(st)) throw Error(path + ": not a regular file");
  const std::uint64_t file_size = fs::file_size(path, ec);
  if (ec) throw Error(path + ": cannot read the file size");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(path + ": cannot open");
  unsigned char magic[8];
  if (!f.read(reinterpret_cast<char*>(magic), 8)) throw Error(path + ": truncated (no npy preamble)");
  if (std::memcmp(magic, "\x93NUMPY", 6) != 0) throw Error(path + ": not an .npy file (bad magic)");
  const int major = magic[6];
  std::uint32_t header_len = 0;
  if (major == 1) {
    unsigned char b[2];
    if (!f.read(reinterpret_cast<char*>(b), 2)) throw Error(path + ": truncated header");
    header_len = b[0] | (b[1] << 8);
  } else if (major == 2 || major == 3) {
    unsigned char b[4];
    if (!f.read(reinterpret_cast<char*>(b), 4)) throw Error(path + ": truncated header");
    header_len = b[0] | (b[1] << 8) | (b[2] << 16) | (static_cast<std::uint32_t>(b[3]) << 24);
    if (header_len > (1u << 24)) throw Error(path + ": corrupt header (length)");
  } else {
    throw Error(path + ": unsupported npy version " + std::to_string(major));
  }
  const std::uint64_t preamble = major == 1 ? 10 : 12;
  if (preamble + header_len > file_size) throw Error(path + ": truncated header");
  std::string header(header_len, '\0');
  if (!f.read(header.data(), header_len)) throw Error(path + ": truncated header");
  Array a;
  const bool fortran = detail::parse_header_dict(header, path, a);

  const std::int64_t count = detail::checked_count(a.shape, dtype_size(a.dtype), path);
  const std::uint64_t nbytes = static_cast<std::uint64_t>(count) * dtype_size(a.dtype);
  const std::uint64_t data_start = preamble + header_len;
  const std::uint64_t available = file_size - data_start;
  if (available < nbytes)
    throw Error(path + ": truncated data (" + std::to_string(available) + " of " +
                std::to_string(nbytes) + " bytes for shape " + shape_string(a.shape) + ")");
  if (available > nbytes)
    throw Error(path + ": corrupt file (" + std::to_string(available - nbytes) +
                " bytes after the data of shape " + shape_string(a.shape) + ")");
  if (max_bytes > 0 && nbytes > max_bytes)
    throw Error(path + ": " + std::to_string(nbytes) + " bytes of data exceed the memory limit (--max-memory-gb)");
  a.bytes.resize(static_cast<std::size_t>(nbytes));
  if (nbytes > 0 && !f.read(reinterpret_cast<char*>(a.bytes.data()), static_cast<std::streamsize>(nbytes)))
    throw Error(path + ": read error");
  detail::check_bool_bytes(a, path);
  if (fortran) detail::fortran_to_c(a);
  return a;
}

// The size of the whole .npy image (preamble + header + the data its dtype and shape declare)
// whose first `size` bytes are at `data`, from its header alone; 0 while those bytes do not yet
// hold the whole header. Lets a reader that produces an image piece by piece (an .npz member
// being inflated) check the size it was told before producing the rest. Throws
// Error("<what>: ...") on a bad magic, version or header, or a size that overflows.
inline std::uint64_t declared_size(const unsigned char* data, std::size_t size, const std::string& what) {
  // Below 12 bytes (the longest preamble) only the magic is checked: the version and the header
  // length are read once a version 2.0/3.0 length would be complete too.
  const std::optional<detail::Preamble> p = detail::read_preamble(data, size < 12 ? std::min<std::size_t>(size, 6) : size, what);
  if (!p) return 0;
  const std::string header(reinterpret_cast<const char*>(data) + p->length, static_cast<std::size_t>(p->header_len));
  Array a;
  detail::parse_header_dict(header, what, a);
  const std::int64_t count = detail::checked_count(a.shape, dtype_size(a.dtype), what);
  std::uint64_t total = 0;
  if (!detail::mul_u64(static_cast<std::uint64_t>(count), dtype_size(a.dtype), total) ||
      total > std::numeric_limits<std::uint64_t>::max() - p->length - p->header_len)
    throw Error(what + ": shape " + shape_string(a.shape) + " overflows the byte count");
  return p->length + p->header_len + total;
}

// Parses a whole .npy image held in memory (`size` bytes at `data`, e.g. an .npz member), with
// the same checks as read(); messages are "<what>: <problem>".
inline Array parse(const unsigned char* data, std::size_t size, const std::string& what) {
  if (!detail::host_is_little_endian()) throw Error(what + ": this reader needs a little-endian host");
  if (size < 10) throw Error(what + ": truncated (no npy preamble)");
  const std::optional<detail::Preamble> p = detail::read_preamble(data, size, what);
  if (!p) throw Error(what + ": truncated header");
  const std::uint64_t preamble = p->length, header_len = p->header_len;
  const std::string header(reinterpret_cast<const char*>(data) + preamble, static_cast<std::size_t>(header_len));
  Array a;
  const bool fortran = detail::parse_header_dict(header, what, a);
  const std::int64_t count = detail::checked_count(a.shape, dtype_size(a.dtype), what);
  const std::uint64_t nbytes = static_cast<std::uint64_t>(count) * dtype_size(a.dtype);
  const std::uint64_t available = size - (preamble + header_len);
  if (available < nbytes)
    throw Error(what + ": truncated data (" + std::to_string(available) + " of " + std::to_string(nbytes) +
                " bytes for shape " + shape_string(a.shape) + ")");
  if (available > nbytes)
    throw Error(what + ": corrupt file (" + std::to_string(available - nbytes) + " bytes after the data of shape " +
                shape_string(a.shape) + ")");
  const unsigned char* begin = data + preamble + header_len;
  a.bytes.assign(begin, begin + nbytes);
  detail::check_bool_bytes(a, what);
  if (fortran) detail::fortran_to_c(a);
  return a;
}

namespace detail {
// Preamble + header of a version 1.0 .npy file for T and `shape`; `count` gets the element count.
template <class T>
std::string header_bytes(const std::string& path, const std::vector<std::int64_t>& shape, std::int64_t& count) {
  if (!host_is_little_endian()) throw Error(path + ": this writer needs a little-endian host");
  const DType d = dtype_of<T>();
  const char* descr = d == DType::f32 ? "<f4" : d == DType::f64 ? "<f8" : d == DType::i32 ? "<i4"
                    : d == DType::i64 ? "<i8" : d == DType::u8 ? "|u1" : "|b1";
  count = checked_count(shape, sizeof(T), path);
  std::string dict = std::string("{'descr': '") + descr + "', 'fortran_order': False, 'shape': (";
  for (std::size_t i = 0; i < shape.size(); ++i)
    dict += std::to_string(shape[i]) + (shape.size() == 1 ? "," : i + 1 < shape.size() ? ", " : "");
  dict += "), }";
  // Pad so that preamble (10 bytes) + header is a multiple of 64, ending in '\n'.
  const std::size_t unpadded = 10 + dict.size() + 1;
  dict.append((64 - unpadded % 64) % 64, ' ');
  dict += '\n';
  if (dict.size() > 65535) throw Error(path + ": header too long");
  const char pre[10] = {'\x93', 'N', 'U', 'M', 'P', 'Y', 1, 0, static_cast<char>(dict.size() & 0xff),
                        static_cast<char>((dict.size() >> 8) & 0xff)};
  return std::string(pre, 10) + dict;
}
inline void write_all(int fd, const char* p, std::size_t n, const std::string& path) {
  while (n > 0) {
    const ::ssize_t w = ::write(fd, p, n);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) throw Error(path + ": write error: " + std::strerror(errno));
    p += w;
    n -= static_cast<std::size_t>(w);
  }
}
}  // namespace detail

// Writes data (count = product(shape)) as a version 1.0 .npy file, C order, little-endian.
// T: float, double, int32_t, int64_t, uint8_t or bool.
template <class T>
void write(const std::string& path, const T* data, const std::vector<std::int64_t>& shape) {
  std::int64_t count = 0;
  const std::string head = detail::header_bytes<T>(path, shape, count);
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw Error(path + ": cannot open for writing");
  f.write(head.data(), static_cast<std::streamsize>(head.size()));
  if (count > 0)
    f.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(count * static_cast<std::int64_t>(sizeof(T))));
  f.flush();
  if (!f) throw Error(path + ": write error");
}

// The complete .npy file (version 1.0, C order) for `count` = product(shape) values at `data`,
// as bytes in memory (an .npz member). T as for write.
template <class T>
std::string to_bytes(const T* data, const std::vector<std::int64_t>& shape) {
  std::int64_t count = 0;
  std::string out = detail::header_bytes<T>("array", shape, count);
  if (count > 0) out.append(reinterpret_cast<const char*>(data), static_cast<std::size_t>(count) * sizeof(T));
  return out;
}

// Like write, but creates a new file: open(O_CREAT | O_EXCL | O_NOFOLLOW), so an existing file
// or a planted symlink at `path` is an error instead of being followed or overwritten.
template <class T>
void write_new(const std::string& path, const T* data, const std::vector<std::int64_t>& shape) {
  std::int64_t count = 0;
  const std::string head = detail::header_bytes<T>(path, shape, count);
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
  if (fd < 0) throw Error(path + ": cannot create: " + std::strerror(errno));
  try {
    detail::write_all(fd, head.data(), head.size(), path);
    if (count > 0)
      detail::write_all(fd, reinterpret_cast<const char*>(data),
                        static_cast<std::size_t>(count) * sizeof(T), path);
    if (::fsync(fd) != 0 && errno != EINVAL) throw Error(path + ": write error: " + std::strerror(errno));
  } catch (...) {
    ::close(fd);
    throw;
  }
  if (::close(fd) != 0) throw Error(path + ": write error: " + std::strerror(errno));
}

template <class T>
void write(const std::string& path, const std::vector<T>& data, const std::vector<std::int64_t>& shape) {
  const std::int64_t count = detail::checked_count(shape, sizeof(T), path);
  if (static_cast<std::int64_t>(data.size()) != count)
    throw Error(path + ": " + std::to_string(data.size()) + " values for shape " + shape_string(shape));
  write(path, data.data(), shape);
}

}  // namespace npy
