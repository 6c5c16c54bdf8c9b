// smg_cli graph — placeholder until issue 3 lands: the subcommand is registered so the
// interface is visible in --help, and it fails with a clear message (exit code 2).
#include "subcommand.hpp"

namespace cli {

Subcommand graph_subcommand() {
  Subcommand s;
  s.name = "graph";
  s.summary = "build the semantic motion graph (graph_indices, graph_weights, features, distances) [not yet available]";
  s.run = [](const Invocation&, JsonLine&) {
    throw RunError("not yet available in this version of smg (planned in issue 3)");
  };
  return s;
}

}  // namespace cli
