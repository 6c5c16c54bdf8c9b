// smg/core/status.hpp — the result of a validation function: ok, or one clear message.
//
// Validation is separate from computation (docs/design.md "Errors"): each entry point has one
// validate_* function that callers run on untrusted input; hot loops never check.
#pragma once

#include "smg/core/config.hpp"

#include <string>
#include <utility>

namespace smg {

class Status {
 public:
  Status() = default;  // ok
  static Status ok() { return Status(); }
  static Status error(std::string message) { return Status(std::move(message), false); }

  bool is_ok() const { return ok_; }
  explicit operator bool() const { return ok_; }
  // Empty when ok; otherwise a one-line message naming the argument and the problem.
  const std::string& message() const { return message_; }

 private:
  Status(std::string message, bool ok) : message_(std::move(message)), ok_(ok) {}
  std::string message_;
  bool ok_ = true;
};

}  // namespace smg
