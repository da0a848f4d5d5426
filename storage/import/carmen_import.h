// CARMEN robot logs (text, one message per line, plain or gzip-compressed) ➜ one `line` sensor.
//
// Lines read (fields separated by blanks; the last three of every message are
// "timestamp host logger_timestamp", and the message's own timestamp is the one used):
//   FLASER / RLASER n r_1..r_n x y theta odom_x odom_y odom_theta timestamp host logger_timestamp
//       old format, front / rear laser; (x, y, theta) is the laser's pose (corrected in a
//       SLAM-corrected log). The n beams span 180° from theta − 90°, spaced π/n for n = 180 or 360
//       and π/(n − 1) for n = 181 or 361 (CARMEN's own guess for these scanners); other n are
//       refused rather than guessed. logger_timestamp may be missing.
//   ROBOTLASER<k> type start_angle fov resolution max_range accuracy remission_mode
//       n r_1..r_n m e_1..e_m laser_x laser_y laser_theta robot_x robot_y robot_theta
//       tv rv forward_safety side_safety turn_axis timestamp host logger_timestamp
//   RAWLASER<k> type start_angle fov resolution max_range accuracy remission_mode
//       n r_1..r_n m e_1..e_m timestamp host logger_timestamp
//       (older loggers wrote both without remission_mode; both layouts are accepted). Beam i
//       is at start_angle + i·resolution from the laser's heading.
//   ODOM x y theta tv rv accel timestamp host logger_timestamp
// Other messages (PARAM, NEFF, SYNC, TRUEPOS, ...) and # comments are skipped.
//
// Mapping: one laser is imported (`laser`: 1 = front = FLASER / ROBOTLASER1 / RAWLASER1,
// 2 = rear = RLASER / ROBOTLASER2 / RAWLASER2, 3 and 4 = RAWLASER3/4, ROBOTLASER3/4) as sensor
// "front", "rear", "laser3" or "laser4", kind line. The system frame is the laser's pose on
// the floor: /path rows are (x, y, 0) with yaw theta, and the sensor sits `height_m` above it
// (T_s2c = (0, 0, height), R_s2c = identity): CARMEN logs are 2D and say nothing of height.
//   - If the log has lines of this laser that carry a pose (FLASER/RLASER, ROBOTLASER<k>), the
//     first such message type in the file is used: one frame and one /path row per line, at
//     its pose (ROBOTLASER: the laser pose). RAWLASER lines of the laser are then ignored
//     (they are the same scans without a pose).
//   - Otherwise the RAWLASER<k> lines are the frames and the ODOM lines are /path (odometry,
//     not corrected); a frame's pose is the odometry interpolated at its time, which puts the
//     laser at the robot's odometry pose (its mounting offset is not known to the log reader).
//     Frames outside the odometry's time span are skipped and counted.
// A beam becomes (r cos a, r sin a, 0) in the sensor frame; a reading ≥ the max range (the
// line's own maximum_range for RAWLASER/ROBOTLASER, and at most `max_range_m`) or 0 is a
// no-return (NaN) ray. Every frame of the laser must have the same number of beams.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/import/scan_import.h"

namespace carvemap {

struct CarmenOptions {
  int laser = 1;  // 1 front, 2 rear, 3, 4
  // A Pioneer-class robot carries its SICK LMS about 0.3 m above the floor; the import needs
  // some height, and the 2D log cannot tell it.
  double height_m = 0.3;
  // SICK LMS 2xx scanners report 8x m for "no echo"; CARMEN's old formats assume 80 m.
  double max_range_m = 80.0;
  // SICK LMS 2xx: about 1 cm statistical error plus 1 cm resolution in the cm mode these logs
  // were recorded in.
  std::array<double, 2> range_sigma = {0.02, 0.0};
  // A posed line's pose is its scan's own, so its time carries no extra error.
  double sigma_t_s = 0.0;
  // Real logs have the odd scan whose time stamp is not after the previous one (4 of the 910
  // in the Intel lab log). Such a line is an error unless this is set; then it is skipped
  // and counted.
  bool skip_backward_times = false;

  [[nodiscard]] absl::Status Validate() const;
};

// What the import did besides the frames, for the caller to report.
struct CarmenReport {
  std::string laser_message;  // the message type the frames came from: "FLASER", "RAWLASER1", ...
  std::string pose_message;   // where /path came from: the same, or "ODOM"
  uint64_t no_return_rays = 0;
  uint64_t skipped_backward = 0;       // lines skipped for a time not after the previous
  int first_skipped_line = 0;          // line number of the first of them (1-based)
  uint64_t skipped_outside_poses = 0;  // RAWLASER frames outside the ODOM time span
  uint64_t ignored_laser_lines = 0;    // lines of the laser in another message type
};

// The sensor the import declares (independent of the file's contents).
[[nodiscard]] SensorInfo CarmenSensor(const CarmenOptions& options = {});

// Parses `file` (gzip-compressed or plain); frames go to `sink` (or into the result if `sink`
// is empty) in time order. Errors name the file, the line number and what is wrong: a line
// cut short or with a wrong count of readings, a non-numeric or non-finite field, a time not
// after the previous one of its kind, no lines of the laser at all. `report`, if given, is
// filled in.
absl::StatusOr<ImportedScan> ImportCarmen(const std::string& file,
                                          const CarmenOptions& options = {},
                                          const FrameSink& sink = nullptr,
                                          CarmenReport* report = nullptr);

}  // namespace carvemap
