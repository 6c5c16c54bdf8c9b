// examples/cli/subcommand.hpp — the contract between smg_cli's driver and its subcommands.
//
// A subcommand declares its flags and a run function. The driver parses argv, opens the case
// directory, calls run, prints the one-line JSON summary and maps every exception to one line
// on stderr and exit code 2 (docs/interop.md). run stages its outputs in an OutputSet and commits
// them only after all computation succeeded, so a failure writes nothing.
#pragma once

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "case_dir.hpp"
#include "smg/core/status.hpp"
#include "cli_args.hpp"
#include "json_line.hpp"
#include "output_set.hpp"

namespace cli {

// An error in the input data or the computation (as opposed to a UsageError).
class RunError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Invocation {
  const CaseDir& case_dir;
  std::filesystem::path out_dir;  // empty for subcommands that write nothing
  const Args& args;
  bool use_float = false;  // --float: compute in float instead of double
  int threads = 0;         // --threads: 0 = all hardware threads
  double max_bytes = 0;    // --max-memory-gb in bytes: requests estimated above it are refused
};

// A library message mapped to the user's names: `names` pairs a library field or view name
// ("alpha", "kappa_m", "quats", "settings: tile_size" is read as "tile_size") with the flag
// ("--alpha") or file (CASE/quats.npy) it came from. "XOptions.alpha must be in [0, 1], got 2"
// becomes "--alpha: alpha must be in [0, 1], got 2"; "k: must be >= 1" becomes "--k: must be
// >= 1"; an unmatched message is prefixed with `fallback`.
using NameMap = std::vector<std::pair<std::string, std::string>>;
inline std::string map_message(std::string m, const NameMap& names, const std::string& fallback) {
  if (const auto dot = m.find("Options."); dot != std::string::npos && m.find(' ') > dot) m = m.substr(dot + 8);
  for (const char* pre : {"settings: ", "camera: "})
    if (m.rfind(pre, 0) == 0) m = m.substr(std::string(pre).size());
  const std::pair<std::string, std::string>* best = nullptr;
  for (const auto& n : names)
    if (m.rfind(n.first, 0) == 0 && (m.size() == n.first.size() || std::string(" :[.").find(m[n.first.size()]) != std::string::npos))
      if (!best || n.first.size() > best->first.size()) best = &n;
  if (!best) return fallback + ": " + m;
  std::string rest = m.substr(best->first.size());
  if (!rest.empty() && rest[0] == ':') return best->second + rest;
  return best->second + ": " + m;
}
// Throws a UsageError (a flag) or RunError (a file) for a failed library Status.
inline void check_mapped(const smg::Status& s, const NameMap& names, const std::string& fallback) {
  if (s) return;
  const std::string m = map_message(s.message(), names, fallback);
  if (m.rfind("--", 0) == 0) throw UsageError(m);
  throw RunError(m);
}

// Throws RunError(s.message()) for a failed library Status whose message already names the
// case's file or flag (the check_mapped route is for messages naming library fields).
inline void ok(const smg::Status& s) {
  if (!s) throw RunError(s.message());
}

// The doubles parsed from a flag, as the case's scalar type S (float under --float).
template <class S>
std::vector<S> cast(const std::vector<double>& v) {
  return std::vector<S>(v.begin(), v.end());
}

// Default of --max-memory-gb (docs/interop.md "Limits").
inline constexpr double kDefaultMaxMemoryGb = 8;

// Non-finite results from finite inputs are an error (docs/interop.md "Overflow"): throws
// RunError("<cause>") when any value of `v` is NaN or Inf.
template <class V>
void require_finite(const V& v, const std::string& cause) {
  for (const auto x : v)
    if (!std::isfinite(static_cast<double>(x))) throw RunError(cause);
}

// Largest coordinate magnitude the computations accept: squared differences of coordinates
// below it, summed over frames, stay finite (sqrt(max) / 1e4, so 1.3e150 in double, 1.8e15 in
// float). Larger finite coordinates are refused as "coordinates too large".
template <class S>
constexpr double max_coordinate() {
  return sizeof(S) == 4 ? 1.8e15 : 1.3e150;
}
template <class S, class V>
void require_coordinates(const V& v, const std::string& file) {
  const double lim = max_coordinate<S>();
  for (const auto x : v)
    if (!(std::abs(static_cast<double>(x)) <= lim)) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.3g", lim);
      throw RunError(file + ": coordinates too large (|value| > " + buf + (sizeof(S) == 4 ? " with --float" : "") +
                     "): the computation would overflow");
    }
}

struct Subcommand {
  std::string name;
  std::string summary;
  std::vector<FlagSpec> flags;
  bool writes_output = true;  // takes CASE OUT (else only CASE)
  // Fills `summary` (the driver has already added "subcommand"); throws on any error.
  std::function<void(const Invocation&, JsonLine& summary)> run;
};

// One function per subcommand, each in its own cmd_<name>.cpp.
Subcommand check_subcommand();
Subcommand graph_subcommand();
Subcommand energies_subcommand();
Subcommand regularizers_subcommand();
Subcommand dqb_subcommand();
Subcommand render_subcommand();

}  // namespace cli
