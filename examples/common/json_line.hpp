// examples/common/json_line.hpp — a one-line JSON object for machine-readable summaries.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>
#include <type_traits>

namespace cli {

class JsonLine {
 public:
  JsonLine& add(const std::string& key, const std::string& value) {
    item(key) += quote(value);
    return *this;
  }
  JsonLine& add(const std::string& key, const char* value) { return add(key, std::string(value)); }
  JsonLine& add(const std::string& key, bool value) {
    item(key) += value ? "true" : "false";
    return *this;
  }
  template <class T, class = std::enable_if_t<std::is_arithmetic_v<T>>>
  JsonLine& add(const std::string& key, T value) {
    if constexpr (std::is_integral_v<T>) {
      item(key) += std::to_string(value);
    } else if (!std::isfinite(static_cast<double>(value))) {
      item(key) += "null";  // JSON has no NaN/Inf
    } else {
      char buf[32];
      std::snprintf(buf, sizeof buf, "%.10g", static_cast<double>(value));
      item(key) += buf;
    }
    return *this;
  }
  // A raw JSON fragment (an array or object the caller formatted).
  JsonLine& add_raw(const std::string& key, const std::string& json) {
    item(key) += json;
    return *this;
  }
  std::string str() const { return "{" + body_ + "}"; }

  static std::string quote(const std::string& s) {
    std::string out = "\"";
    for (char c : s) {
      switch (c) {
        case '"': out += "\\\""; break;
        case '\\': out += "\\\\"; break;
        case '\n': out += "\\n"; break;
        case '\t': out += "\\t"; break;
        default:
          if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", c);
            out += buf;
          } else {
            out += c;
          }
      }
    }
    return out + "\"";
  }

 private:
  std::string& item(const std::string& key) {
    if (!body_.empty()) body_ += ",";
    body_ += quote(key) + ":";
    return body_;
  }
  std::string body_;
};

}  // namespace cli
