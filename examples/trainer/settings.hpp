// examples/trainer/settings.hpp — smg_trainer's command-line settings, each declared once
// (docs/trainer.md, "Flags").
//
// One row per flag: its name, what it takes, its help text, its accepted range or names, and for a
// setting of TrainerConfig the two accessors that read and write it. The default that --help
// shows is read from default_config() (and default_config(true) for --quick) through the row's
// accessor, so it is never restated by hand; the range that --help shows is the one the parser
// enforces. train.cpp keeps only the rules that relate flags to each other (--data against the
// generated scene's settings, --export-layout needs --export-dycheck, ...).
#pragma once

#include <string>
#include <vector>

#include "cli_args.hpp"
#include "trainer/pipeline.hpp"

namespace trainer {

// What a flag takes: an integer or a number within [lo, hi], one of a list of names, free text
// (a path), or nothing (a switch).
enum class SettingKind { integer, number, choice, text, flag };

struct Setting {
  const char* name;  // without the leading "--"
  SettingKind kind;
  const char* help;
  double lo = 0, hi = 0;                                    // integer, number: accepted range
  const std::vector<std::string>& (*choices)() = nullptr;   // choice: accepted names
  // A TrainerConfig setting: its value (a choice as the index of its name) and how it is set.
  // Null for the flags that choose what the program does (--out, --data, --quiet, ...).
  double (*get)(const TrainerConfig&) = nullptr;
  void (*set)(TrainerConfig&, double) = nullptr;
  const char* fixed_default = "";  // a flag outside TrainerConfig: its default ("" = none)
  bool generated_only = false;      // sets the generated scene: refused with --data
};

// The names --export-layout accepts (the layouts the exporter writes: layouts.hpp).
const std::vector<std::string>& export_layout_names();

// Every flag of smg_trainer, in --help order (which is also the order they are applied in).
const std::vector<Setting>& settings();

// The flags for cli::Args, with help texts completed by the accepted values and the defaults
// of default_config(false) and default_config(true).
std::vector<cli::FlagSpec> setting_flags();

// The default of a TrainerConfig setting as --help prints it ("32", "0.1", "full").
std::string setting_default(const Setting& s, bool quick);

// Sets every TrainerConfig setting given on the command line, in table order; a value outside
// its range or names is a cli::UsageError naming the flag.
void apply_settings(const cli::Args& args, TrainerConfig* config);

}  // namespace trainer
