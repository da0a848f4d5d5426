// The backpack's line scanners (§2.1: Hokuyo UTM-30LX, 40 Hz, 270°, 0.25°, 30 m): one level,
// two near-vertical across the walking direction, with lever arms from the system origin.
//
// Sensor frame convention: beam j has angle a_j = -fov/2 + j·step in the sensor's x-y plane and
// direction (cos a_j, sin a_j, 0); a ∈ [−135°, 135°] at the default 270° field of view, so the
// sensor's +x is the middle of the sweep. System frame: x forward, y left, z up.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "geometry/pose.h"

namespace carvemap {

struct RigOptions {
  double rate_hz = 40.0;        // frames per second per scanner
  double beam_step_deg = 0.25;  // angle between beams
  double fov_deg = 270.0;
  double max_range_m = 30.0;
  double tilt_yaw_deg = 25.0;   // the vertical scanners' planes are yawed ± this from "across"
  [[nodiscard]] absl::Status Validate() const;
};

struct LineScanner {
  std::string name;
  Pose T_system_sensor;  // sensor ➜ system (R_s2c, T_s2c)
  double rate_hz = 40;
  double phase_s = 0;    // first frame time offset, so the scanners' frames interleave
  double max_range_m = 30;
  std::vector<Eigen::Vector3f> beams_sensor;  // unit directions, in angle order
};

// "h_level", "v_left", "v_right".
[[nodiscard]] std::vector<LineScanner> MakeBackpackRig(const RigOptions& options);

}  // namespace carvemap
