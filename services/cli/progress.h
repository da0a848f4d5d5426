// A progress line on stderr, redrawn in place at most once a second, for long commands.
#pragma once

#include <chrono>
#include <cstdarg>
#include <cstdio>

#include <unistd.h>

#include "services/sim/simulator.h"

namespace carvemap {

class ProgressLine {
 public:
  // On a terminal the line is redrawn in place; in a log each update is its own line, every
  // 10 s.
  explicit ProgressLine(bool enabled = true)
      : enabled_(enabled), tty_(isatty(fileno(stderr)) != 0) {}
  ~ProgressLine() { Finish(); }

  // printf-style; dropped when the last line was drawn less than a second ago.
  [[gnu::format(printf, 2, 3)]] void Update(const char* format, ...) {
    if (!enabled_) return;
    const auto now = std::chrono::steady_clock::now();
    if (drawn_ && now - last_ < std::chrono::seconds(tty_ ? 1 : 10)) return;
    last_ = now;
    drawn_ = true;
    if (tty_) std::fputc('\r', stderr);
    va_list args;
    va_start(args, format);
    std::vfprintf(stderr, format, args);
    va_end(args);
    std::fputs(tty_ ? "   " : "\n", stderr);
  }
  // Ends the line so later output starts on a fresh one.
  void Finish() {
    if (drawn_ && tty_) std::fputc('\n', stderr);
    drawn_ = false;
  }

 private:
  bool enabled_;
  bool tty_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_;
};

// Draws the simulator's progress (share of the walk, rays/s) on `line`, which must outlive it.
ProgressCallback SimulationProgressPrinter(ProgressLine& line);

}  // namespace carvemap
