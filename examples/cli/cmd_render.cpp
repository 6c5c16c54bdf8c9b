// smg_cli render — placeholder until issue 6 lands: the subcommand is registered so the
// interface is visible in --help, and it fails with a clear message (exit code 2).
#include "subcommand.hpp"

namespace cli {

Subcommand render_subcommand() {
  Subcommand s;
  s.name = "render";
  s.summary = "render Gaussians with the reference CPU splatter (and backward with grad_image.npy) [not yet available]";
  s.run = [](const Invocation&, JsonLine&) {
    throw RunError("not yet available in this version of smg (planned in issue 6)");
  };
  return s;
}

}  // namespace cli
