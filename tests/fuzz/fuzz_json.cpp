// tests/fuzz/fuzz_json.cpp — json::parse as the scene reader calls it (depth limit 64, NaN and
// Infinity allowed: Python's json writes them), then the typed getters the camera reader uses.
#include <string>

#include "fuzz_target.hpp"
#include "json_read.hpp"

SMG_FUZZ_TARGET(json)(const std::uint8_t* data, std::size_t size) {
  try {
    const json::Value v = json::parse(std::string(reinterpret_cast<const char*>(data), size), 64, true);
    if (v.is_object()) {
      (void)json::get_number(v, "focal_length");
      (void)json::get_numbers(v, "position", 3);
    }
  } catch (const json::Error&) {
  }
  return 0;
}
