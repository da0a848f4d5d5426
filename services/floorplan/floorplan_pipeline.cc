#include "services/floorplan/floorplan_pipeline.h"

#include <chrono>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "services/floorplan/model/extrusion.h"

namespace carvemap {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

absl::Status InStage(const char* stage, const absl::Status& s) {
  return absl::Status(s.code(), absl::StrCat("floor plan ", stage, ": ", s.message()));
}

}  // namespace

std::string_view FloorPlanMethodName(FloorPlanMethod method) {
  return method == FloorPlanMethod::kEigencrust ? "eigencrust" : "rooms";
}

absl::StatusOr<FloorPlanMethod> ParseFloorPlanMethod(std::string_view name) {
  if (name == "rooms") return FloorPlanMethod::kRooms;
  if (name == "eigencrust") return FloorPlanMethod::kEigencrust;
  return absl::InvalidArgumentError(absl::StrCat(
      "floor plan: unknown method '", std::string(name), "' (rooms: §3.3 room partitioning; eigencrust: §3.2)"));
}

absl::Status FloorPlanOptions::Validate() const {
  if (absl::Status s = rooms.Validate(); !s.ok()) return s;
  if (method == FloorPlanMethod::kEigencrust) {
    if (absl::Status s = eigencrust.Validate(); !s.ok()) return s;
  }
  if (!std::isfinite(simplify_error_m) || simplify_error_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "floor plan: simplify_error_m must be finite and ≥ 0, got ", simplify_error_m));
  }
  return absl::OkStatus();
}

absl::StatusOr<LevelFloorPlan> BuildLevelFloorPlan(const WallSampleSet& samples, int level,
                                                   const FloorPlanOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  LevelFloorPlan out;
  out.wall_samples = samples.samples.size();

  out.method = options.method;
  Clock::time_point t0 = Clock::now();
  absl::StatusOr<FloorPlan> plan =
      options.method == FloorPlanMethod::kEigencrust
          ? EigencrustFloorPlan(samples, options.eigencrust, options.rooms, &out.labeling,
                                &out.eigencrust)
          : LabelRooms(samples, options.rooms, &out.labeling);
  if (!plan.ok()) return InStage("rooms", plan.status());
  out.plan = *std::move(plan);
  out.plan.level = level;
  // §3.3.4: heights come from the samples at the triangulation's vertices, so they are taken
  // before simplification moves or removes boundary vertices.
  AssignRoomHeights(out.plan);
  out.seconds_rooms = SecondsSince(t0);

  t0 = Clock::now();
  if (options.simplify) {
    FloorPlanSimplifyOptions so;
    // With Eigencrust the curve fitting has straightened the walls (§3.2.4): only the vertices
    // left collinear on a line go (error ~0), not §3.3.3's r = d_s.
    const double default_error =
        options.method == FloorPlanMethod::kEigencrust ? 1e-6 : samples.spacing_m;
    so.max_error_m = options.simplify_error_m > 0 ? options.simplify_error_m : default_error;
    if (absl::Status s = SimplifyFloorPlan(out.plan, so, &out.simplify); !s.ok()) {
      return InStage("simplification", s);
    }
  }
  out.seconds_simplify = SecondsSince(t0);

  t0 = Clock::now();
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(out.plan);
  if (!outline.ok()) return InStage("outline", outline.status());
  out.outline = *std::move(outline);
  out.seconds_outline = SecondsSince(t0);

  t0 = Clock::now();
  absl::StatusOr<TriangleMesh> mesh = ExtrudeFloorPlan(out.plan);
  if (!mesh.ok()) return InStage("extrusion", mesh.status());
  out.extruded = *std::move(mesh);
  out.seconds_extrude = SecondsSince(t0);
  return out;
}

nlohmann::json RoomsToJson(const LevelFloorPlan& result) {
  const FloorPlan& plan = result.plan;
  std::vector<Eigen::Vector2d> centroid(plan.rooms.size(), Eigen::Vector2d::Zero());
  std::vector<double> area(plan.rooms.size(), 0.0);
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    const Eigen::Vector2d a = plan.vertices[tri[0]], b = plan.vertices[tri[1]],
                          c = plan.vertices[tri[2]];
    const double w = 0.5 * std::abs((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
    const int r = plan.triangle_room[t];
    centroid[r] += w * (a + b + c) / 3.0;
    area[r] += w;
  }
  nlohmann::json rooms = nlohmann::json::array();
  for (size_t r = 0; r < plan.rooms.size(); ++r) {
    const FloorPlanRoom& room = plan.rooms[r];
    const Eigen::Vector2d c = area[r] > 0 ? Eigen::Vector2d(centroid[r] / area[r])
                                          : Eigen::Vector2d::Zero();
    rooms.push_back({{"level", plan.level},
                     {"room", r},
                     {"area_m2", area[r]},
                     {"floor_z", room.floor_z},
                     {"ceiling_z", room.ceiling_z},
                     {"centroid", {c.x(), c.y()}}});
  }
  return rooms;
}

}  // namespace carvemap
