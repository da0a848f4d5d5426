// A progress line on stderr, redrawn in place at most once a second, for long commands.
#pragma once

#include <chrono>
#include <cstdarg>
#include <cstdio>

#include "services/sim/simulator.h"

namespace carvemap {

class ProgressLine {
 public:
  explicit ProgressLine(bool enabled = true) : enabled_(enabled) {}
  ~ProgressLine() { Finish(); }

  // printf-style; dropped when the last line was drawn less than a second ago.
  [[gnu::format(printf, 2, 3)]] void Update(const char* format, ...) {
    if (!enabled_) return;
    const auto now = std::chrono::steady_clock::now();
    if (drawn_ && now - last_ < std::chrono::seconds(1)) return;
    last_ = now;
    drawn_ = true;
    std::fputc('\r', stderr);
    va_list args;
    va_start(args, format);
    std::vfprintf(stderr, format, args);
    va_end(args);
    std::fputs("   ", stderr);
  }
  // Ends the line so later output starts on a fresh one.
  void Finish() {
    if (drawn_) std::fputc('\n', stderr);
    drawn_ = false;
  }

 private:
  bool enabled_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_;
};

// Draws the simulator's progress (share of the walk, rays/s) on `line`, which must outlive it.
ProgressCallback SimulationProgressPrinter(ProgressLine& line);

}  // namespace carvemap
