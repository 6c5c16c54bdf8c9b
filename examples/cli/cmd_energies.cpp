// smg_cli energies — placeholder until issue 4 lands: the subcommand is registered so the
// interface is visible in --help, and it fails with a clear message (exit code 2).
#include "subcommand.hpp"

namespace cli {

Subcommand energies_subcommand() {
  Subcommand s;
  s.name = "energies";
  s.summary = "node confidences, C-ARAP, LRM and plain ARAP energies with gradients [not yet available]";
  s.run = [](const Invocation&, JsonLine&) {
    throw RunError("not yet available in this version of smg (planned in issue 4)");
  };
  return s;
}

}  // namespace cli
