#include "coordinator/rate_window.h"

#include <algorithm>

namespace carvemap {

void RateWindow::Add(Time now, double amount) {
  if (amount <= 0) return;
  total_ += amount;
  samples_.emplace_back(now, amount);
  while (!samples_.empty() && now - samples_.front().first > window_) samples_.pop_front();
}

double RateWindow::Rate(Time now) const {
  // The increments within the window. The first one's work was done before it arrived, over
  // an interval nobody measured: the rate is what came after it over the time since it. With
  // a single increment, its amount over the time since it (at least a second).
  const std::pair<Time, double>* first = nullptr;
  double after_first = 0;
  for (const auto& s : samples_) {
    if (now - s.first > window_) continue;
    if (first == nullptr) {
      first = &s;
    } else {
      after_first += s.second;
    }
  }
  if (first == nullptr) return 0;
  const double since = std::chrono::duration<double>(now - first->first).count();
  if (after_first == 0) return first->second / std::max(since, 1.0);
  return since > 0 ? after_first / since : 0;
}

}  // namespace carvemap
