// For the coordinator's tests: a LeaseTable::Clock whose wall and monotonic time move
// together, by hand, so that leases, sweeps and rates are tested without sleeping.
#pragma once

#include <chrono>
#include <cstdint>

#include "coordinator/lease_table.h"

namespace carvemap {

class FakeClock final : public LeaseTable::Clock {
 public:
  int64_t NowUnixMs() override { return now_ms; }
  std::chrono::steady_clock::time_point SteadyNow() override {
    return std::chrono::steady_clock::time_point{} + std::chrono::milliseconds(now_ms);
  }
  void AdvanceMs(int64_t ms) { now_ms += ms; }
  int64_t now_ms = 1'700'000'000'000;
};

}  // namespace carvemap
