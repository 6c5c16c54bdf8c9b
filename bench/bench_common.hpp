// bench/bench_common.hpp — what every bench/bench_<module>.cpp shares:
//
//  * run-time parameters (problem size, gaps, threads, precision, repetitions): `--name=value`
//    flags, parsed and removed from argv before benchmark::Initialize, or SMG_BENCH_<NAME>
//    environment variables (flags win). `--smg_help` lists a binary's parameters and defaults.
//  * one timing convention: wall time (UseRealTime) beside the process CPU time over all threads
//    (MeasureProcessCPUTime), a `min` statistic beside Google Benchmark's median when repeated;
//  * the run's context in the JSON: smg's own build type, compiler and flags (compile definitions
//    from bench/CMakeLists.txt), the resolved parameters and /proc/loadavg at the start;
//  * per row, the machine's load while the row ran: `others_cpus`, the CPUs that other processes
//    kept busy (all CPUs' busy time from /proc/stat minus this process's CPU time, over the wall
//    time since the previous row was reported), and `loadavg_1m` at the end of the row.
#pragma once

#include <benchmark/benchmark.h>

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#ifndef SMG_BENCH_BUILD_TYPE
#define SMG_BENCH_BUILD_TYPE "unknown"
#endif
#ifndef SMG_BENCH_CXX_FLAGS
#define SMG_BENCH_CXX_FLAGS "unknown"
#endif
#ifndef SMG_BENCH_COMPILER
#define SMG_BENCH_COMPILER "unknown"
#endif

extern char** environ;

namespace smg_bench {

// ---- run-time parameters ----------------------------------------------------------------------
class Params {
 public:
  // Collects SMG_BENCH_* variables and removes every `--name=value` flag that is not one of
  // Google Benchmark's (`--benchmark_*`) from argv; `--smg_help` asks for the parameter list.
  Params(int& argc, char** argv, std::string module) : module_(std::move(module)) {
    for (char** e = environ; e && *e; ++e) {
      const std::string kv = *e;
      if (kv.rfind("SMG_BENCH_", 0) != 0) continue;
      const auto eq = kv.find('=');
      if (eq == std::string::npos) continue;
      std::string name = kv.substr(10, eq - 10);
      for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      env_[name] = {kv.substr(eq + 1), "SMG_BENCH_" + kv.substr(10, eq - 10)};
    }
    int out = 1;
    for (int a = 1; a < argc; ++a) {
      const std::string s = argv[a];
      if (s == "--smg_help") {
        help_ = true;
        continue;
      }
      if (s.rfind("--", 0) == 0 && s.rfind("--benchmark_", 0) != 0 && s.find('=') != std::string::npos) {
        const auto eq = s.find('=');
        raw_[s.substr(2, eq - 2)] = {s.substr(eq + 1), s.substr(0, eq)};
        continue;
      }
      argv[out++] = argv[a];
    }
    argc = out;
    argv[argc] = nullptr;
  }

  long integer(const std::string& name, long fallback, const std::string& help) {
    const std::string v = take(name, std::to_string(fallback), help);
    char* end = nullptr;
    const long r = std::strtol(v.c_str(), &end, 10);
    if (end == v.c_str() || *end != '\0') fail(name, v, "an integer");
    return r;
  }
  double real(const std::string& name, double fallback, const std::string& help) {
    std::ostringstream d;
    d << fallback;
    const std::string v = take(name, d.str(), help);
    char* end = nullptr;
    const double r = std::strtod(v.c_str(), &end);
    if (end == v.c_str() || *end != '\0') fail(name, v, "a number");
    return r;
  }
  std::vector<long> list(const std::string& name, const std::vector<long>& fallback, const std::string& help) {
    std::string d;
    for (long x : fallback) d += (d.empty() ? "" : ",") + std::to_string(x);
    const std::string v = take(name, d, help);
    std::vector<long> r;
    std::stringstream ss(v);
    std::string item;
    while (std::getline(ss, item, ',')) {
      char* end = nullptr;
      const long x = std::strtol(item.c_str(), &end, 10);
      if (item.empty() || *end != '\0') fail(name, v, "a comma-separated list of integers");
      r.push_back(x);
    }
    if (r.empty()) fail(name, v, "a non-empty list");
    return r;
  }
  std::string text(const std::string& name, const std::string& fallback, const std::string& help) {
    return take(name, fallback, help);
  }
  // precision=float|double|both: which scalar types run.
  void precision(const std::string& fallback = "both") {
    const std::string p = take("precision", fallback, "float | double | both: the scalar types that run");
    if (p != "float" && p != "double" && p != "both") fail("precision", p, "float, double or both");
    float_ = p != "double";
    double_ = p != "float";
  }
  template <class S>
  bool runs() const {
    return sizeof(S) == sizeof(float) ? float_ : double_;
  }
  // repetitions (noise protocol), default `fallback`.
  int reps(int fallback) {
    reps_ = static_cast<int>(integer("reps", fallback,
                                     "repetitions of every row (the report shows their median and min)"));
    if (reps_ < 1) fail("reps", std::to_string(reps_), "at least 1");
    return reps_;
  }
  int repetitions() const { return reps_; }

  // After every parameter was read: --smg_help prints them and exits; unknown flags are errors
  // (a typo must not silently run the default size). SMG_BENCH_* variables another binary
  // reads (scripts/bench.sh runs several with one environment) are ignored here. Records the resolved values in the context.
  void finish() {
    if (help_) {
      std::printf("bench_%s parameters (flag --name=value, or environment SMG_BENCH_NAME=value):\n",
                  module_.c_str());
      for (const auto& d : docs_) std::printf("  --%-14s %s (default %s)\n", d[0].c_str(), d[2].c_str(), d[1].c_str());
      std::printf("and Google Benchmark's own flags (--help), e.g. --benchmark_filter=REGEX.\n");
      std::exit(0);
    }
    for (const auto& r : raw_)
      if (!used_.count(r.first)) {
        std::fprintf(stderr, "bench_%s: unknown parameter %s (--smg_help lists them)\n", module_.c_str(),
                     r.second.second.c_str());
        std::exit(2);
      }
    std::string s;
    for (const auto& d : docs_) s += (s.empty() ? "" : " ") + d[0] + "=" + values_[d[0]];
    benchmark::AddCustomContext("smg_params", s);
  }

 private:
  std::string take(const std::string& name, const std::string& fallback, const std::string& help) {
    used_[name] = true;
    std::string v = fallback;
    if (raw_.count(name))
      v = raw_.at(name).first;
    else if (env_.count(name))
      v = env_.at(name).first;
    docs_.push_back({name, fallback, help});
    values_[name] = v;
    return v;
  }
  [[noreturn]] void fail(const std::string& name, const std::string& v, const char* what) {
    std::fprintf(stderr, "bench_%s: %s=%s is not %s\n", module_.c_str(), name.c_str(), v.c_str(), what);
    std::exit(2);
  }

  std::string module_;
  std::map<std::string, std::pair<std::string, std::string>> raw_;  // flags: name -> (value, flag)
  std::map<std::string, std::pair<std::string, std::string>> env_;  // SMG_BENCH_*: name -> (value, variable)
  std::map<std::string, bool> used_;
  std::map<std::string, std::string> values_;
  std::vector<std::vector<std::string>> docs_;
  bool help_ = false, float_ = true, double_ = true;
  int reps_ = 1;
};

// ---- the machine's load -----------------------------------------------------------------------
inline std::string loadavg() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}
// Busy seconds of all CPUs together since boot (/proc/stat: user nice system idle iowait irq
// softirq steal ...; busy = all but idle and iowait).
inline double busy_seconds() {
  std::ifstream f("/proc/stat");
  std::string cpu;
  f >> cpu;
  double v[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  for (double& x : v) f >> x;
  const double ticks = static_cast<double>(sysconf(_SC_CLK_TCK));
  return (v[0] + v[1] + v[2] + v[5] + v[6] + v[7]) / ticks;
}
inline double process_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}
inline double wall_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Adds others_cpus and loadavg_1m to every run of a report (one measurement per reported row,
// shared by the console and the file reporter, which see the same rows in turn).
class LoadMeter {
 public:
  LoadMeter() { reset(); }
  void reset() {
    busy0_ = busy_seconds();
    own0_ = process_cpu_seconds();
    wall0_ = wall_seconds();
  }
  void annotate(std::vector<benchmark::BenchmarkReporter::Run>& runs) {
    if (runs.empty()) return;
    const std::string key = runs.front().benchmark_name() + "#" + std::to_string(runs.size());
    if (key != last_key_) {
      const double busy = busy_seconds(), own = process_cpu_seconds(), wall = wall_seconds();
      const double dt = std::max(1e-9, wall - wall0_);
      others_ = std::max(0.0, (busy - busy0_) - (own - own0_)) / dt;
      std::istringstream l(loadavg());
      l >> load1_;
      busy0_ = busy;
      own0_ = own;
      wall0_ = wall;
      last_key_ = key;
    }
    for (auto& r : runs) {
      r.counters["others_cpus"] = benchmark::Counter(others_);
      r.counters["loadavg_1m"] = benchmark::Counter(load1_);
    }
  }

 private:
  double busy0_ = 0, own0_ = 0, wall0_ = 0, others_ = 0, load1_ = 0;
  std::string last_key_;
};
inline LoadMeter& load_meter() {
  static LoadMeter m;
  return m;
}

class Console : public benchmark::ConsoleReporter {
 public:
  using benchmark::ConsoleReporter::ConsoleReporter;
  void ReportRuns(const std::vector<Run>& runs) override {
    std::vector<Run> r = runs;
    load_meter().annotate(r);
    benchmark::ConsoleReporter::ReportRuns(r);
  }
};
class Json : public benchmark::JSONReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    std::vector<Run> r = runs;
    load_meter().annotate(r);
    benchmark::JSONReporter::ReportRuns(r);
  }
};

// ---- registration -----------------------------------------------------------------------------
// The protocol every row follows: wall time, process CPU time, `reps` repetitions (aggregates
// only: mean, median, stddev, cv and min) when reps > 1.
// manual_time: the row times itself (SetIterationTime) instead of the wall time of the loop.
inline benchmark::internal::Benchmark* protocol(benchmark::internal::Benchmark* b, int reps,
                                                bool manual_time = false) {
  if (manual_time)
    b->UseManualTime();
  else
    b->UseRealTime();
  b->MeasureProcessCPUTime();
  if (reps > 1) {
    b->Repetitions(reps)->ReportAggregatesOnly(true)->ComputeStatistics(
        "min", [](const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); });
  }
  return b;
}

// Initialize, record smg's build in the context, run with the load-annotating reporters.
inline int run(int argc, char** argv) {
  bool json_out = false, other_format = false;
  for (int a = 1; a < argc; ++a) {
    const std::string s = argv[a];
    if (s.rfind("--benchmark_out=", 0) == 0) json_out = true;
    if (s.rfind("--benchmark_out_format=", 0) == 0 && s != "--benchmark_out_format=json") other_format = true;
    if (s.rfind("--benchmark_format=", 0) == 0 && s != "--benchmark_format=console") other_format = true;
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::AddCustomContext("smg_build_type", SMG_BENCH_BUILD_TYPE);
  benchmark::AddCustomContext("smg_cxx_flags", SMG_BENCH_CXX_FLAGS);
  benchmark::AddCustomContext("smg_compiler", SMG_BENCH_COMPILER);
  benchmark::AddCustomContext("smg_cpu_time", "process CPU time over all threads (MeasureProcessCPUTime), beside wall time (UseRealTime)");
  benchmark::AddCustomContext("loadavg_start", loadavg());
  load_meter().reset();
  if (other_format) {
    benchmark::RunSpecifiedBenchmarks();  // the caller asked for another format: no load counters
  } else {
    Console console(isatty(fileno(stdout)) ? benchmark::ConsoleReporter::OO_Color
                                           : benchmark::ConsoleReporter::OO_None);
    Json json;
    benchmark::RunSpecifiedBenchmarks(&console, json_out ? &json : nullptr);
  }
  benchmark::Shutdown();
  return 0;
}

// Wall seconds of a loop, measured around it (for per-call counters, printed as plain numbers).
class Stopwatch {
 public:
  Stopwatch() : t0_(wall_seconds()) {}
  double seconds() const { return wall_seconds() - t0_; }

 private:
  double t0_;
};
// A plain per-unit value: seconds * scale / (iterations * units), e.g. ns per call.
inline double per(const benchmark::State& state, double seconds, double units, double scale) {
  return seconds * scale / (static_cast<double>(std::max<benchmark::IterationCount>(1, state.iterations())) * units);
}

}  // namespace smg_bench
