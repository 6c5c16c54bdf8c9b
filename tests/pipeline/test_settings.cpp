// smg_trainer's settings table (examples/trainer/settings.hpp): every row is checked by the same
// loop, so a new setting is covered by adding its row. What is checked: --help's default is
// default_config's value (both sizes), each range end and each name is accepted and lands in the
// config, a value outside the range or the names is a usage error naming the flag, and a flag
// not given leaves the config untouched.
#include <doctest/doctest.h>

#include <string>
#include <vector>

#include "trainer/settings.hpp"

namespace {

using trainer::Setting;
using trainer::SettingKind;

// cli::Args holding the setting flags, parsed from `words` (e.g. {"--frames", "8"}).
cli::Args parsed(const std::vector<std::string>& words) {
  cli::Args a(trainer::setting_flags());
  std::vector<const char*> argv{"smg_trainer"};
  for (const auto& w : words) argv.push_back(w.c_str());
  a.parse(static_cast<int>(argv.size()), argv.data(), 1);
  return a;
}

// The value given for a setting, as the command line spells it.
std::string spelled(const Setting& s, double v) {
  if (s.kind == SettingKind::integer) return std::to_string(static_cast<long long>(v));
  return std::to_string(v);
}

}  // namespace

TEST_CASE("settings: --help shows default_config's defaults and the enforced ranges") {
  const std::vector<cli::FlagSpec> specs = trainer::setting_flags();
  REQUIRE(specs.size() == trainer::settings().size());
  for (std::size_t k = 0; k < specs.size(); ++k) {
    const Setting& s = trainer::settings()[k];
    CAPTURE(s.name);
    CHECK(specs[k].name == s.name);
    CHECK(specs[k].is_switch == (s.kind == SettingKind::flag));
    const std::string d = trainer::setting_default(s, false);
    if (!d.empty()) CHECK(specs[k].help.find("default " + d) != std::string::npos);
    if (s.kind == SettingKind::choice)
      for (const std::string& n : s.choices()) CHECK(specs[k].help.find(n) != std::string::npos);
  }
  // One row spelled out: the defaults are default_config's (32 frames, 16 with --quick).
  const trainer::TrainerConfig full = trainer::default_config(false), quick = trainer::default_config(true);
  CHECK(full.dataset.scene.frames == 32);
  CHECK(quick.dataset.scene.frames == 16);
  for (const auto& f : specs)
    if (f.name == "frames") CHECK(f.help == "number of frames T (in [4, 1000]; default 32, quick 16; not with --data)");
}

TEST_CASE("settings: every range end and name is accepted and lands in the config") {
  for (const Setting& s : trainer::settings()) {
    if (!s.set) continue;
    CAPTURE(s.name);
    const bool has_get = s.get != nullptr;
    REQUIRE(has_get);
    std::vector<double> values;
    if (s.kind == SettingKind::choice)
      for (std::size_t k = 0; k < s.choices().size(); ++k) values.push_back(static_cast<double>(k));
    else
      values = {s.lo, s.hi, 0.5 * (s.lo + s.hi)};
    for (double v : values) {
      const std::string word = s.kind == SettingKind::choice ? s.choices()[static_cast<std::size_t>(v)] : spelled(s, v);
      CAPTURE(word);
      trainer::TrainerConfig c = trainer::default_config(false);
      trainer::apply_settings(parsed({"--" + std::string(s.name), word}), &c);
      const double want = s.kind == SettingKind::integer ? static_cast<double>(static_cast<long long>(v)) : v;
      CHECK(s.get(c) == doctest::Approx(want).epsilon(1e-12));
    }
  }
}

TEST_CASE("settings: out of range or unknown is a usage error naming the flag; not given changes nothing") {
  for (const Setting& s : trainer::settings()) {
    if (!s.set) continue;
    CAPTURE(s.name);
    std::vector<std::string> bad;
    if (s.kind == SettingKind::choice) bad = {"no-such-" + std::string(s.name)};
    if (s.kind == SettingKind::integer) bad = {spelled(s, s.lo - 1), spelled(s, s.hi + 1), "abc", "1.5"};
    if (s.kind == SettingKind::number) bad = {spelled(s, s.lo - 1e-3), spelled(s, s.hi * 1.01 + 1), "nan", "abc"};
    for (const std::string& word : bad) {
      CAPTURE(word);
      trainer::TrainerConfig c = trainer::default_config(false);
      try {
        trainer::apply_settings(parsed({"--" + std::string(s.name), word}), &c);
        FAIL("accepted");
      } catch (const cli::UsageError& e) {
        CHECK(std::string(e.what()).find(std::string("--") + s.name) != std::string::npos);
      }
    }
  }
}

TEST_CASE("settings: each row writes its own field and no other") {
  // A row whose accessors point at another row's field (a copied line) fails here.
  const trainer::TrainerConfig d = trainer::default_config(false);
  for (const Setting& s : trainer::settings()) {
    if (!s.set) continue;
    CAPTURE(s.name);
    const double v = s.kind == SettingKind::choice ? (s.get(d) == 0.0 ? 1.0 : 0.0) : s.hi;
    REQUIRE(v != s.get(d));
    const std::string word = s.kind == SettingKind::choice ? s.choices()[static_cast<std::size_t>(v)] : spelled(s, v);
    trainer::TrainerConfig c = d;
    trainer::apply_settings(parsed({"--" + std::string(s.name), word}), &c);
    CHECK(s.get(c) != s.get(d));
    for (const Setting& o : trainer::settings())
      if (o.get && &o != &s) CHECK_MESSAGE(o.get(c) == o.get(d), o.name);
  }
  // Not given: nothing changes, in either size.
  for (const bool quick : {false, true}) {
    trainer::TrainerConfig c = trainer::default_config(quick);
    trainer::apply_settings(parsed({}), &c);
    for (const Setting& s : trainer::settings())
      if (s.get) CHECK(s.get(c) == s.get(trainer::default_config(quick)));
  }
}
