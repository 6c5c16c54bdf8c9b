// smg_cli check CASE — loads the standard node files of a case directory and validates them
// with the library's validators; writes nothing. Use it to find out why another subcommand
// rejects a case, or to confirm that a Python exporter writes what smg expects.
#include <chrono>
#include <cstdint>

#include "smg/core/validate.hpp"
#include "subcommand.hpp"

namespace cli {

namespace {

void check_case(const Invocation& inv, JsonLine& summary) {
  const auto t0 = std::chrono::steady_clock::now();
  const CaseDir& c = inv.case_dir;
  const auto x = c.load<double>("positions.npy", {{"T"}, {"N"}, {"", 3}});
  const std::int64_t T = x.dim(0), N = x.dim(1);
  std::string files = "[\"positions.npy\"";
  auto ok = [](const smg::Status& s) {
    if (!s) throw RunError(s.message());
  };
  ok(smg::validate_positions<double>({x.ptr(), T, N}, T, N, c.file("positions.npy")));
  if (auto q = c.load_optional<double>("quats.npy", {{"T", T}, {"N", N}, {"", 4}})) {
    ok(smg::validate_quaternions<double>({q->ptr(), T, N}, T, N,
                                         smg::QuaternionNorm::normalize_on_entry, c.file("quats.npy")));
    files += ",\"quats.npy\"";
  }
  if (auto v = c.load_optional<std::uint8_t>("visibility.npy", {{"T", T}, {"N", N}})) {
    ok(smg::validate_visibility<std::uint8_t>({v->ptr(), T, N}, T, N, c.file("visibility.npy")));
    files += ",\"visibility.npy\"";
  }
  std::int64_t C = 0;
  if (auto g = c.load_optional<double>("feature_samples.npy", {{"T", T}, {"N", N}, {"C"}})) {
    C = g->dim(2);
    ok(smg::validate_feature_samples<double>({g->ptr(), T, N, C}, T, N, C, c.file("feature_samples.npy")));
    files += ",\"feature_samples.npy\"";
  }
  if (auto f = c.load_optional<double>("features.npy", {{"N", N}, {"C", C > 0 ? C : -1}})) {
    C = f->dim(1);
    ok(smg::validate_features<double>({f->ptr(), N, C}, N, C, c.file("features.npy")));
    files += ",\"features.npy\"";
  }
  files += "]";
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Files are validated in double whatever --float says.
  summary.add("T", T).add("N", N).add("C", C).add_raw("files", files).add("precision", "float64")
      .add("seconds", seconds);
}

}  // namespace

Subcommand check_subcommand() {
  return {"check", "validate a case directory's node files (positions, quats, visibility, features)", {},
          /*writes_output=*/false, check_case};
}

}  // namespace cli
