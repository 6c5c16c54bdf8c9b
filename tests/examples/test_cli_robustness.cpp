// CLI robustness suite (issue 10): malformed inputs of every class across all smg_cli
// subcommands. Each case must end with exit code 2, nothing on stdout, exactly one line on
// stderr of the form "smg_cli <sub>: error: <file or flag>: <problem>", and the case folder and
// the output folder (with its parents) byte-for-byte unchanged. The cases are a table
// (`robustness_cases`); `SMG_PRINT_CASES=1 test_examples` prints it. Plus a bounded randomised
// mutation test of the npy reader, in-process.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <iterator>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

#include "npy.hpp"
#include "support/run_program.hpp"

namespace fs = std::filesystem;
using smg::test::slurp;
using smg::test::write_bytes;

namespace {

// A raw .npy file (version 1.0) with a hand-written header dict and `data` bytes.
std::string raw_npy(const std::string& dict, const std::string& data, int major = 1) {
  std::string h = dict;
  const std::size_t pre = major == 1 ? 10 : 12;
  while ((pre + h.size() + 1) % 64 != 0) h += ' ';
  h += '\n';
  std::string out = std::string("\x93NUMPY", 6) + static_cast<char>(major) + '\0';
  out += static_cast<char>(h.size() & 0xff);
  out += static_cast<char>((h.size() >> 8) & 0xff);
  if (major != 1) out += std::string(2, '\0');
  return out + h + data;
}

// Tree snapshot: relative path -> "d" (folder), "l:<target>" (symlink), "p" (FIFO) or
// "f:<contents>"; symlinks are never followed.
std::map<std::string, std::string> snapshot(const fs::path& root) {
  std::map<std::string, std::string> s;
  std::error_code ec;
  if (!fs::exists(fs::symlink_status(root, ec))) return s;
  for (auto it = fs::recursive_directory_iterator(root, fs::directory_options::none, ec);
       it != fs::recursive_directory_iterator(); it.increment(ec)) {
    const fs::path p = it->path();
    const std::string rel = fs::relative(p, root).string();
    const auto st = fs::symlink_status(p);
    if (fs::is_symlink(st)) s[rel] = "l:" + fs::read_symlink(p).string();
    else if (fs::is_directory(st)) s[rel] = "d";
    else if (fs::is_fifo(st)) s[rel] = "p";
    else s[rel] = "f:" + slurp(p);
  }
  return s;
}

std::string shell_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

#ifdef SMG_CLI_PATH
using Run = smg::test::ProgramRun;
Run run_cli_env(const std::string& args, const std::string& env = "") {
  smg::test::RunOptions o;
  o.env = env;
  o.timeout_s = 20;  // a regression that blocks (a FIFO input) fails the case instead of hanging ctest
  o.no_stdin = true;
  o.require_exit = false;
  return smg::test::run_program(SMG_CLI_PATH, args, "smg_test_cli_robustness_io", o);
}
#endif

// ---- case folders -------------------------------------------------------------------------

std::vector<double> ramp(std::size_t n, double scale, double offset = 0) {
  std::vector<double> v(n);
  for (std::size_t k = 0; k < n; ++k) v[k] = offset + scale * std::sin(0.37 * double(k) + 0.1);
  return v;
}

constexpr std::int64_t kT = 3, kN = 20, kP = 4, kQ = 2, kG = 3;

// Node files: positions [T,N,3], quats [T,N,4] (identity), visibility [T,N].
void node_case(const fs::path& d) {
  npy::write((d / "positions.npy").string(), ramp(kT * kN * 3, 1.0), {kT, kN, 3});
  std::vector<double> q(kT * kN * 4, 0.0);
  for (std::int64_t k = 0; k < kT * kN; ++k) q[std::size_t(4 * k)] = 1;
  npy::write((d / "quats.npy").string(), q, {kT, kN, 4});
  npy::write((d / "visibility.npy").string(), std::vector<std::uint8_t>(kT * kN, 1), {kT, kN});
}

void dqb_case(const fs::path& d) {
  node_case(d);
  npy::write((d / "points.npy").string(), ramp(kP * 3, 0.5), {kP, 3});
  npy::write((d / "anchor.npy").string(), std::vector<std::int64_t>{0, 1, 2, 3}, {kP});
  npy::write((d / "t_ref.npy").string(), std::vector<std::int64_t>{0, 1, 2, 0}, {kP});
  npy::write((d / "t_query.npy").string(), std::vector<std::int64_t>{1, 2}, {kQ});
  npy::write((d / "sigma.npy").string(), std::vector<double>(kN, 0.5), {kN});
}

void render_case(const fs::path& d) {
  npy::write((d / "means.npy").string(), std::vector<double>{0, 0, 4, 0.3, 0.1, 5, -0.2, 0.2, 6}, {kG, 3});
  npy::write((d / "quats.npy").string(), std::vector<double>{1, 0, 0, 0, 1, 0, 0, 0, 0.9, 0.1, 0, 0}, {kG, 4});
  npy::write((d / "scales.npy").string(), std::vector<double>(kG * 3, -1.5), {kG, 3});
  npy::write((d / "opacities.npy").string(), std::vector<double>(kG, 0.5), {kG});
  npy::write((d / "colors.npy").string(), ramp(kG * 3, 0.3, 0.5), {kG, 3});
  npy::write((d / "viewmat.npy").string(),
             std::vector<double>{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, {4, 4});
  npy::write((d / "K.npy").string(), std::vector<double>{20, 0, 8, 0, 20, 8, 0, 0, 1}, {3, 3});
}

void base_case(const std::string& sub, const fs::path& d) {
  fs::create_directories(d);
  if (sub == "render") render_case(d);
  else if (sub == "dqb") dqb_case(d);
  else node_case(d);
}

// The previous run's outputs in OUT (which must survive any failed run unchanged).
void old_outputs(const fs::path& out) {
  fs::create_directories(out);
  for (const char* f : {"graph_indices.npy", "graph_weights.npy", "confidence.npy", "grad_positions_carap.npy",
                        "blended_points.npy", "image.npy", "alpha.npy"})
    write_bytes(out / f, std::string("old contents of ") + f);
  write_bytes(out / "notes.txt", "user file\n");
}

// ---- the table -----------------------------------------------------------------------------

struct Ctx {
  fs::path root, case_dir, out;
  std::string file(const std::string& f) const { return (case_dir / f).string(); }
};

struct Case {
  std::string name;      // what is malformed
  std::string sub;       // subcommand
  std::string args;      // extra arguments (flags)
  std::function<void(Ctx&)> setup;  // modifies the base case / OUT; may redirect ctx.out
  std::function<std::string(const Ctx&)> names;  // the file or flag the error line must name
  std::string env;       // environment assignments for the run
  Case(std::string n, std::string s, std::string a, std::function<void(Ctx&)> f,
       std::function<std::string(const Ctx&)> nm, std::string e = "")
      : name(std::move(n)), sub(std::move(s)), args(std::move(a)), setup(std::move(f)), names(std::move(nm)), env(std::move(e)) {}
};

std::function<std::string(const Ctx&)> file_(const std::string& f) {
  return [f](const Ctx& c) { return c.file(f); };
}
std::function<std::string(const Ctx&)> flag_(const std::string& f) {
  return [f](const Ctx&) { return f; };
}
auto nothing = [](Ctx&) {};

void put(const Ctx& c, const std::string& f, const std::string& bytes) { write_bytes(c.case_dir / f, bytes); }
std::string f8(std::size_t n, double v = 1.0) {
  std::string s(n * 8, '\0');
  for (std::size_t k = 0; k < n; ++k) std::memcpy(&s[8 * k], &v, 8);
  return s;
}

std::vector<Case> robustness_cases() {
  const std::string pos_dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (3, 20, 3), }";
  std::vector<Case> cs = {
      // --- npy format ---
      {"truncated data", "graph", "", [](Ctx& c) {
         const std::string b = slurp(c.case_dir / "positions.npy");
         put(c, "positions.npy", b.substr(0, b.size() - 8)); }, file_("positions.npy")},
      {"bad magic", "energies", "", [](Ctx& c) { put(c, "positions.npy", "NOTNUMPY" + std::string(120, ' ')); },
       file_("positions.npy")},
      {"header length beyond the file", "check", "", [](Ctx& c) {
         put(c, "positions.npy", std::string("\x93NUMPY\x01\x00\xff\xff", 10) + "{'descr'"); }, file_("positions.npy")},
      {"version 2 header length 2^32-1", "graph", "", [](Ctx& c) {
         put(c, "positions.npy", std::string("\x93NUMPY\x02\x00\xff\xff\xff\xff", 12) + "{}"); }, file_("positions.npy")},
      {"shape overflows the element count", "energies", "", [](Ctx& c) {
         put(c, "positions.npy", raw_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (100000000000000, 100000000000000, 3), }", f8(8))); },
       file_("positions.npy")},
      {"shape whose byte count wraps to the file size", "dqb", "", [](Ctx& c) {
         // 39673147557917 * 58121 = 2^61 + 5 elements; * 8 bytes wraps around 2^64 to 40 bytes,
         // exactly the data present.
         put(c, "positions.npy", raw_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (39673147557917, 58121), }", f8(5))); },
       file_("positions.npy")},
      {"negative dimension", "check", "", [](Ctx& c) {
         put(c, "positions.npy", raw_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (-1, 20, 3), }", f8(60))); },
       file_("positions.npy")},
      {"big-endian dtype", "check", "", [](Ctx& c) {
         put(c, "positions.npy", raw_npy("{'descr': '>f8', 'fortran_order': False, 'shape': (3, 20, 3), }", f8(180))); },
       file_("positions.npy")},
      // Fortran order itself is read (transposed, tests/examples/test_npy.cpp); its data is checked
      // like C order's.
      {"Fortran order, truncated data", "graph", "", [](Ctx& c) {
         put(c, "positions.npy", raw_npy("{'descr': '<f8', 'fortran_order': True, 'shape': (3, 20, 3), }", f8(179))); },
       file_("positions.npy")},
      {"unsupported dtype complex128", "energies", "", [](Ctx& c) {
         put(c, "positions.npy", raw_npy("{'descr': '<c16', 'fortran_order': False, 'shape': (3, 20, 3), }", f8(360))); },
       file_("positions.npy")},
      {"trailing bytes after the data", "check", "", [pos_dict](Ctx& c) { put(c, "positions.npy", raw_npy(pos_dict, f8(181))); },
       file_("positions.npy")},
      {"header without a dict", "dqb", "", [](Ctx& c) { put(c, "sigma.npy", raw_npy("no dict here", f8(6))); },
       file_("sigma.npy")},
      // --- dtypes, ranks, sizes, values ---
      {"positions as float16 (float32 or float64 expected)", "check", "", [](Ctx& c) {
         put(c, "positions.npy", raw_npy("{'descr': '<f2', 'fortran_order': False, 'shape': (3, 20, 3), }",
                                         std::string(360, '\x3c'))); }, file_("positions.npy")},
      {"positions as int32", "graph", "", [](Ctx& c) {
         npy::write(c.file("positions.npy"), std::vector<std::int32_t>(kT * kN * 3, 1), {kT, kN, 3}); }, file_("positions.npy")},
      {"positions of rank 2", "energies", "", [](Ctx& c) {
         npy::write(c.file("positions.npy"), std::vector<double>(kT * kN, 1), {kT, kN}); }, file_("positions.npy")},
      {"positions [T,N,4]", "dqb", "", [](Ctx& c) {
         npy::write(c.file("positions.npy"), std::vector<double>(kT * kN * 4, 1), {kT, kN, 4}); }, file_("positions.npy")},
      {"quats with another N", "energies", "", [](Ctx& c) {
         npy::write(c.file("quats.npy"), std::vector<double>(kT * 5 * 4, 1), {kT, 5, 4}); }, file_("quats.npy")},
      {"visibility with another T", "graph", "", [](Ctx& c) {
         npy::write(c.file("visibility.npy"), std::vector<std::uint8_t>(2 * kN, 1), {2, kN}); }, file_("visibility.npy")},
      {"visibility value 2", "check", "", [](Ctx& c) {
         std::vector<std::uint8_t> v(kT * kN, 1);
         v[4] = 2;
         npy::write(c.file("visibility.npy"), v, {kT, kN}); }, file_("visibility.npy")},
      {"NaN in positions", "check", "", [](Ctx& c) {
         auto x = ramp(kT * kN * 3, 1.0);
         x[7] = std::numeric_limits<double>::quiet_NaN();
         npy::write(c.file("positions.npy"), x, {kT, kN, 3}); }, file_("positions.npy")},
      {"Inf in quats", "energies", "", [](Ctx& c) {
         std::vector<double> q(kT * kN * 4, 0.5);
         q[3] = std::numeric_limits<double>::infinity();
         npy::write(c.file("quats.npy"), q, {kT, kN, 4}); }, file_("quats.npy")},
      {"zero quaternion", "check", "", [](Ctx& c) {
         npy::write(c.file("quats.npy"), std::vector<double>(kT * kN * 4, 0.0), {kT, kN, 4}); }, file_("quats.npy")},
      {"empty input T = 0", "graph", "", [](Ctx& c) {
         fs::remove(c.case_dir / "quats.npy");
         fs::remove(c.case_dir / "visibility.npy");
         npy::write(c.file("positions.npy"), std::vector<double>{}, {0, kN, 3}); }, file_("positions.npy")},
      {"empty input N = 0", "graph", "", [](Ctx& c) {
         fs::remove(c.case_dir / "quats.npy");
         fs::remove(c.case_dir / "visibility.npy");
         npy::write(c.file("positions.npy"), std::vector<double>{}, {kT, 0, 3}); }, file_("positions.npy")},
      {"empty input N = 0 (dqb)", "dqb", "", [](Ctx& c) {
         npy::write(c.file("positions.npy"), std::vector<double>{}, {kT, 0, 3}); }, file_("positions.npy")},
      {"coordinates around 1e200", "energies", "", [](Ctx& c) {
         npy::write(c.file("positions.npy"), ramp(kT * kN * 3, 1e200), {kT, kN, 3}); }, file_("positions.npy")},
      {"coordinates around 1e200 (graph)", "graph", "", [](Ctx& c) {
         npy::write(c.file("positions.npy"), ramp(kT * kN * 3, 1e200), {kT, kN, 3}); }, file_("positions.npy")},
      {"coordinates around 1e20 with --float", "dqb", "--float", [](Ctx& c) {
         npy::write(c.file("positions.npy"), ramp(kT * kN * 3, 1e20), {kT, kN, 3}); }, file_("positions.npy")},
      // --- integer narrowing ---
      {"graph index 2^32+3 (int64)", "energies", "", [](Ctx& c) {
         std::vector<std::int64_t> idx(kN * 2, 1);
         idx[3] = (std::int64_t(1) << 32) + 3;
         npy::write(c.file("graph_indices.npy"), idx, {kN, 2});
         npy::write(c.file("graph_weights.npy"), std::vector<double>(kN * 2, 0.5), {kN, 2}); }, file_("graph_indices.npy")},
      {"graph index out of range", "energies", "", [](Ctx& c) {
         std::vector<std::int32_t> idx(kN * 2, 1);
         idx[0] = 99;
         npy::write(c.file("graph_indices.npy"), idx, {kN, 2});
         npy::write(c.file("graph_weights.npy"), std::vector<double>(kN * 2, 0.5), {kN, 2}); }, file_("graph_indices.npy")},
      {"anchor 2^32+3 (int64)", "dqb", "", [](Ctx& c) {
         npy::write(c.file("anchor.npy"), std::vector<std::int64_t>{0, 1, (std::int64_t(1) << 32) + 3, 3}, {kP}); },
       file_("anchor.npy")},
      {"t_query negative", "dqb", "", [](Ctx& c) {
         npy::write(c.file("t_query.npy"), std::vector<std::int64_t>{1, -1}, {kQ}); }, file_("t_query.npy")},
      {"anchor as float", "dqb", "", [](Ctx& c) {
         npy::write(c.file("anchor.npy"), std::vector<double>{0, 1, 2, 3}, {kP}); }, file_("anchor.npy")},
      {"sigma zero", "dqb", "", [](Ctx& c) {
         npy::write(c.file("sigma.npy"), std::vector<double>(kN, 0.0), {kN}); }, file_("sigma.npy")},
      {"missing sigma.npy", "dqb", "", [](Ctx& c) { fs::remove(c.case_dir / "sigma.npy"); }, file_("sigma.npy")},
      {"NaN in points", "dqb", "", [](Ctx& c) {
         npy::write(c.file("points.npy"), std::vector<double>(kP * 3, std::nan("")), {kP, 3}); }, file_("points.npy")},
      // --- special files ---
      {"FIFO as positions.npy", "graph", "", [](Ctx& c) {
         fs::remove(c.case_dir / "positions.npy");
         REQUIRE(::mkfifo(c.file("positions.npy").c_str(), 0600) == 0); }, file_("positions.npy")},
      {"FIFO as an optional input", "energies", "", [](Ctx& c) {
         fs::remove(c.case_dir / "visibility.npy");
         REQUIRE(::mkfifo(c.file("visibility.npy").c_str(), 0600) == 0); }, file_("visibility.npy")},
      {"folder as colors.npy", "render", "--width 16 --height 16", [](Ctx& c) {
         fs::remove(c.case_dir / "colors.npy");
         fs::create_directories(c.case_dir / "colors.npy"); }, file_("colors.npy")},
      {"dangling symlink as positions.npy", "check", "", [](Ctx& c) {
         fs::remove(c.case_dir / "positions.npy");
         fs::create_symlink(c.root / "nowhere.npy", c.case_dir / "positions.npy"); }, file_("positions.npy")},
      {"case folder is a regular file", "check", "", [](Ctx& c) {
         fs::remove_all(c.case_dir);
         write_bytes(c.case_dir, "not a folder"); }, [](const Ctx& c) { return c.case_dir.string(); }},
      // --- flags ---
      {"--tile-size 4294967312 (wraps to 16)", "render", "--width 16 --height 16 --tile-size 4294967312", nothing, flag_("--tile-size")},
      {"--tile-size 12", "render", "--width 16 --height 16 --tile-size 12", nothing, flag_("--tile-size")},
      {"--k 4294967312", "graph", "--k 4294967312", nothing, flag_("--k")},
      {"--k 0", "energies", "--k 0", nothing, flag_("--k")},
      {"--k 1048576 beyond the memory limit", "graph", "--k 1048576 --max-memory-gb 0.01", nothing, flag_("--k")},
      {"--m 0", "graph", "--m 0", nothing, flag_("--m")},
      {"--rho 1.5", "graph", "--rho 1.5", nothing, flag_("--rho")},
      {"--tau nan", "graph", "--tau nan", nothing, flag_("--tau")},
      {"--aggregation mean", "dqb", "--aggregation mean", nothing, flag_("--aggregation")},
      {"--alpha 2", "energies", "--alpha 2", nothing, flag_("--alpha")},
      {"--kappa-m 0", "energies", "--kappa-m 0", nothing, flag_("--kappa-m")},
      {"--huber-delta -1", "energies", "--huber-delta -1", nothing, flag_("--huber-delta")},
      {"--gaps 1,x", "energies", "--gaps 1,x --gap-weights 1,1", nothing, flag_("--gaps")},
      {"--gaps 1,0", "energies", "--gaps 1,0 --gap-weights 1,1", nothing, flag_("--gaps")},
      {"--gap-weights count", "energies", "--gaps 1,2 --gap-weights 1", nothing, flag_("--gap-weights")},
      {"--gap-weights -1", "energies", "--gaps 1,2 --gap-weights 1,-1", nothing, flag_("--gap-weights")},
      {"--width 0", "render", "--width 0 --height 16", nothing, flag_("--width")},
      {"--width 65536 --height 65536 (memory)", "render", "--width 65536 --height 65536", nothing, flag_("--width")},
      {"--near 0", "render", "--width 16 --height 16 --near 0", nothing, flag_("--near")},
      {"--alpha-max 1", "render", "--width 16 --height 16 --alpha-max 1", nothing, flag_("--alpha-max")},
      {"--background with 2 values", "render", "--width 16 --height 16 --background 1,2", nothing, flag_("--background")},
      {"--threads -1", "graph", "--threads -1", nothing, flag_("--threads")},
      {"--threads 99999999999", "check", "--threads 99999999999", nothing, flag_("--threads")},
      {"--max-memory-gb 0", "energies", "--max-memory-gb 0", nothing, flag_("--max-memory-gb")},
      {"unknown flag", "dqb", "--bogus 1", nothing, flag_("--bogus")},
      {"flag without value", "graph", "--k", nothing, flag_("--k")},
      {"control characters in a flag value", "graph", "--k \"$(printf '1\\n2\\r\\t\\177')\"", nothing, flag_("--k")},
      // --- render inputs ---
      {"render zero quaternion", "render", "--width 16 --height 16", [](Ctx& c) {
         npy::write(c.file("quats.npy"), std::vector<double>(kG * 4, 0.0), {kG, 4}); }, file_("quats.npy")},
      {"render K.npy missing", "render", "--width 16 --height 16", [](Ctx& c) { fs::remove(c.case_dir / "K.npy"); },
       file_("K.npy")},
      {"render SH coefficient count 5", "render", "--width 16 --height 16", [](Ctx& c) {
         npy::write(c.file("colors.npy"), std::vector<double>(kG * 5 * 3, 0.1), {kG, 5, 3}); }, file_("colors.npy")},
      {"render grad_image of another size", "render", "--width 16 --height 16", [](Ctx& c) {
         npy::write(c.file("grad_image.npy"), std::vector<double>(8 * 8 * 3, 0.1), {8, 8, 3}); }, file_("grad_image.npy")},
      // --- memory ---
      {"Q x P blend of tens of GB", "dqb", "", [](Ctx& c) {
         const std::int64_t P = 20000, Q = 20000;
         npy::write(c.file("points.npy"), std::vector<double>(std::size_t(P * 3), 0.1), {P, 3});
         npy::write(c.file("anchor.npy"), std::vector<std::int64_t>(std::size_t(P), 0), {P});
         npy::write(c.file("t_ref.npy"), std::vector<std::int64_t>(std::size_t(P), 0), {P});
         npy::write(c.file("t_query.npy"), std::vector<std::int64_t>(std::size_t(Q), 1), {Q}); }, file_("t_query.npy")},
      // --- outputs ---
      {"OUT is a regular file", "graph", "", [](Ctx& c) {
         fs::remove_all(c.out);
         write_bytes(c.out, "a file where OUT should be"); }, [](const Ctx& c) { return c.out.string(); }},
      {"OUT's parent is a regular file", "energies", "", [](Ctx& c) {
         write_bytes(c.root / "plain", "x");
         c.out = c.root / "plain" / "sub" / "out"; }, [](const Ctx& c) { return (c.root / "plain").string(); }},
      {"directory at an output's name (rollback of earlier moves)", "graph", "", [](Ctx& c) {
         fs::create_directories(c.out / "distances.npy" / "inner"); },
       [](const Ctx& c) { return (c.out / "distances.npy").string(); }},
      {"symlink at an output's name", "dqb", "", [](Ctx& c) {
         fs::create_symlink(c.root / "victim", c.out / "blended_quats.npy"); },
       [](const Ctx& c) { return (c.out / "blended_quats.npy").string(); }},
      {"move failure after 3 of 6 outputs (injected)", "energies", "", nothing,
       [](const Ctx& c) { return (c.out / "grad_positions_lrm.npy").string(); }, "SMG_CLI_TEST_FAIL_MOVE=4"},
      {"move failure of a new OUT with new parents (injected)", "render", "--width 16 --height 16", [](Ctx& c) {
         c.out = c.root / "new1" / "new2" / "out"; }, [](const Ctx& c) { return c.out.string(); }, "SMG_CLI_TEST_FAIL_MOVE=1"},
  };
  return cs;
}

}  // namespace

TEST_CASE("robustness table: print with SMG_PRINT_CASES=1") {
  const auto cs = robustness_cases();
  CHECK(cs.size() >= 40);
  if (std::getenv("SMG_PRINT_CASES"))
    for (const auto& c : cs) std::cout << c.sub << ": " << c.name << (c.args.empty() ? "" : "  [" + c.args + "]") << "\n";
}

#ifdef SMG_CLI_PATH
TEST_CASE("smg_cli robustness: malformed inputs give one error line, exit code 2, nothing changed") {
  const fs::path base = fs::temp_directory_path() / "smg_test_cli_robustness";
  fs::remove_all(base);
  int k = 0;
  for (const Case& cs : robustness_cases()) {
    CAPTURE(cs.sub);
    CAPTURE(cs.name);
    Ctx c;
    c.root = base / ("case" + std::to_string(k++));
    c.case_dir = c.root / "case";
    c.out = c.root / "out";
    base_case(cs.sub, c.case_dir);
    old_outputs(c.out);
    write_bytes(c.root / "victim", "victim file\n");
    cs.setup(c);
    const auto before = snapshot(c.root);
    const bool writes = cs.sub != "check";
    const Run r = run_cli_env(cs.sub + " " + shell_quote(c.case_dir.string()) + (writes ? " " + shell_quote(c.out.string()) : "") +
                              " " + cs.args,
                          cs.env);
    CAPTURE(r.err);
    if (std::getenv("SMG_PRINT_CASES")) std::cout << cs.sub << ": " << cs.name << "\n    " << r.err;
    CHECK(r.code == 2);
    CHECK(r.out.empty());
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
    CHECK((!r.err.empty() && r.err.back() == '\n'));
    const std::string prefix = "smg_cli " + cs.sub + ": error: " + cs.names(c) + ":";
    CHECK(r.err.rfind(prefix, 0) == 0);
    CHECK(r.err.find("::") == std::string::npos);
    // The problem itself, for the classes whose root cause must not be masked by another check.
    static const std::map<std::string, std::string> problem = {
        {"shape overflows the element count", "overflows the element count"},
        {"shape whose byte count wraps to the file size", "overflows the byte count"},
        {"negative dimension", "negative dimension"},
        {"FIFO as positions.npy", "not a regular file"},
        {"FIFO as an optional input", "not a regular file"},
        {"empty input T = 0", "empty input (T = 0"},
        {"empty input N = 0", "empty input (N = 0"},
        {"coordinates around 1e200", "coordinates too large"},
        {"graph index 2^32+3 (int64)", "does not fit in int32"},
        {"--tile-size 4294967312 (wraps to 16)", "got 4294967312"},
        {"--k 1048576 beyond the memory limit", "--max-memory-gb"},
        {"--width 65536 --height 65536 (memory)", "--max-memory-gb"},
        {"Q x P blend of tens of GB", "--max-memory-gb"},
        {"control characters in a flag value", "'1\\n2\\r\\t\\x7f'"},
        {"directory at an output's name (rollback of earlier moves)", "not replaced"},
    };
    if (const auto it = problem.find(cs.name); it != problem.end()) CHECK(r.err.find(it->second) != std::string::npos);
    CHECK(snapshot(c.root) == before);
  }
  fs::remove_all(base);
}
#endif

#ifdef SMG_CLI_PATH
TEST_CASE("smg_cli outputs: planted symlinks at staging names are never followed; new OUT parents") {
  const fs::path root = fs::temp_directory_path() / "smg_test_cli_robustness_ok";
  fs::remove_all(root);
  const fs::path case_dir = root / "case", out = root / "out";
  base_case("graph", case_dir);
  fs::create_directories(out);
  write_bytes(root / "victim", "victim file\n");
  // The old fixed staging names, and a guess at the new ones: all must be left alone.
  for (const char* f : {".graph_indices.npy.partial", ".graph_weights.npy.partial", ".distances.npy.partial",
                        ".features.npy.partial", ".smg_stage.XXXXXX", ".smg_stage.000000"})
    fs::create_symlink(root / "victim", out / f);
  write_bytes(out / "graph_indices.npy", "old");
  Run r = run_cli_env("graph " + shell_quote(case_dir.string()) + " " + shell_quote(out.string()) + " --k 4");
  CAPTURE(r.err);
  REQUIRE(r.code == 0);
  CHECK(slurp(root / "victim") == "victim file\n");
  for (const char* f : {"graph_indices.npy", "graph_weights.npy", "distances.npy", "features.npy"}) {
    CAPTURE(f);
    CHECK(fs::is_regular_file(fs::symlink_status(out / f)));
    CHECK_NOTHROW(npy::read((out / f).string()));
  }
  CHECK(fs::is_symlink(fs::symlink_status(out / ".graph_indices.npy.partial")));
  // No staging folder is left behind.
  for (const auto& e : fs::directory_iterator(out)) {
    const std::string n = e.path().filename().string();
    if (n.rfind(".smg_stage.", 0) == 0) CHECK(fs::is_symlink(fs::symlink_status(e.path())));
  }
  // A new OUT with new parents appears complete; nothing else is left in its parent.
  const fs::path nested = root / "a" / "b" / "out";
  r = run_cli_env("graph " + shell_quote(case_dir.string()) + " " + shell_quote(nested.string()) + " --k 4");
  REQUIRE(r.code == 0);
  CHECK(fs::exists(nested / "graph_indices.npy"));
  std::vector<std::string> in_parent;
  for (const auto& e : fs::directory_iterator(root / "a" / "b")) in_parent.push_back(e.path().filename().string());
  CHECK(in_parent == std::vector<std::string>{"out"});
  // Replacing existing outputs keeps user files and leaves no backup behind.
  write_bytes(nested / "notes.txt", "mine");
  r = run_cli_env("graph " + shell_quote(case_dir.string()) + " " + shell_quote(nested.string()) + " --k 4");
  REQUIRE(r.code == 0);
  CHECK(slurp(nested / "notes.txt") == "mine");
  int entries = 0;
  for (const auto& e : fs::directory_iterator(nested)) {
    (void)e;
    ++entries;
  }
  CHECK(entries == 5);
  // OUT given with a trailing slash.
  r = run_cli_env("graph " + shell_quote(case_dir.string()) + " " + shell_quote((root / "t" / "out").string() + "/") + " --k 4");
  CHECK(r.code == 0);
  CHECK(fs::exists(root / "t" / "out" / "graph_indices.npy"));
  fs::remove_all(root);
}
#endif

TEST_CASE("npy::read survives randomised mutations of headers and sizes") {
  const fs::path dir = fs::temp_directory_path() / "smg_test_npy_mutation";
  fs::create_directories(dir);
  const fs::path file = dir / "m.npy";
  std::mt19937_64 rng(20261123);
  auto pick = [&](std::size_t n) { return static_cast<std::size_t>(rng() % n); };
  // Valid seeds of several dtypes, ranks and header versions.
  std::vector<std::string> seeds;
  seeds.push_back(raw_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 4, 3), }", f8(36)));
  seeds.push_back(raw_npy("{'descr': '<f4', 'fortran_order': False, 'shape': (5,), }", std::string(20, '\1')));
  seeds.push_back(raw_npy("{'descr': '<i8', 'fortran_order': False, 'shape': (2, 2), }", std::string(32, '\0')));
  seeds.push_back(raw_npy("{'descr': '|b1', 'fortran_order': False, 'shape': (7,), }", std::string(7, '\1')));
  seeds.push_back(raw_npy("{'descr': '<i4', 'fortran_order': False, 'shape': (), }", std::string(4, '\2'), 2));
  seeds.push_back(raw_npy("{'descr': '|u1', 'fortran_order': False, 'shape': (0, 5), }", "", 3));
  const std::vector<std::string> tokens = {"0", "1", "-1", "9223372036854775807", "4611686018427387904",
                                           "2305843009213693953", "999999999999999", "39673147557917, 58121", "100000000000000", "18446744073709551616",
                                           "(", ")", ",", "'", "{", "}", "<f8", ">f8", "True", " ", "\n", "\x7f"};
  int ok = 0, errors = 0;
  const int cases = 3000;
  for (int k = 0; k < cases; ++k) {
    std::string b = seeds[pick(seeds.size())];
    const int edits = 1 + static_cast<int>(pick(4));
    for (int e = 0; e < edits; ++e) {
      switch (pick(7)) {
        case 0: if (!b.empty()) b[pick(b.size())] = static_cast<char>(rng()); break;  // byte flip
        case 1: b.resize(pick(b.size() + 1)); break;                                   // truncate
        case 2: b.append(pick(64), static_cast<char>(rng())); break;                   // extend
        case 3: if (b.size() > 10) { b[8] = static_cast<char>(rng()); b[9] = static_cast<char>(rng() % 4); } break;  // header length
        case 4: {  // replace a shape dimension / header token
          const std::size_t at = b.find('(');
          if (at != std::string::npos && at + 1 < b.size()) b.insert(at + 1, tokens[pick(tokens.size())] + ", ");
          break;
        }
        case 5: {
          const std::size_t at = 10 + pick(std::max<std::size_t>(1, std::min<std::size_t>(b.size(), 80) - 9));
          if (at <= b.size()) b.insert(at, tokens[pick(tokens.size())]);
          break;
        }
        default: if (b.size() > 7) b[6] = static_cast<char>(1 + pick(4)); break;  // version
      }
    }
    write_bytes(file, b);
    try {
      const npy::Array a = npy::read(file.string());
      const std::int64_t n = a.size();
      CHECK(a.bytes.size() == static_cast<std::size_t>(n) * npy::dtype_size(a.dtype));
      if (npy::is_float(a.dtype)) CHECK(a.as<double>().size() == static_cast<std::size_t>(n));
      else CHECK(a.as<std::int64_t>().size() == static_cast<std::size_t>(n));
      ++ok;
    } catch (const npy::Error&) {
      ++errors;
    }
  }
  MESSAGE(ok << " mutated files read, " << errors << " refused with npy::Error");
  CHECK(ok + errors == cases);
  CHECK(errors > 0);
  fs::remove_all(dir);
}
