// smg_cli dqb — placeholder until issue 5 lands: the subcommand is registered so the
// interface is visible in --help, and it fails with a clear message (exit code 2).
#include "subcommand.hpp"

namespace cli {

Subcommand dqb_subcommand() {
  Subcommand s;
  s.name = "dqb";
  s.summary = "dual-quaternion blending of points and rotations [not yet available]";
  s.run = [](const Invocation&, JsonLine&) {
    throw RunError("not yet available in this version of smg (planned in issue 5)");
  };
  return s;
}

}  // namespace cli
