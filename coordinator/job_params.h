// A job's parameters (docs/RPC.md SubmitJob, jobs.proto JobParams): what a submit asks, with
// zeros and empty strings meaning "the default", resolved and checked into the parameters the
// job runs with, and those stored as JSON in the job store (JobRecord::params_json) so that a
// restarted coordinator resumes the job as it was submitted. Plain data; no RPC, no files.
#pragma once

#include <string>

#include "absl/status/statusor.h"
#include "geometry/carving_types.h"  // CarveEvaluation
#include "geometry/north_alignment.h"  // NorthMode
#include "services/merge/merge_params.h"

namespace carvemap {

inline constexpr double kDefaultJobResolutionM = 0.0625;
// The leaf sizes a job may ask for: 2 m / 2^k, k in [kMinJobChunkDepth, kMaxJobChunkDepth].
inline constexpr int kMinJobChunkDepth = 5;  // 6.25 cm
inline constexpr int kMaxJobChunkDepth = 8;  // 0.78 cm

// The values are jobs.proto's CarveMethod and what params_json stores.
enum class CarveMethod { kProbabilistic = 1, kVoxel = 2 };

// What a submit asks (jobs.proto JobParams, field by field): 0 or "" is the default.
struct JobParamsRequest {
  double resolution_m = 0;
  int method = 0;  // jobs.proto CarveMethod: 0 unspecified, 1 probabilistic, 2 voxel
  int workers_hint = 0;
  double object_resolution_m = 0;
  std::string floorplan_method;
  bool trimmed_points = false;
  double min_object_volume_m3 = 0;
  int evaluation = 0;  // jobs.proto CarveEvaluation: 0 unspecified, 1 fast, 2 exact
  std::string north;   // §2.3: "auto", "magnetic", "none"; "" = auto
  std::string location;     // §2.3 true north: "LAT,LON"; "" = magnetic north
  std::string survey_date;  // "YYYY-MM-DD"; "" = from the scan's times
};

// The parameters a job runs with, every default filled in.
struct JobParams {
  double resolution_m = kDefaultJobResolutionM;
  CarveMethod method = CarveMethod::kProbabilistic;
  int workers_hint = 0;  // a hint: the coordinator never waits for this many workers
  // §5.6.1's re-carve of the chunks that hold objects; = resolution_m: no re-carve.
  double object_resolution_m = kDefaultJobResolutionM;
  std::string floorplan_method = "rooms";               // §3.3 rooms, or §3.2 eigencrust
  bool trimmed_points = false;                          // §5.5 points.ply on request
  double min_object_volume_m3 = 0;                      // §5.6 specks; 0 = the merge's default
  CarveEvaluation evaluation = CarveEvaluation::kFast;  // eq 4.7 in the workers
  NorthMode north = NorthMode::kAuto;                   // §2.3 (north_alignment.h)
  std::string location, survey_date;                    // §2.3 true north; "" = magnetic

  // One line of JSON, its keys in a fixed order: equal parameters give equal text (a
  // resubmission with the same idempotency key is compared by it).
  [[nodiscard]] std::string ToJson() const;
  // The stored text back. Keys a job stored before they existed take the value such a job
  // ran with: no object_resolution_m → resolution_m (no re-carve), no evaluation → exact,
  // no north → none.
  // Text that is not a JSON object gives the defaults.
  static JobParams FromJson(const std::string& text);
  // What the merge gets of them, with the turn to north the job's tiles were carved with.
  [[nodiscard]] MergeParams merge_params(double world_yaw_rad) const {
    return {.resolution_m = resolution_m,
            .object_resolution_m = object_resolution_m,
            .floorplan_method = floorplan_method,
            .trimmed_points = trimmed_points,
            .min_object_volume_m3 = min_object_volume_m3,
            .world_yaw_rad = world_yaw_rad};
  }
  bool operator==(const JobParams&) const = default;
};

// The defaults filled in and every field checked, so that a bad parameter fails the submit
// rather than the merge an hour later. InvalidArgument naming the field and what it accepts;
// Unimplemented for the voxel method (§4.2), which the workers do not carve.
[[nodiscard]] absl::StatusOr<JobParams> ResolveJobParams(const JobParamsRequest& request);

}  // namespace carvemap
