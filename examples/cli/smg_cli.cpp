// smg_cli — the npy bridge between smg and NumPy/PyTorch codebases (docs/interop.md).
//
//   smg_cli <subcommand> CASE [OUT] [--flags]
//
// Reads a case directory of .npy files, runs one part of the library, writes .npy results into
// OUT and one JSON line on stdout. Any error: one line on stderr, exit code 2, nothing written.
#include <chrono>
#include <exception>
#include <iostream>
#include <new>
#include <string>
#include <vector>

#include "smg/core/version.hpp"
#include "subcommand.hpp"

namespace {

std::vector<cli::Subcommand> registry() {
  return {cli::check_subcommand(), cli::graph_subcommand(), cli::energies_subcommand(),
          cli::regularizers_subcommand(), cli::dqb_subcommand(), cli::render_subcommand()};
}

std::vector<cli::FlagSpec> common_flags() {
  return {{"float", "", "compute in float (default: double)", true},
          {"threads", "0", "worker threads, 0 = all hardware threads", false},
          {"max-memory-gb", cli::format_number(cli::kDefaultMaxMemoryGb),
           "refuse requests whose estimated memory (outputs + main workspaces) exceeds this many GiB", false},
          {"help", "", "print this help", true}};
}

void print_usage(std::ostream& os, const std::vector<cli::Subcommand>& subs) {
  os << "usage: smg_cli <subcommand> CASE [OUT] [--flags]\n\nsubcommands:\n";
  for (const auto& s : subs) os << "  " << s.name << "  " << s.summary << "\n";
  os << "\n'smg_cli <subcommand> --help' lists its flags. Formats: docs/interop.md.\n"
     << "smg " << SMG_VERSION_STRING << ", instruction set " << SMG_ISA_NAME
     << " (chosen at compile time: docs/quickstart.md \"Build flags\").\n";
}

int fail(const std::string& where, const std::string& message) {
  std::cerr << "smg_cli" << (where.empty() ? "" : " " + cli::escape_line(where)) << ": error: "
            << cli::escape_line(message) << "\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  const auto subs = registry();
  if (argc < 2) {
    print_usage(std::cerr, subs);
    return 2;
  }
  const std::string name = argv[1];
  if (name == "--help" || name == "-h" || name == "help") {
    print_usage(std::cout, subs);
    return 0;
  }
  const cli::Subcommand* sub = nullptr;
  for (const auto& s : subs)
    if (s.name == name) sub = &s;
  if (!sub) return fail("", "unknown subcommand '" + name + "' (try smg_cli --help)");

  try {
    std::vector<cli::FlagSpec> flags = sub->flags;
    for (auto& f : common_flags()) flags.push_back(f);
    cli::Args args(flags);
    args.parse(argc, argv, 2);
    if (args.get_switch("help")) {
      std::cout << "usage: smg_cli " << sub->name << " CASE" << (sub->writes_output ? " OUT" : "")
                << " [--flags]\n" << sub->summary << "\n\nflags:\n" << args.help();
      return 0;
    }
    const std::size_t want = sub->writes_output ? 2 : 1;
    if (args.positionals().size() != want)
      throw cli::UsageError(std::string("expected ") + (want == 2 ? "CASE OUT" : "CASE") + ", got " +
                            std::to_string(args.positionals().size()) + " positional argument(s)");
    const int threads = args.get_int32_in("threads", 0, 4096);
    const double max_gb = args.get_double("max-memory-gb");
    if (!(max_gb > 0 && max_gb <= 1048576))
      throw cli::UsageError("--max-memory-gb: must be in (0, 1048576], got '" + args.get("max-memory-gb") + "'");
    const double max_bytes = max_gb * 1073741824.0;

    const cli::CaseDir case_dir(args.positionals()[0], max_bytes);
    const cli::Invocation inv{case_dir, sub->writes_output ? args.positionals()[1] : "", args,
                              args.get_switch("float"), threads, max_bytes};
    cli::JsonLine summary;
    summary.add("subcommand", sub->name);
    sub->run(inv, summary);
    std::cout << summary.str() << std::endl;
    return 0;
  } catch (const std::bad_alloc&) {
    const std::string& what = cli::alloc_context();
    return fail(sub->name, (what.empty() ? std::string("smg_cli") : what) +
                               ": out of memory (std::bad_alloc; see --max-memory-gb)");
  } catch (const std::exception& e) {
    return fail(sub->name, e.what());
  }
}
