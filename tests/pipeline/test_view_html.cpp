// tests/pipeline/test_view_html.cpp — the base64 encoder that embeds view.html's data
// (examples/trainer/view_html.hpp). The page itself is checked in a browser by
// test_view_html.py (ctest view_html).
#include <doctest/doctest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "trainer/view_html.hpp"

namespace {
std::string view_b64(const std::string& s) {
  return trainer::base64_encode(reinterpret_cast<const std::uint8_t*>(s.data()), s.size());
}
}  // namespace

TEST_CASE("base64_encode: RFC 4648's test vectors") {
  const char* const vectors[][2] = {{"", ""},         {"f", "Zg=="},         {"fo", "Zm8="},        {"foo", "Zm9v"},
                                    {"foob", "Zm9vYg=="}, {"fooba", "Zm9vYmE="}, {"foobar", "Zm9vYmFy"}};
  for (const auto& v : vectors) {
    CAPTURE(v[0]);
    CHECK(view_b64(v[0]) == v[1]);
  }
}

TEST_CASE("base64_encode: every byte value, as Python's base64.b64encode(bytes(range(256))) gives it") {
  std::vector<std::uint8_t> all(256);
  for (int i = 0; i < 256; ++i) all[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(i);
  const std::string python =
      "AAECAwQFBgcICQoLDA0ODxAREhMUFRYXGBkaGxwdHh8gISIjJCUmJygpKissLS4vMDEyMzQ1Njc4OTo7PD0+P0BBQkNERUZHSElK"
      "S0xNTk9QUVJTVFVWV1hZWltcXV5fYGFiY2RlZmdoaWprbG1ub3BxcnN0dXZ3eHl6e3x9fn+AgYKDhIWGh4iJiouMjY6PkJGSk5SV"
      "lpeYmZqbnJ2en6ChoqOkpaanqKmqq6ytrq+wsbKztLW2t7i5uru8vb6/wMHCw8TFxsfIycrLzM3Oz9DR0tPU1dbX2Nna29zd3t/g"
      "4eLj5OXm5+jp6uvs7e7v8PHy8/T19vf4+fr7/P3+/w==";
  CHECK(trainer::base64_encode(all.data(), all.size()) == python);
}
