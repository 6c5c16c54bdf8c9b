// tests/support/errors.hpp — the message of an expected exception, for tests that compare error
// messages whole (CHECK(message == "...") prints both strings when they differ).
#pragma once

#include <string>

namespace smg::test {

// e.what() of the exception of type E that f() throws; `none` when f() returns normally (an
// exception of another type propagates and fails the test).
template <class E, class F>
std::string error_message(F&& f, const std::string& none = "") {
  try {
    f();
  } catch (const E& e) {
    return e.what();
  }
  return none;
}

}  // namespace smg::test
