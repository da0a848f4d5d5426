// §2.3: the turn about the vertical that brings the model's frame to magnetic north (ENU:
// +x east, +y north, +z up), from the magnetometer readings taken into the world frame.
//
// Eq 2.1 is a least-squares fit of R_z(θ) to the readings. Its minimizer over the readings'
// horizontal parts h_i is the direction of Σ h_i (a weighted circular mean), which a few
// readings bent by steel (§2.3's ferrous walls, lifts) pull off: so the fit here is that mean
// made robust, reweighted with Tukey's biweight on the angle residuals from a start at the
// densest heading. The sign departs from the dissertation's text: its sensor reported the
// field's reverse ("readings point south"); a magnetometer measures the field itself, whose
// horizontal part points to magnetic north, and so does our simulator (+y).
//
// Plain code: no files, no logging.
#ifndef CARVEMAP_SERVICES_GEOMETRY_NORTH_ALIGNMENT_H_
#define CARVEMAP_SERVICES_GEOMETRY_NORTH_ALIGNMENT_H_

#include <span>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "absl/status/statusor.h"

namespace carvemap {

struct NorthOptions {
  // Fewer readings kept than this, or fewer than this fraction of the usable ones: not
  // confident.
  int min_readings = 20;
  double min_kept_fraction = 0.5;
  // A robust spread (1.4826 · median absolute residual) of the kept readings' headings above
  // this: not confident (the field indoors is too disturbed to say where north is).
  double max_spread_deg = 25.0;
};

struct NorthEstimate {
  // Turn about +z (counter-clockwise from above) that brings the readings' horizontal part
  // to +y: apply it to the world frame (ScanReader::OpenOptions::world_yaw_rad). In (-π, π].
  double yaw_rad = 0;
  int readings = 0;  // given
  int usable = 0;    // with a horizontal part (a reading straight up or down says nothing)
  int kept = 0;      // inliers of the final fit
  double spread_rad = 0;          // robust spread of the kept readings' headings
  double standard_error_rad = 0;  // of yaw_rad: spread / sqrt(kept)
  bool confident = false;
  std::string why_not;  // when not confident: what was wrong, in words
};

NorthEstimate EstimateNorth(std::span<const Eigen::Vector3d> world_fields,
                            const NorthOptions& options = {});

// What a job does with the estimate (`--north`):
// - kAuto (the default): turn when the fit is confident and the turn is at least
//   min_turn_deg; otherwise keep the scan's frame, with a warning when the fit failed. Below
//   a degree the turn is within what the localizer's own heading drift makes (the simulator's
//   0.5° yaw drift alone moves the estimate ~0.5°), and turning the model off the octree's
//   axes by so little would only make its walls into staircases.
// - kMagnetic: turn by the estimate whatever its size; an error without readings or without
//   a confident fit.
// - kNone: keep the scan's frame.
enum class NorthMode { kAuto, kMagnetic, kNone };

struct NorthDecision {
  double yaw_rad = 0;  // the turn to apply (0: none)
  bool turned = false;
  std::string note;     // why not turned (kAuto), in words; empty when turned
  bool warn = false;    // the note is worth a warning (the fit failed, not just small)
};

// `has_readings`: the scan has a /magnetometer. `declination_rad`: where magnetic north lies
// east of true north at the survey's place and date (services/geomag/), to turn to true
// north instead (the turn becomes yaw − declination); 0: magnetic north. FAILED_PRECONDITION
// for kMagnetic without a confident fit, naming why.
absl::StatusOr<NorthDecision> DecideNorth(NorthMode mode, bool has_readings,
                                          const NorthEstimate& estimate,
                                          double declination_rad = 0,
                                          double min_turn_deg = 1.0);

// Where and when the survey was made, for true north: the World Magnetic Model's declination
// there (services/geomag/). `survey_date` "YYYY-MM-DD"; empty: from the scan's times, when
// they are absolute (Unix seconds).
struct NorthPlace {
  double lat_deg = 0, lon_deg = 0;
  std::string survey_date;
};

// "LAT,LON" in degrees (latitude in [-90, 90], longitude in [-180, 360)); INVALID_ARGUMENT
// naming `what` otherwise.
absl::StatusOr<NorthPlace> ParseNorthPlace(std::string_view location, std::string_view date,
                                           std::string_view what);

// "YYYY-MM-DD" as a decimal year (the day's start); INVALID_ARGUMENT otherwise.
absl::StatusOr<double> DecimalYear(const std::string& date);

// "auto", "magnetic", "none" (and "" = auto); INVALID_ARGUMENT otherwise.
absl::StatusOr<NorthMode> ParseNorthMode(std::string_view text);
const char* NorthModeName(NorthMode mode);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_GEOMETRY_NORTH_ALIGNMENT_H_
