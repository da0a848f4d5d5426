// Test support: a small, fast `room` scan (5 Hz, 2° beams, 10 s walk) for suites that need
// real scan data but not accuracy. Link: carvemap_sim.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "services/sim/simulator.h"

namespace carvemap::testing {

// Simulates into `dir`; returns the scan.h5 path.
inline absl::StatusOr<std::string> SimulateThinRoomScan(const std::string& dir, uint64_t seed) {
  SimulateOptions o;
  o.preset = "room";
  o.seed = seed;
  o.rig.rate_hz = 5;
  o.rig.beam_step_deg = 2;
  o.max_duration_s = 10;
  o.output_dir = dir;
  absl::StatusOr<SimulationSummary> s = Simulate(o);
  if (!s.ok()) return s.status();
  return s->scan_path;
}

}  // namespace carvemap::testing
