// tests/trainer/layout_fixture.hpp — what the tests of the layout readers share
// (test_layout_som.cpp, test_layout_mosca.cpp): a fresh copy of a checked-in fixture under
// tests/data, to break one file of, the one-line error that reading a scene gives, and the check
// of a missing file.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <doctest/doctest.h>

#include "support/errors.hpp"
#include "trainer/layouts.hpp"

namespace trainer::test {

// tests/data/<fixture> copied to <tmp>/smg_test_layout_<fixture>_<name> (replacing any old copy).
inline std::filesystem::path layout_fixture_copy(const std::string& fixture, const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path p = fs::temp_directory_path() / ("smg_test_layout_" + fixture + "_" + name);
  fs::remove_all(p);
  fs::copy(fs::path(SMG_TEST_DATA_DIR) / fixture, p, fs::copy_options::recursive);
  return p;
}

// The DataError message of read_data_scene(dir) ("(read)" when it does not throw).
inline std::string layout_read_error(const std::filesystem::path& dir) {
  return smg::test::error_message<trainer::DataError>([&] { (void)trainer::read_data_scene(dir.string()); }, "(read)");
}

// Each of `rels` removed in turn from a fresh copy of tests/data/<fixture>: the error names it.
inline void check_missing_files(const std::string& fixture, const std::vector<std::string>& rels) {
  for (const std::string& rel : rels) {
    CAPTURE(rel);
    const std::filesystem::path d = layout_fixture_copy(fixture, "missing");
    std::filesystem::remove(d / rel);
    CHECK(layout_read_error(d).rfind(rel + ": ", 0) == 0);
  }
}

}  // namespace trainer::test
