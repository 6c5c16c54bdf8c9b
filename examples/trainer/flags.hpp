// examples/trainer/flags.hpp — the command-line handling the trainer's programs (smg_trainer,
// scene_preview) share, on top of examples/common/cli_args.hpp. Every failure is a
// cli::UsageError: the programs print it as one line on stderr and exit with code 2.
#pragma once

#include <iostream>
#include <string>

#include "cli_args.hpp"
#include "trainer/priors.hpp"
#include "trainer/scene.hpp"

namespace trainer::flags {

// --NAME as an integer in [lo, hi] (a range within int).
inline int int_in(const cli::Args& a, const std::string& name, long long lo, long long hi) {
  const long long v = a.get_int(name);
  if (v < lo || v > hi)
    throw cli::UsageError("--" + name + " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                          std::to_string(v));
  return static_cast<int>(v);
}

// --NAME as a number in [lo, hi].
inline double double_in(const cli::Args& a, const std::string& name, double lo, double hi) {
  const double v = a.get_double(name);
  if (!(v >= lo && v <= hi))
    throw cli::UsageError("--" + name + " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                          a.get(name));
  return v;
}

// Parses argv (flags only, no positional arguments). With --help it prints
// "usage: PROGRAM [--flags]", the description and the flags to stdout and returns false: the
// program then exits with code 0.
inline bool parse(cli::Args& args, int argc, char** argv, const std::string& program, const std::string& description) {
  args.parse(argc, argv, 1);
  if (args.get_switch("help")) {
    std::cout << "usage: " << program << " [--flags]\n" << description << "\n\nflags:\n" << args.help();
    return false;
  }
  if (!args.positionals().empty())
    throw cli::UsageError("unexpected argument '" + args.positionals()[0] + "' (flags only; see --help)");
  return true;
}

// A scene or prior configuration that the generators reject is a usage error.
inline void validate(const SceneConfig& scene, const PriorConfig& priors) {
  if (smg::Status st = validate_scene_config(scene); !st) throw cli::UsageError(st.message());
  if (smg::Status st = validate_prior_config(priors); !st) throw cli::UsageError(st.message());
}

}  // namespace trainer::flags
