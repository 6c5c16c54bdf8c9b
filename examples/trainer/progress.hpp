// examples/trainer/progress.hpp — progress lines: "[  12.3s] stage1  it  100/400  ...".
//
// One line per report on the given stream (stderr by default, so that stdout keeps only the
// final metrics JSON line), prefixed by the elapsed wall time since the Progress was made.
// quiet = true suppresses everything (tests). Every line is one line: control characters in the
// text (a scene path or frame name from disk, an exception message) are escaped here, so no
// caller has to remember to.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

#include "cli_args.hpp"  // cli::escape_line

namespace trainer {

// Seconds since t0.
inline double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

class Progress {
 public:
  explicit Progress(std::FILE* stream = stderr, bool quiet = false)
      : stream_(stream), quiet_(quiet), start_(std::chrono::steady_clock::now()) {}
  // Counting from `start` (another Progress's start(): one clock across two streams).
  Progress(std::FILE* stream, bool quiet, std::chrono::steady_clock::time_point start)
      : stream_(stream), quiet_(quiet), start_(start) {}

  double elapsed() const { return seconds_since(start_); }
  std::chrono::steady_clock::time_point start() const { return start_; }
  void line(const std::string& stage, const std::string& text) const {
    if (quiet_ || !stream_) return;
    std::fprintf(stream_, "[%7.1fs] %-7s %s\n", elapsed(), stage.c_str(), cli::escape_line(text).c_str());
    std::fflush(stream_);
  }
  bool quiet() const { return quiet_; }

 private:
  std::FILE* stream_;
  bool quiet_;
  std::chrono::steady_clock::time_point start_;
};

// printf into a std::string.
template <class... A>
std::string format(const char* fmt, A... args) {
  char buf[512];
  std::snprintf(buf, sizeof buf, fmt, args...);
  return buf;
}

}  // namespace trainer
