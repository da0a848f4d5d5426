#include "coordinator/job_params.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "geometry/octree_keys.h"
#include "services/floorplan/floorplan_pipeline.h"  // FloorPlanMethod names

namespace carvemap {

std::string JobParams::ToJson() const {
  // nlohmann's object keeps its keys sorted: the text depends on the values only.
  nlohmann::json j = {
      {"resolution_m", resolution_m},
      {"method", static_cast<int>(method)},
      {"workers_hint", workers_hint},
      {"object_resolution_m", object_resolution_m},
      {"floorplan_method", floorplan_method},
      {"trimmed_points", trimmed_points},
      {"min_object_volume_m3", min_object_volume_m3},
      {"evaluation", evaluation == CarveEvaluation::kExact ? "exact" : "fast"},
      {"north", NorthModeName(north)}};
  // Only when given, so that the text of a job without them stays as it was.
  if (!location.empty()) {
    j["location"] = location;
    j["survey_date"] = survey_date;
  }
  return j.dump();
}

JobParams JobParams::FromJson(const std::string& text) {
  JobParams p;
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object()) return p;
  p.resolution_m = j.value("resolution_m", kDefaultJobResolutionM);
  p.method = j.value("method", 1) == 2 ? CarveMethod::kVoxel : CarveMethod::kProbabilistic;
  p.workers_hint = j.value("workers_hint", 0);
  p.object_resolution_m = j.value("object_resolution_m", p.resolution_m);
  p.floorplan_method = j.value("floorplan_method", std::string("rooms"));
  p.trimmed_points = j.value("trimmed_points", false);
  p.min_object_volume_m3 = j.value("min_object_volume_m3", 0.0);
  p.evaluation = j.value("evaluation", std::string("exact")) == "fast" ? CarveEvaluation::kFast
                                                                       : CarveEvaluation::kExact;
  absl::StatusOr<NorthMode> north = ParseNorthMode(j.value("north", std::string("none")));
  p.north = north.ok() ? *north : NorthMode::kNone;
  p.location = j.value("location", std::string());
  p.survey_date = j.value("survey_date", std::string());
  return p;
}

absl::StatusOr<JobParams> ResolveJobParams(const JobParamsRequest& in) {
  JobParams p;
  const double resolution = in.resolution_m == 0 ? kDefaultJobResolutionM : in.resolution_m;
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(resolution);
  if (!grid.ok() || grid->chunk_depth < kMinJobChunkDepth ||
      grid->chunk_depth > kMaxJobChunkDepth) {
    return absl::InvalidArgumentError(absl::StrCat(
        "resolution_m ", in.resolution_m,
        ": must be one of 0.0625, 0.03125, 0.015625, 0.0078125 (2 m / 2^k, k = 5..8)"));
  }
  p.resolution_m = grid->resolution_m();
  switch (in.method) {
    case 0:
    case static_cast<int>(CarveMethod::kProbabilistic):
      p.method = CarveMethod::kProbabilistic;
      break;
    case static_cast<int>(CarveMethod::kVoxel):
      return absl::UnimplementedError("method VOXEL: not implemented by the workers yet");
    default:
      return absl::InvalidArgumentError(absl::StrCat("unknown method ", in.method));
  }
  if (in.workers_hint < 0) return absl::InvalidArgumentError("workers_hint must be >= 0");
  p.workers_hint = in.workers_hint;
  if (in.object_resolution_m == 0) {
    // Half the job's leaf size: on the simulated office, objects re-carved at 3.125 cm under
    // 6.25 cm tiles were found more often than at 1.5625 cm (65 % against 57 %,
    // docs/BENCHMARKS.md: the scan points that keep legs and rods are a few cm apart).
    p.object_resolution_m =
        OctreeGrid{std::min(grid->chunk_depth + 1, kMaxJobChunkDepth)}.resolution_m();
  } else {
    absl::StatusOr<OctreeGrid> fine = OctreeGrid::FromResolution(in.object_resolution_m);
    if (!fine.ok() || fine->chunk_depth < grid->chunk_depth ||
        fine->chunk_depth > kMaxJobChunkDepth) {
      return absl::InvalidArgumentError(absl::StrCat("object_resolution_m ", in.object_resolution_m,
                                                     ": must be 2 m / 2^k, not coarser "
                                                     "than resolution_m (",
                                                     p.resolution_m,
                                                     ") and not finer than 0.0078125"));
    }
    p.object_resolution_m = fine->resolution_m();
  }
  absl::StatusOr<FloorPlanMethod> plan = ParseFloorPlanMethod(
      in.floorplan_method.empty() ? std::string_view("rooms") : in.floorplan_method);
  if (!plan.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("floorplan_method: ", plan.status().message()));
  }
  p.floorplan_method = std::string(FloorPlanMethodName(*plan));
  p.trimmed_points = in.trimmed_points;
  if (!(in.min_object_volume_m3 >= 0) || !std::isfinite(in.min_object_volume_m3)) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_object_volume_m3 ", in.min_object_volume_m3, ": must be finite and ≥ 0"));
  }
  p.min_object_volume_m3 = in.min_object_volume_m3;
  switch (in.evaluation) {
    case 0:
    case 1:
      p.evaluation = CarveEvaluation::kFast;
      break;
    case 2:
      p.evaluation = CarveEvaluation::kExact;
      break;
    default:
      return absl::InvalidArgumentError(absl::StrCat("unknown evaluation ", in.evaluation));
  }
  absl::StatusOr<NorthMode> north = ParseNorthMode(in.north);
  if (!north.ok()) return north.status();
  p.north = *north;
  if (!in.location.empty()) {
    absl::StatusOr<NorthPlace> place = ParseNorthPlace(in.location, in.survey_date, "location");
    if (!place.ok()) return place.status();
  } else if (!in.survey_date.empty()) {
    return absl::InvalidArgumentError("survey_date: given without a location");
  }
  p.location = in.location;
  p.survey_date = in.survey_date;
  return p;
}

}  // namespace carvemap
