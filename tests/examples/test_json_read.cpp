// Tests of examples/common/json_read.hpp: the strict JSON reader (values, escapes, numbers),
// errors with line and column for malformed text, the NaN/Infinity literals (refused unless
// allowed), the nesting limit, and the get_* helpers' messages.
#include <doctest/doctest.h>

#include <cmath>
#include <string>

#include "json_read.hpp"
#include "support/errors.hpp"

namespace {
std::string error_of(const std::string& text, int max_depth = 64) {
  return smg::test::error_message<json::Error>([&] { json::parse(text, max_depth); });
}
template <class F>
std::string helper_error(F&& f) {
  return smg::test::error_message<json::Error>(f);
}
}  // namespace

TEST_CASE("json: a valid document with every kind of value") {
  const json::Value v = json::parse(R"( {"a": 1, "b": [1.5, -2e3, 0, -0.25E-2], "s": "x\"y\\z\/\n\u00e9\ud83d\ude00",
    "t": true, "f": false, "n": null, "o": {"k": []}, "e": {}} )");
  REQUIRE(v.is_object());
  CHECK(v.members.size() == 8);
  CHECK(json::get_number(v, "a") == 1);
  const auto b = json::get_numbers(v, "b", 4);
  CHECK(b[0] == 1.5);
  CHECK(b[1] == -2000);
  CHECK(b[2] == 0);
  CHECK(b[3] == -0.0025);
  CHECK(v.find("s")->string == "x\"y\\z/\n\xc3\xa9\xf0\x9f\x98\x80");
  CHECK(v.find("t")->boolean);
  CHECK(v.find("f")->type == json::Value::Type::boolean);
  CHECK(!v.find("f")->boolean);
  CHECK(v.find("n")->type == json::Value::Type::null);
  CHECK(v.find("o")->find("k")->is_array());
  CHECK(v.find("missing") == nullptr);
  CHECK(json::parse("3").number == 3);
  CHECK(json::parse("1e-400").number == 0);  // underflow is the nearest double
}

TEST_CASE("json: malformed text is an error with line and column") {
  CHECK(error_of("") == "line 1, column 1: unexpected end of text (expected a value)");
  CHECK(error_of("{\"a\": 1,}") == "line 1, column 9: expected a string key");
  CHECK(error_of("[1, 2,]") == "line 1, column 7: unexpected character ']'");
  CHECK(error_of("{\n  \"a\": 1\n  \"b\": 2}") == "line 3, column 3: expected ',' or '}'");
  CHECK(error_of("[1 2]") == "line 1, column 4: expected ',' or ']'");
  CHECK(error_of("{\"a\" 1}") == "line 1, column 6: expected ':' after a key");
  CHECK(error_of("[1] x") == "line 1, column 5: unexpected text after the JSON value");
  CHECK(error_of("\"abc") == "line 1, column 1: unterminated string");
  CHECK(error_of("\"a\tb\"") == "line 1, column 3: control character in a string (escape it)");
  CHECK(error_of("\"\\x\"") == "line 1, column 2: invalid escape in a string");
  CHECK(error_of("\"\\u12g4\"") == "line 1, column 6: invalid \\u escape");
  CHECK(error_of("\"\\ud800\"") == "line 1, column 8: unpaired surrogate in \\u escape");
  CHECK(error_of("01") == "line 1, column 1: leading zero in a number");
  CHECK(error_of("1.") == "line 1, column 1: invalid number (no digits after '.')");
  CHECK(error_of("1e+") == "line 1, column 1: invalid number (no digits in the exponent)");
  CHECK(error_of("-") == "line 1, column 1: invalid number");
  CHECK(error_of("+1") == "line 1, column 1: unexpected character '+'");
  CHECK(error_of("1e999") == "line 1, column 1: number 1e999 is out of range");
  CHECK(error_of("tru") == "line 1, column 1: invalid literal (expected 'true')");
  CHECK(error_of("nul") == "line 1, column 1: invalid literal (expected 'null')");
  CHECK(error_of("{\"a\": 1, \"a\": 2}") == "line 1, column 10: duplicate key 'a'");
  CHECK(error_of("// c\n1") == "line 1, column 1: unexpected character '/'");
  CHECK(error_of("{'a': 1}") == "line 1, column 2: expected a string key");
}

TEST_CASE("json: NaN and Infinity literals are refused unless allowed") {
  CHECK(error_of("{\"f\": NaN}") == "line 1, column 7: NaN and Infinity are not JSON numbers");
  CHECK(error_of("[Infinity]") == "line 1, column 2: NaN and Infinity are not JSON numbers");
  CHECK(error_of("[-Infinity]") == "line 1, column 2: NaN and Infinity are not JSON numbers");
  const json::Value v = json::parse("[NaN, Infinity, -Infinity]", 64, true);
  CHECK(std::isnan(v.items[0].number));
  CHECK(v.items[1].number == HUGE_VAL);
  CHECK(v.items[2].number == -HUGE_VAL);
  CHECK(error_of("[-NaN]") != "");
  try {
    json::parse("[Nan]", 64, true);
    FAIL("no error");
  } catch (const json::Error& e) {
    CHECK(std::string(e.what()) == "line 1, column 2: invalid literal (expected 'NaN')");
  }
}

TEST_CASE("json: nesting deeper than the limit is an error, not a stack overflow") {
  std::string ok(64, '[');
  ok += std::string(64, ']');
  CHECK(json::parse(ok).is_array());
  std::string deep(65, '[');
  deep += std::string(65, ']');
  CHECK(error_of(deep) == "line 1, column 65: nesting deeper than 64 levels");
  CHECK(error_of("{\"a\": {\"b\": 1}}", 1) == "line 1, column 7: nesting deeper than 1 levels");
  const std::string huge(1000000, '[');
  CHECK(error_of(huge).find("nesting deeper than 64 levels") != std::string::npos);
}

TEST_CASE("json: get_* helpers name the key; extra keys are tolerated") {
  const json::Value v = json::parse(R"({"x": "s", "n": 2, "a": [1, "b"], "i": [1, 2.5], "names": ["p", 3],
                                        "ints": [0, -4, 7], "strs": ["u", "v"], "extra": {"deep": [1]}})");
  CHECK(helper_error([&] { json::get_number(v, "y"); }) == "missing key 'y'");
  CHECK(helper_error([&] { json::get_number(v, "x"); }) == "'x' is not a number (found a string)");
  CHECK(helper_error([&] { json::get_numbers(v, "n"); }) == "'n' is not an array (found a number)");
  CHECK(helper_error([&] { json::get_numbers(v, "a"); }) == "'a'[1] is not a number (found a string)");
  CHECK(helper_error([&] { json::get_numbers(v, "ints", 2); }) == "'ints' has 3 elements, expected 2");
  CHECK(helper_error([&] { json::get_ints(v, "i"); }) == "'i'[1] is not an integer");
  CHECK(helper_error([&] { json::get_strings(v, "names"); }) == "'names'[1] is not a string (found a number)");
  CHECK(helper_error([&] { json::get_number(json::parse("[1]"), "a"); }) == "expected an object, found an array");
  CHECK(json::get_ints(v, "ints") == std::vector<std::int64_t>{0, -4, 7});
  CHECK(json::get_strings(v, "strs") == std::vector<std::string>{"u", "v"});
  CHECK(json::get_number(v, "n") == 2);
}
