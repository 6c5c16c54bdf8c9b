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
    char head[64];
    std::snprintf(head, sizeof head, "[%7.1fs] %-7s ", elapsed(), stage.c_str());
    const std::string out = head + cli::escape_line(text) + "\n";
    if (holding_) {
      held_ += out;
      return;
    }
    std::fputs(out.c_str(), stream_);
    std::fflush(stream_);
  }
  bool quiet() const { return quiet_; }

  // Holds the lines back, in memory, until release(): a caller that may still refuse its input
  // (smg_trainer --data before stage 0 has accepted the scene) then prints only the refusal;
  // a Progress destroyed while holding drops them.
  void hold() const { holding_ = true; }
  void release() const {
    holding_ = false;
    if (held_.empty()) return;
    std::fputs(held_.c_str(), stream_);
    std::fflush(stream_);
    held_.clear();
  }

 private:
  std::FILE* stream_;
  bool quiet_;
  std::chrono::steady_clock::time_point start_;
  mutable bool holding_ = false;  // hold()/release() are const like line(): callers pass const&
  mutable std::string held_;
};

// printf into a std::string.
template <class... A>
std::string format(const char* fmt, A... args) {
  char buf[512];
  std::snprintf(buf, sizeof buf, fmt, args...);
  return buf;
}

}  // namespace trainer
