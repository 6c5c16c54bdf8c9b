// examples/common/json_read.hpp — a small, strict JSON reader (RFC 8259) for the example
// programs' input files (camera and split files of a scene, docs/data.md).
//
// Part of the examples, not the library. parse() builds a Value tree from the whole text:
// objects, arrays, numbers, strings (with \uXXXX escapes and surrogate pairs, emitted as UTF-8),
// true, false, null. Anything else — NaN/Infinity literals (unless parse() is asked to accept
// the ones Python's json module writes), trailing commas, comments, leading
// zeros, unescaped control characters, duplicate keys, numbers outside double's range, text after
// the value, nesting deeper than max_depth — is a json::Error whose message gives the line and
// column ("line 3, column 14: expected ',' or '}'"). The get_* helpers read one member of an
// object with messages like "missing key 'x'" and "'x' is not a number"; extra keys are
// tolerated. Callers prefix the file name.
#pragma once

#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <system_error>
#include <string>
#include <utility>
#include <vector>

namespace json {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Value {
  enum class Type { null, boolean, number, string, array, object };
  Type type = Type::null;
  bool boolean = false;
  double number = 0;
  std::string string;
  std::vector<Value> items;                             // array elements
  std::vector<std::pair<std::string, Value>> members;   // object members, in file order

  bool is_number() const { return type == Type::number; }
  bool is_string() const { return type == Type::string; }
  bool is_array() const { return type == Type::array; }
  bool is_object() const { return type == Type::object; }
  // The member named `key` of an object, or null when absent (or when this is not an object).
  const Value* find(const std::string& key) const {
    for (const auto& m : members)
      if (m.first == key) return &m.second;
    return nullptr;
  }
};

inline const char* type_name(Value::Type t) {
  switch (t) {
    case Value::Type::null: return "null";
    case Value::Type::boolean: return "a boolean";
    case Value::Type::number: return "a number";
    case Value::Type::string: return "a string";
    case Value::Type::array: return "an array";
    case Value::Type::object: return "an object";
  }
  return "?";
}

namespace detail {

class Parser {
 public:
  Parser(const std::string& text, int max_depth, bool allow_non_finite)
      : s_(text), max_depth_(max_depth), allow_non_finite_(allow_non_finite) {}

  Value document() {
    skip_space();
    Value v = value(0);
    skip_space();
    if (pos_ != s_.size()) fail("unexpected text after the JSON value");
    return v;
  }

 private:
  const std::string& s_;
  std::size_t pos_ = 0;
  int max_depth_;
  bool allow_non_finite_;

  [[noreturn]] void fail(const std::string& what) const { fail_at(pos_, what); }
  [[noreturn]] void fail_at(std::size_t at, const std::string& what) const {
    std::size_t line = 1, column = 1;
    for (std::size_t i = 0; i < at && i < s_.size(); ++i) {
      if (s_[i] == '\n') {
        ++line;
        column = 1;
      } else {
        ++column;
      }
    }
    throw Error("line " + std::to_string(line) + ", column " + std::to_string(column) + ": " + what);
  }
  bool at_end() const { return pos_ >= s_.size(); }
  char peek() const { return at_end() ? '\0' : s_[pos_]; }
  void skip_space() {
    while (!at_end() && (s_[pos_] == ' ' || s_[pos_] == '\t' || s_[pos_] == '\n' || s_[pos_] == '\r')) ++pos_;
  }
  void expect_word(const char* word) {
    const std::size_t start = pos_;
    for (const char* p = word; *p; ++p, ++pos_)
      if (peek() != *p) fail_at(start, "invalid literal (expected '" + std::string(word) + "')");
  }

  Value value(int depth) {
    if (at_end()) fail("unexpected end of text (expected a value)");
    Value v;
    const char c = peek();
    if (c == '{' || c == '[') {
      if (depth >= max_depth_) fail("nesting deeper than " + std::to_string(max_depth_) + " levels");
      if (c == '{') object(v, depth + 1);
      else array(v, depth + 1);
    } else if (c == '"') {
      v.type = Value::Type::string;
      v.string = string();
    } else if (c == 't') {
      expect_word("true");
      v.type = Value::Type::boolean;
      v.boolean = true;
    } else if (c == 'f') {
      expect_word("false");
      v.type = Value::Type::boolean;
    } else if (c == 'n') {
      expect_word("null");
    } else if (c == '-' || (c >= '0' && c <= '9') || c == 'N' || c == 'I') {
      // Numbers, and NaN / Infinity, which number() accepts only when allowed.
      v.type = Value::Type::number;
      v.number = number();
    } else {
      fail(std::string("unexpected character '") + c + "'");
    }
    return v;
  }

  void object(Value& v, int depth) {
    v.type = Value::Type::object;
    ++pos_;  // '{'
    skip_space();
    if (peek() == '}') {
      ++pos_;
      return;
    }
    for (;;) {
      skip_space();
      if (peek() != '"') fail("expected a string key");
      const std::size_t key_at = pos_;
      std::string key = string();
      if (v.find(key)) fail_at(key_at, "duplicate key '" + key + "'");
      skip_space();
      if (peek() != ':') fail("expected ':' after a key");
      ++pos_;
      skip_space();
      Value member = value(depth);
      v.members.emplace_back(std::move(key), std::move(member));
      skip_space();
      if (peek() == ',') {
        ++pos_;
        continue;
      }
      if (peek() == '}') {
        ++pos_;
        return;
      }
      fail(at_end() ? "unexpected end of text in an object" : "expected ',' or '}'");
    }
  }

  void array(Value& v, int depth) {
    v.type = Value::Type::array;
    ++pos_;  // '['
    skip_space();
    if (peek() == ']') {
      ++pos_;
      return;
    }
    for (;;) {
      skip_space();
      v.items.push_back(value(depth));
      skip_space();
      if (peek() == ',') {
        ++pos_;
        continue;
      }
      if (peek() == ']') {
        ++pos_;
        return;
      }
      fail(at_end() ? "unexpected end of text in an array" : "expected ',' or ']'");
    }
  }

  unsigned hex4() {
    unsigned u = 0;
    for (int k = 0; k < 4; ++k, ++pos_) {
      const char h = peek();
      u <<= 4;
      if (h >= '0' && h <= '9') u |= static_cast<unsigned>(h - '0');
      else if (h >= 'a' && h <= 'f') u |= static_cast<unsigned>(h - 'a' + 10);
      else if (h >= 'A' && h <= 'F') u |= static_cast<unsigned>(h - 'A' + 10);
      else fail("invalid \\u escape");
    }
    return u;
  }
  static void put_utf8(std::string& out, unsigned cp) {
    if (cp < 0x80) {
      out += static_cast<char>(cp);
    } else if (cp < 0x800) {
      out += static_cast<char>(0xC0 | (cp >> 6));
      out += static_cast<char>(0x80 | (cp & 0x3F));
    } else if (cp < 0x10000) {
      out += static_cast<char>(0xE0 | (cp >> 12));
      out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
      out += static_cast<char>(0x80 | (cp & 0x3F));
    } else {
      out += static_cast<char>(0xF0 | (cp >> 18));
      out += static_cast<char>(0x80 | ((cp >> 12) & 0x3F));
      out += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
      out += static_cast<char>(0x80 | (cp & 0x3F));
    }
  }

  std::string string() {
    const std::size_t start = pos_;
    ++pos_;  // '"'
    std::string out;
    for (;;) {
      if (at_end()) fail_at(start, "unterminated string");
      const char c = s_[pos_];
      if (c == '"') {
        ++pos_;
        return out;
      }
      if (static_cast<unsigned char>(c) < 0x20) fail("control character in a string (escape it)");
      if (c != '\\') {
        out += c;
        ++pos_;
        continue;
      }
      ++pos_;
      const char e = peek();
      ++pos_;
      switch (e) {
        case '"': out += '"'; break;
        case '\\': out += '\\'; break;
        case '/': out += '/'; break;
        case 'b': out += '\b'; break;
        case 'f': out += '\f'; break;
        case 'n': out += '\n'; break;
        case 'r': out += '\r'; break;
        case 't': out += '\t'; break;
        case 'u': {
          unsigned cp = hex4();
          if (cp >= 0xD800 && cp <= 0xDBFF) {
            if (peek() != '\\' || pos_ + 1 >= s_.size() || s_[pos_ + 1] != 'u') fail("unpaired surrogate in \\u escape");
            pos_ += 2;
            const unsigned lo = hex4();
            if (lo < 0xDC00 || lo > 0xDFFF) fail("unpaired surrogate in \\u escape");
            cp = 0x10000 + ((cp - 0xD800) << 10) + (lo - 0xDC00);
          } else if (cp >= 0xDC00 && cp <= 0xDFFF) {
            fail("unpaired surrogate in \\u escape");
          }
          put_utf8(out, cp);
          break;
        }
        default: fail_at(pos_ - 2, "invalid escape in a string");
      }
    }
  }

  // RFC 8259 grammar: -?(0|[1-9][0-9]*)(\.[0-9]+)?([eE][+-]?[0-9]+)?, converted with
  // std::from_chars (whatever the locale).
  double number() {
    const std::size_t start = pos_;
    auto digits = [&] {
      const std::size_t d0 = pos_;
      while (!at_end() && s_[pos_] >= '0' && s_[pos_] <= '9') ++pos_;
      return pos_ - d0;
    };
    const bool negative = peek() == '-';
    if (negative) ++pos_;
    if (peek() == 'I' || peek() == 'N') {
      if (!allow_non_finite_) fail_at(start, "NaN and Infinity are not JSON numbers");
      if (peek() == 'N' && !negative) {
        expect_word("NaN");
        return std::numeric_limits<double>::quiet_NaN();
      }
      expect_word("Infinity");
      return negative ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
    }
    if (peek() == '0') {
      ++pos_;
      if (peek() >= '0' && peek() <= '9') fail_at(start, "leading zero in a number");
    } else if (digits() == 0) {
      fail_at(start, "invalid number");
    }
    if (peek() == '.') {
      ++pos_;
      if (digits() == 0) fail_at(start, "invalid number (no digits after '.')");
    }
    if (peek() == 'e' || peek() == 'E') {
      ++pos_;
      if (peek() == '+' || peek() == '-') ++pos_;
      if (digits() == 0) fail_at(start, "invalid number (no digits in the exponent)");
    }
    double v = 0;
    const auto r = std::from_chars(s_.data() + start, s_.data() + pos_, v);  // locale-independent
    if (r.ec == std::errc::result_out_of_range) {
      // Overflow is an error; underflow (1e-400) is the nearest double, as strtod gives it.
      v = std::strtod(s_.substr(start, pos_ - start).c_str(), nullptr);
      if (!std::isfinite(v)) fail_at(start, "number " + s_.substr(start, pos_ - start) + " is out of range");
    } else if (r.ec != std::errc() || r.ptr != s_.data() + pos_ || !std::isfinite(v)) {
      fail_at(start, "invalid number");
    }
    return v;
  }
};

}  // namespace detail

// Parses a whole JSON text; arrays and objects nest at most max_depth levels. With
// allow_non_finite, the literals NaN, Infinity and -Infinity that Python's json module writes are
// read as numbers (for a caller that then names the offending key); otherwise they are errors.
// Throws json::Error("line L, column C: <problem>").
inline Value parse(const std::string& text, int max_depth = 64, bool allow_non_finite = false) {
  return detail::Parser(text, max_depth, allow_non_finite).document();
}

// The member `key` of object `obj`; throws json::Error("missing key 'key'") (or "not an object").
inline const Value& get(const Value& obj, const std::string& key) {
  if (!obj.is_object()) throw Error("expected an object, found " + std::string(type_name(obj.type)));
  const Value* v = obj.find(key);
  if (!v) throw Error("missing key '" + key + "'");
  return *v;
}

// A number member; throws "'key' is not a number" (null included).
inline double get_number(const Value& obj, const std::string& key) {
  const Value& v = get(obj, key);
  if (!v.is_number()) throw Error("'" + key + "' is not a number (found " + type_name(v.type) + ")");
  return v.number;
}

// An array-of-numbers member; expected_size >= 0 also checks its length.
inline std::vector<double> get_numbers(const Value& obj, const std::string& key, long expected_size = -1) {
  const Value& v = get(obj, key);
  if (!v.is_array()) throw Error("'" + key + "' is not an array (found " + type_name(v.type) + ")");
  if (expected_size >= 0 && v.items.size() != static_cast<std::size_t>(expected_size))
    throw Error("'" + key + "' has " + std::to_string(v.items.size()) + " elements, expected " +
                std::to_string(expected_size));
  std::vector<double> out;
  out.reserve(v.items.size());
  for (std::size_t i = 0; i < v.items.size(); ++i) {
    if (!v.items[i].is_number())
      throw Error("'" + key + "'[" + std::to_string(i) + "] is not a number (found " + type_name(v.items[i].type) + ")");
    out.push_back(v.items[i].number);
  }
  return out;
}

// An array-of-integers member: every element a number with an integral value in int64's range.
inline std::vector<std::int64_t> get_ints(const Value& obj, const std::string& key, long expected_size = -1) {
  const std::vector<double> d = get_numbers(obj, key, expected_size);
  std::vector<std::int64_t> out(d.size());
  for (std::size_t i = 0; i < d.size(); ++i) {
    if (d[i] != std::floor(d[i]) || std::abs(d[i]) > 9.0e15)
      throw Error("'" + key + "'[" + std::to_string(i) + "] is not an integer");
    out[i] = static_cast<std::int64_t>(d[i]);
  }
  return out;
}

// An array-of-strings member.
inline std::vector<std::string> get_strings(const Value& obj, const std::string& key) {
  const Value& v = get(obj, key);
  if (!v.is_array()) throw Error("'" + key + "' is not an array (found " + type_name(v.type) + ")");
  std::vector<std::string> out;
  out.reserve(v.items.size());
  for (std::size_t i = 0; i < v.items.size(); ++i) {
    if (!v.items[i].is_string())
      throw Error("'" + key + "'[" + std::to_string(i) + "] is not a string (found " + type_name(v.items[i].type) + ")");
    out.push_back(v.items[i].string);
  }
  return out;
}

}  // namespace json
