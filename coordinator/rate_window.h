// The recent rate of a growing count (work done), from increments as they arrive: the carve's
// live rays/s, fed by the workers' heartbeats (each carries the wedges carved since the last
// one, mid-chunk too), so a progress line shows the rate the workers carve at, not the
// moments chunks happen to finish. Plain data, time passed in.
#pragma once

#include <chrono>
#include <deque>
#include <utility>

namespace carvemap {

class RateWindow {
 public:
  using Time = std::chrono::steady_clock::time_point;

  // Rates over the last `window_s` seconds (> 0). The default spans six of a worker's 5-s
  // heartbeats: over two, the rate swung with when a batch's chunks happened to be carved.
  explicit RateWindow(double window_s = 30.0) : window_(window_s) {}

  // `amount` more was done by `now` (times non-decreasing).
  void Add(Time now, double amount);
  // Per second over the window ending at `now`: the increments within it over the time since
  // the window began, or since the first increment when that is later (a young window is not
  // diluted by time before any work). 0 before any increment, and once none came for a
  // whole window.
  [[nodiscard]] double Rate(Time now) const;
  [[nodiscard]] double total() const { return total_; }

 private:
  std::chrono::duration<double> window_;
  double total_ = 0;
  std::deque<std::pair<Time, double>> samples_;  // (time, amount added then), oldest first
};

}  // namespace carvemap
