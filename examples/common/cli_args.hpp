// examples/common/cli_args.hpp — strict "--flag value" parsing for the example programs.
//
// Every flag a program accepts is declared with its default; an unknown flag, a missing value or
// a malformed number is a cli::UsageError with a one-line message. Programs turn any error into
// one line on stderr and exit code 2 (docs/interop.md).
#pragma once

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace cli {

class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FlagSpec {
  std::string name;           // without the leading "--"
  std::string default_value;  // for switches: "" (off)
  std::string help;
  bool is_switch = false;     // takes no value
};

class Args {
 public:
  Args() = default;
  explicit Args(std::vector<FlagSpec> specs) : specs_(std::move(specs)) {}

  // Parses argv[first..argc): "--name value", "--name=value", switches "--name"; everything
  // not starting with "--" is a positional. "-" alone is a positional.
  void parse(int argc, const char* const* argv, int first) {
    for (int k = first; k < argc; ++k) {
      std::string a = argv[k];
      if (a.size() > 2 && a[0] == '-' && a[1] == '-') {
        std::string name = a.substr(2), value;
        bool has_value = false;
        if (auto eq = name.find('='); eq != std::string::npos) {
          value = name.substr(eq + 1);
          name.resize(eq);
          has_value = true;
        }
        const FlagSpec* spec = find(name);
        if (!spec) throw UsageError("--" + name + ": unknown flag");
        if (spec->is_switch) {
          if (has_value) throw UsageError("--" + name + ": takes no value");
          values_[name] = "1";
        } else {
          if (!has_value) {
            if (k + 1 >= argc) throw UsageError("--" + name + ": needs a value");
            value = argv[++k];
          }
          values_[name] = value;
        }
      } else {
        positionals_.push_back(a);
      }
    }
  }

  const std::vector<std::string>& positionals() const { return positionals_; }
  bool given(const std::string& name) const { return values_.count(name) > 0; }

  std::string get(const std::string& name) const {
    const FlagSpec* spec = find(name);
    if (!spec) throw std::logic_error("flag --" + name + " was not declared");
    auto it = values_.find(name);
    return it == values_.end() ? spec->default_value : it->second;
  }
  bool get_switch(const std::string& name) const { return get(name) == "1"; }
  double get_double(const std::string& name) const { return to_double(name, get(name)); }
  long long get_int(const std::string& name) const { return to_int(name, get(name)); }
  // A 64-bit parse with a full-string check, then a range check before any narrowing:
  // "--name: must be between lo and hi, got v".
  long long get_int_in(const std::string& name, long long lo, long long hi) const {
    return in_range(name, get_int(name), lo, hi);
  }
  int get_int32_in(const std::string& name, long long lo = std::numeric_limits<int>::min(),
                   long long hi = std::numeric_limits<int>::max()) const {
    lo = std::max<long long>(lo, std::numeric_limits<int>::min());
    hi = std::min<long long>(hi, std::numeric_limits<int>::max());
    return static_cast<int>(get_int_in(name, lo, hi));
  }
  static long long in_range(const std::string& name, long long v, long long lo, long long hi) {
    if (v < lo || v > hi)
      throw UsageError("--" + name + ": must be between " + std::to_string(lo) + " and " + std::to_string(hi) +
                       ", got " + std::to_string(v));
    return v;
  }
  std::vector<double> get_doubles(const std::string& name) const {
    std::vector<double> out;
    for (const auto& item : split(get(name))) out.push_back(to_double(name, item));
    return out;
  }
  std::vector<long long> get_ints(const std::string& name) const {
    std::vector<long long> out;
    for (const auto& item : split(get(name))) out.push_back(to_int(name, item));
    return out;
  }
  // The comma-separated items of a flag's value, as given.
  std::vector<std::string> get_strings(const std::string& name) const { return split(get(name)); }
  // One of `choices`, else a UsageError listing them.
  std::string get_choice(const std::string& name, const std::vector<std::string>& choices) const {
    const std::string v = get(name);
    for (const auto& c : choices)
      if (c == v) return v;
    std::string list;
    for (const auto& c : choices) list += (list.empty() ? "" : " | ") + c;
    throw UsageError("--" + name + ": must be one of " + list + ", got '" + v + "'");
  }

  std::string help() const {
    std::ostringstream s;
    for (const auto& f : specs_) {
      s << "  --" << f.name;
      if (!f.is_switch) s << " " << (f.default_value.empty() ? "VALUE" : f.default_value);
      s << "\n      " << f.help << "\n";
    }
    return s.str();
  }

 private:
  const FlagSpec* find(const std::string& name) const {
    for (const auto& f : specs_)
      if (f.name == name) return &f;
    return nullptr;
  }
  static std::vector<std::string> split(const std::string& s) {
    std::vector<std::string> out;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ',')) out.push_back(item);
    return out;
  }
  static double to_double(const std::string& name, const std::string& v) {
    errno = 0;
    char* end = nullptr;
    const double d = std::strtod(v.c_str(), &end);
    if (v.empty() || end != v.c_str() + v.size() || errno == ERANGE || !std::isfinite(d))
      throw UsageError("--" + name + ": expects a finite number, got '" + v + "'");
    return d;
  }
  static long long to_int(const std::string& name, const std::string& v) {
    errno = 0;
    char* end = nullptr;
    const long long i = std::strtoll(v.c_str(), &end, 10);
    if (v.empty() || end != v.c_str() + v.size() || errno == ERANGE)
      throw UsageError("--" + name + ": expects an integer, got '" + v + "'");
    return i;
  }

  std::vector<FlagSpec> specs_;
  std::map<std::string, std::string> values_;
  std::vector<std::string> positionals_;
};

// The shortest decimal text that reads back as exactly `v` (for flag defaults taken from the
// library's option structs: 0.6 -> "0.6", 1e-4 -> "0.0001").
inline std::string format_number(double v) {
  char buf[40];
  for (int p = 1; p <= 17; ++p) {
    std::snprintf(buf, sizeof buf, "%.*g", p, v);
    if (std::strtod(buf, nullptr) == v) break;
  }
  return buf;
}
inline std::string format_number(float v) { return format_number(static_cast<double>(v)); }
inline std::string format_number(int v) { return std::to_string(v); }

// Escapes control characters (bytes < 0x20 and 0x7f) as \n, \r, \t or \xHH, so that an echoed
// path or flag value cannot break the one-line error format.
inline std::string escape_line(const std::string& s) {
  std::string out;
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '\n') out += "\\n";
    else if (c == '\r') out += "\\r";
    else if (c == '\t') out += "\\t";
    else if (u < 0x20 || u == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", u);
      out += buf;
    } else {
      out += c;
    }
  }
  return out;
}

// Creates `dir` (and its parents) and proves it writable by writing and removing a probe file,
// so a program can refuse before doing any work. Throws UsageError with a one-line message.
inline void ensure_writable_dir(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir))
    throw UsageError("cannot create output folder '" + dir.string() + "'" + (ec ? ": " + ec.message() : ""));
  const std::filesystem::path probe = dir / ".smg_write_probe";
  {
    std::ofstream f(probe);
    if (!(f << "ok")) throw UsageError("output folder '" + dir.string() + "' is not writable");
  }
  std::filesystem::remove(probe, ec);
}

}  // namespace cli
