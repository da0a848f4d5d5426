#include "services/floorplan/eigencrust/eigencrust_floorplan.h"

#include <chrono>
#include <cmath>
#include <tuple>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "services/floorplan/model/room_polygons.h"

namespace carvemap {
namespace {

using Clock = std::chrono::steady_clock;
using Eigen::Vector2d;

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

absl::Status InStep(const char* step, const absl::Status& s) {
  return absl::Status(s.code(), absl::StrCat("eigencrust ", step, ": ", s.message()));
}

double SignedArea(const Vector2d& a, const Vector2d& b, const Vector2d& c) {
  return 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
}


// Moves the plan's vertices that are samples of B onto their curves (§3.2.4: "the inlier samples
// and edges in B are replaced by edges that conform exactly to their models' locations").
// Plan vertices are the same distinct sample positions as the labelling's (both number them in
// (x, y) order); they are matched by position, so nothing rests on that. An ear (a triangle with
// two boundary edges: a sample that stuck out of the wall between its neighbours) left flat on
// one line is dropped, its third edge the wall now. Any other triangle the moves turn over or
// flatten has its moved corners put back, until none is left.
absl::StatusOr<size_t> ApplyCurves(const EigencrustLabeling& labeling, const WallCurveFit& fit,
                                   FloorPlan& plan, EigencrustFloorPlanReport* rep) {
  const FloorPlan original = plan;
  absl::flat_hash_map<std::pair<double, double>, int> eigen_vertex;
  for (size_t v = 0; v < labeling.samples; ++v) {
    eigen_vertex[{labeling.vertices[v].x(), labeling.vertices[v].y()}] = static_cast<int>(v);
  }
  const size_t nv = plan.vertices.size();
  std::vector<int> curve(nv, -1);
  std::vector<char> moved(nv, 0);
  for (size_t v = 0; v < nv; ++v) {
    const auto it = eigen_vertex.find({plan.vertices[v].x(), plan.vertices[v].y()});
    if (it == eigen_vertex.end() || fit.curve_of[it->second] < 0) continue;
    const Vector2d to = fit.fitted[it->second];
    if (to == plan.vertices[v]) continue;
    curve[v] = fit.curve_of[it->second];
    plan.vertices[v] = to;
    moved[v] = 1;
  }
  auto area = [&](const std::array<uint32_t, 3>& t) {
    return SignedArea(plan.vertices[t[0]], plan.vertices[t[1]], plan.vertices[t[2]]);
  };
  // A triangle flat on one line: its three corners lie on a line curve (one of their curves;
  // a corner sample moved to where two lines meet lies on both).
  auto on_line = [&](uint32_t v, int c) {
    const WallCurve& l = fit.curves[c];
    const Vector2d d = plan.vertices[v] - l.point;
    return std::abs(d.x() * l.direction.y() - d.y() * l.direction.x()) <= 1e-9;
  };
  auto flat_on_a_line = [&](const std::array<uint32_t, 3>& t) {
    if (std::abs(area(t)) > 1e-9) return false;
    for (uint32_t v : t) {
      const int c = curve[v];
      if (c < 0 || !moved[v] || fit.curves[c].kind != WallCurve::Kind::kLine) continue;
      if (on_line(t[0], c) && on_line(t[1], c) && on_line(t[2], c)) return true;
    }
    return false;
  };
  // Repeatedly: put back the moved corners of any triangle turned over or flattened, unless it
  // is an ear (two or three boundary edges) flat on a line, which is dropped.
  std::vector<char> dropped(plan.triangles.size(), 0);
  for (bool changed = true; changed;) {
    changed = false;
    absl::flat_hash_map<std::pair<uint32_t, uint32_t>, int> uses;
    for (size_t t = 0; t < plan.triangles.size(); ++t) {
      if (dropped[t]) continue;
      const auto& tri = plan.triangles[t];
      for (int i = 0; i < 3; ++i) {
        ++uses[{std::min(tri[i], tri[(i + 1) % 3]), std::max(tri[i], tri[(i + 1) % 3])}];
      }
    }
    std::vector<size_t> ears;
    for (size_t t = 0; t < plan.triangles.size(); ++t) {
      if (dropped[t]) continue;
      const auto& tri = plan.triangles[t];
      if (area(tri) > 1e-12) continue;
      int boundary = 0;
      for (int i = 0; i < 3; ++i) {
        boundary += uses[{std::min(tri[i], tri[(i + 1) % 3]), std::max(tri[i], tri[(i + 1) % 3])}] == 1;
      }
      if (boundary >= 2 && flat_on_a_line(tri)) {
        ears.push_back(t);
        continue;
      }
      for (uint32_t v : tri) {
        if (!moved[v]) continue;
        plan.vertices[v] = original.vertices[v];
        moved[v] = 0;
        ++rep->refused_moves;
        changed = true;
      }
    }
    if (changed) continue;  // the ears are judged again with the corners put back
    for (size_t t : ears) dropped[t] = 1;
    changed = !ears.empty();
  }
  // Drop the flat triangles; renumber; a room whose seed went gets its largest triangle.
  std::vector<int> new_index(plan.triangles.size(), -1);
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<int> triangle_room;
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    if (dropped[t]) continue;
    new_index[t] = static_cast<int>(triangles.size());
    triangles.push_back(plan.triangles[t]);
    triangle_room.push_back(plan.triangle_room[t]);
  }
  plan.triangles = std::move(triangles);
  plan.triangle_room = std::move(triangle_room);
  std::vector<double> largest(plan.rooms.size(), -1);
  std::vector<int> largest_t(plan.rooms.size(), -1);
  for (FloorPlanRoom& room : plan.rooms) room.area_m2 = 0;
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    const double a = area(plan.triangles[t]);
    const int r = plan.triangle_room[t];
    plan.rooms[r].area_m2 += a;
    if (a > largest[r]) {
      largest[r] = a;
      largest_t[r] = static_cast<int>(t);
    }
  }
  for (size_t r = 0; r < plan.rooms.size(); ++r) {
    FloorPlanRoom& room = plan.rooms[r];
    room.seed_triangle = room.seed_triangle >= 0 ? new_index[room.seed_triangle] : -1;
    if (room.seed_triangle < 0) room.seed_triangle = largest_t[r];
  }
  if (absl::Status s = ValidateFloorPlan(plan); !s.ok()) {
    // Dropping flat triangles broke the triangulation somewhere: keep the plan as labelled.
    plan = original;
    rep->refused_moves += rep->moved_vertices;
    return size_t{0};
  }
  size_t n = 0;
  for (char m : moved) n += m ? 1 : 0;
  rep->moved_vertices = n;
  rep->dropped_flat_triangles = original.triangles.size() - plan.triangles.size();
  return n;
}

}  // namespace

absl::Status EigencrustFloorPlanOptions::Validate() const {
  if (absl::Status s = labeling.Validate(); !s.ok()) return s;
  return curves.Validate();
}

absl::StatusOr<FloorPlan> EigencrustFloorPlan(const WallSampleSet& samples,
                                              const EigencrustFloorPlanOptions& options,
                                              const RoomLabelingOptions& rooms,
                                              RoomLabelingReport* room_report,
                                              EigencrustFloorPlanReport* report) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = samples.Validate(); !s.ok()) return s;
  EigencrustFloorPlanReport rep;

  // §3.2.1.
  Clock::time_point t0 = Clock::now();
  WallSampleSet smoothed;
  const WallSampleSet* input = &samples;
  if (options.labeling.smooth) {
    absl::StatusOr<WallSampleSet> s = SmoothWallSamples(samples, options.labeling);
    if (!s.ok()) return InStep("smoothing", s.status());
    smoothed = *std::move(s);
    for (size_t i = 0; i < samples.samples.size(); ++i) {
      rep.labeling.smoothed +=
          (smoothed.samples[i].position - samples.samples[i].position).norm() > 1e-6 ? 1 : 0;
    }
    input = &smoothed;
  }
  rep.seconds_smooth = SecondsSince(t0);

  // §3.2.2–§3.2.3.
  t0 = Clock::now();
  const size_t smoothed_count = rep.labeling.smoothed;
  absl::StatusOr<EigencrustLabeling> labeling =
      LabelEigencrust(*input, options.labeling, &rep.labeling);
  if (!labeling.ok()) return InStep("labelling", labeling.status());
  rep.labeling.smoothed = smoothed_count;
  rep.seconds_label = SecondsSince(t0);

  // Rooms: §3.3.2 on the Eigencrust interior (see the header).
  t0 = Clock::now();
  int hint = -1;
  const InteriorTest interior = [&](const Vector2d& a, const Vector2d& b, const Vector2d& c) {
    return labeling->InsideAt((a + b + c) / 3.0, &hint);
  };
  absl::StatusOr<FloorPlan> plan = LabelRoomsOfInterior(*input, interior, rooms, room_report);
  if (!plan.ok()) return InStep("rooms", plan.status());
  rep.seconds_rooms = SecondsSince(t0);

  // §3.2.4.
  t0 = Clock::now();
  if (options.fit_curves) {
    absl::StatusOr<WallCurveFit> fit =
        FitWallCurves(labeling->vertices, labeling->normals, labeling->boundary,
                      input->spacing_m, options.curves, &rep.curves);
    if (!fit.ok()) return InStep("curve fitting", fit.status());
    absl::StatusOr<size_t> moved = ApplyCurves(*labeling, *fit, *plan, &rep);
    if (!moved.ok()) return InStep("curve fitting", moved.status());
  }
  rep.seconds_curves = SecondsSince(t0);
  if (report != nullptr) *report = rep;
  return plan;
}

}  // namespace carvemap
