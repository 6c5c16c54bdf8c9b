// tests/support/files.hpp — whole-file reads and writes for the tests of the programs and file
// formats (bytes as they are: binary mode, no newline translation).
#pragma once

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace smg::test {

// The bytes of file p ("" when it cannot be read).
inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Replaces the contents of file p by `bytes` (creating it).
inline void write_bytes(const std::filesystem::path& p, const std::string& bytes) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace smg::test
