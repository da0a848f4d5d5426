// The backpack operator's walk through a building (docs/DESIGN.md §4): a route through every
// entered room and back to the start (a loop closure, as in a real survey), then a
// time-parametrized TRUE system path with a human gait. Plain functions: no files, no logging.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/pose.h"
#include "services/building/building.h"

namespace carvemap {

struct WalkOptions {
  double speed_mps = 1.0;            // nominal walking speed
  double speed_variation = 0.1;      // relative, slow sinusoidal variation of the speed
  double accel_mps2 = 1.0;           // speeding up / slowing down at corners and stops
  double max_yaw_rate_dps = 80.0;    // heading follows the walking direction, at most this fast
  double system_height_m = 1.7;      // system origin above the floor
  double step_frequency_hz = 2.0;    // gait: one vertical bob per step (at nominal speed)
  double bob_amplitude_m = 0.02;     // ± vertical bob
  double sway_roll_deg = 1.5;        // ± roll, once per stride (two steps)
  double sway_pitch_deg = 1.0;       // ± pitch, once per step
  double room_loop_radius_m = 1.2;   // largest loop walked at each visit point (shrunk to fit)
  double sample_rate_hz = 200.0;     // of the output path
  uint64_t seed = 1;                 // gait phase and speed-variation phase
  // The tour walked this many times in a row (it ends where it starts): a longer survey of
  // the same building, each lap with its own noise and the drift going on.
  int laps = 1;
  [[nodiscard]] absl::Status Validate() const;
};

// A point of the route: floor-contact position (z = floor height) and its level.
struct RoutePoint {
  Eigen::Vector3d floor_point;
  int level = 0;
};

struct WalkRoute {
  std::vector<RoutePoint> points;  // polyline, before smoothing
  std::vector<int> rooms_visited;  // room indices (into Building::rooms), in visit order
};

// Plans the route: from the visit point of rooms[0] through every entered room (greedy nearest
// by geodesic distance, level by level, stairs between levels), a short loop at each visit
// point, and back to the start. Errors (InvalidArgument / NotFound) name the room or level
// that cannot be reached.
absl::StatusOr<WalkRoute> PlanRoute(const Building& building, const WalkOptions& options);

// Time-parametrizes a route into the true system path: x forward along the walking direction,
// y left, z up; sampled at options.sample_rate_hz from t = 0.
absl::StatusOr<std::vector<TimedPose>> TimeParametrize(const WalkRoute& route,
                                                       const WalkOptions& options);

// Both of the above, the route repeated options.laps times.
struct Walk {
  WalkRoute route;
  std::vector<TimedPose> path;  // true system poses
  double length_m = 0;          // horizontal length of the true path
};
absl::StatusOr<Walk> PlanWalk(const Building& building, const WalkOptions& options);

// Geodesic helpers on a NavGrid (exposed for tests). Cells are (ix, iy).
// A*, 8-connected, no corner cutting past blocked cells; empty if unreachable.
std::vector<Eigen::Vector2i> GridAStar(const NavGrid& grid, const Eigen::Vector2i& start,
                                       const Eigen::Vector2i& goal);
// Geodesic distance (m) from `start` to every cell; +inf where unreachable.
std::vector<double> GridDistances(const NavGrid& grid, const Eigen::Vector2i& start);
// True if the straight segment between the two world points crosses only free cells.
bool LineOfSight(const NavGrid& grid, const Eigen::Vector2d& a, const Eigen::Vector2d& b);

}  // namespace carvemap
