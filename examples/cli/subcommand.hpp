// examples/cli/subcommand.hpp — the contract between smg_cli's driver and its subcommands.
//
// A subcommand declares its flags and a run function. The driver parses argv, opens the case
// directory, calls run, prints the one-line JSON summary and maps every exception to one line
// on stderr and exit code 2 (docs/interop.md). run stages its outputs in an OutputSet and commits
// them only after all computation succeeded, so a failure writes nothing.
#pragma once

#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "case_dir.hpp"
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
};

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
Subcommand dqb_subcommand();
Subcommand render_subcommand();

}  // namespace cli
