#include "services/floorplan/export/building_ifc.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/string_view.h"
#include "services/floorplan/export/floorplan_dxf.h"
#include "services/floorplan/model/room_polygons.h"
#include "storage/atomic_file.h"
#include "storage/file_hash.h"

namespace carvemap {
namespace {

using Eigen::Vector2d;

// --- GlobalIds -------------------------------------------------------------------------------

// The building's key: SHA-256 of what the plans hold (levels, vertices, triangles, rooms and
// their heights), so the same plans give the same ids and other buildings other ids.
std::string BuildingKey(std::span<const std::pair<Level, FloorPlan>> plans) {
  std::string bytes;
  const auto put = [&bytes](const void* p, size_t n) {
    bytes.append(static_cast<const char*>(p), n);
  };
  const auto real = [&put](double v) {
    if (v == 0) v = 0;  // −0 and +0 alike
    put(&v, sizeof v);
  };
  for (const auto& [level, plan] : plans) {
    const int64_t index = level.index;
    put(&index, sizeof index);
    real(level.floor_z);
    for (const Vector2d& v : plan.vertices) {
      real(v.x());
      real(v.y());
    }
    for (const auto& t : plan.triangles) put(t.data(), sizeof(uint32_t) * 3);
    for (int r : plan.triangle_room) put(&r, sizeof r);
    for (const FloorPlanRoom& room : plan.rooms) {
      real(room.floor_z);
      real(room.ceiling_z);
    }
  }
  return Sha256Hex(bytes);
}

// IfcGloballyUniqueId: the first 128 bits of SHA-256(key, role) in IFC's base 64 (the
// buildingSMART compression of a GUID: its first byte in 2 characters, then 5 groups of 3
// bytes in 4 characters each).
std::string GlobalId(const std::string& key, absl::string_view role) {
  const std::string hex = Sha256Hex(absl::StrCat(key, "\n", role));
  std::array<uint32_t, 16> bytes;
  for (int i = 0; i < 16; ++i) bytes[i] = std::stoul(hex.substr(2 * i, 2), nullptr, 16);
  static constexpr char kChars[] =
      "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz_$";
  std::string out;
  const auto put = [&out](uint32_t v, int digits) {
    for (int i = digits - 1; i >= 0; --i) out.push_back(kChars[(v >> (6 * i)) & 63]);
  };
  put(bytes[0], 2);
  for (int i = 1; i < 16; i += 3) put((bytes[i] << 16) | (bytes[i + 1] << 8) | bytes[i + 2], 4);
  return out;
}

// --- STEP values ------------------------------------------------------------------------------

// A REAL: ISO 10303-21 wants a decimal point ("3." not "3"); micrometres are plenty.
std::string Real(double v) {
  std::string s = absl::StrFormat("%.6f", v);
  while (s.back() == '0') s.pop_back();
  if (s == "-0.") s = "0.";  // −0, or a negative value under a micrometre
  return s;
}

// A STRING: quotes and backslashes doubled; bytes outside printable ASCII (never in our own
// names) become '_' rather than an encoding a reader may not know.
std::string Str(absl::string_view text) {
  std::string out = "'";
  for (char c : text) {
    if (c == '\'' || c == '\\') out.push_back(c);
    out.push_back(c >= 0x20 && c < 0x7f ? c : '_');
  }
  return out + "'";
}

std::string Ref(int id) { return absl::StrCat("#", id); }

std::string Refs(const std::vector<int>& ids) {
  return absl::StrCat(
      "(", absl::StrJoin(ids, ",", [](std::string* s, int id) { absl::StrAppend(s, "#", id); }),
      ")");
}

// The DATA section, one instance a line, numbered in order.
class StepData {
 public:
  int Add(absl::string_view type, absl::string_view args) {
    absl::StrAppend(&text_, "#", ++last_, "=", type, "(", args, ");\n");
    return last_;
  }
  int Point(double x, double y) {
    return Add("IFCCARTESIANPOINT", absl::StrCat("(", Real(x), ",", Real(y), ")"));
  }
  int Point(double x, double y, double z) {
    return Add("IFCCARTESIANPOINT", absl::StrCat("(", Real(x), ",", Real(y), ",", Real(z), ")"));
  }
  int Direction(double x, double y, double z) {
    return Add("IFCDIRECTION", absl::StrCat("(", Real(x), ",", Real(y), ",", Real(z), ")"));
  }
  // A closed IfcPolyline: the first point again at the end, as IFC's closed curves require.
  int ClosedPolyline(const std::vector<Vector2d>& ring) {
    std::vector<int> points;
    for (const Vector2d& p : ring) points.push_back(Point(p.x(), p.y()));
    points.push_back(points.front());
    return Add("IFCPOLYLINE", Refs(points));
  }
  int last() const { return last_; }
  std::string& text() { return text_; }

 private:
  std::string text_;
  int last_ = 0;
};

// --- The plans' walls and doors ---------------------------------------------------------------

// The room of the triangle left of each directed triangle edge (triangles are CCW).
class EdgeRooms {
 public:
  explicit EdgeRooms(const FloorPlan& plan) {
    for (size_t i = 0; i < plan.vertices.size(); ++i) {
      index_.emplace(Key(plan.vertices[i]), static_cast<uint32_t>(i));
    }
    for (size_t t = 0; t < plan.triangles.size(); ++t) {
      for (int e = 0; e < 3; ++e) {
        left_[{plan.triangles[t][e], plan.triangles[t][(e + 1) % 3]}] = plan.triangle_room[t];
      }
    }
  }
  // The room left of a → b, or −1. The outline's and the borders' points are the plan's
  // vertices, copied, so they are found exactly.
  int LeftOf(const Vector2d& a, const Vector2d& b) const {
    const auto ia = index_.find(Key(a)), ib = index_.find(Key(b));
    if (ia == index_.end() || ib == index_.end()) return -1;
    const auto it = left_.find({ia->second, ib->second});
    return it == left_.end() ? -1 : it->second;
  }

 private:
  static std::pair<double, double> Key(const Vector2d& p) { return {p.x(), p.y()}; }
  std::map<std::pair<double, double>, uint32_t> index_;
  std::map<std::pair<uint32_t, uint32_t>, int> left_;
};

struct WallRun {
  Vector2d a, b;  // interior on the left of a → b
  int room = -1;
};

// A wall loop (interior on the left, first point repeated) cut into straight runs along one
// room each: consecutive edges join while every point stays within kRunToleranceM of the line
// from the run's start to its end. After §3.3.3's simplification a loop's vertices are corners
// or within the samples' noise of a straight wall, so a wall becomes one IfcWall, not one per
// triangle edge.
constexpr double kRunToleranceM = 0.02;

std::vector<WallRun> WallRuns(const std::vector<Vector2d>& loop, const EdgeRooms& rooms) {
  std::vector<Vector2d> p(loop.begin(), loop.end());
  if (p.size() > 1 && p.front() == p.back()) p.pop_back();
  const size_t n = p.size();
  std::vector<WallRun> runs;
  if (n < 2) return runs;
  std::vector<int> room(n);
  for (size_t i = 0; i < n; ++i) room[i] = rooms.LeftOf(p[i], p[(i + 1) % n]);
  const auto straight = [&](size_t from, size_t count) {  // edges from..from+count−1
    const Vector2d a = p[from % n], b = p[(from + count) % n];
    const Vector2d d = b - a;
    const double len = d.norm();
    if (!(len > 0)) return false;
    for (size_t k = 1; k < count; ++k) {
      const Vector2d q = p[(from + k) % n] - a;
      if (std::abs(d.x() * q.y() - d.y() * q.x()) / len > kRunToleranceM) return false;
      if (q.dot(d) <= 0 || q.dot(d) >= len * len) return false;  // doubles back
    }
    return true;
  };
  // Start at an edge that cannot join the one before it, so no run is cut at the loop's start.
  size_t start = 0;
  for (size_t i = 0; i < n; ++i) {
    const size_t before = (i + n - 1) % n;
    if (room[i] != room[before] || !straight(before, 2)) {
      start = i;
      break;
    }
  }
  for (size_t done = 0; done < n;) {
    const size_t from = start + done;
    size_t count = 1;
    while (done + count < n && room[(from + count) % n] == room[from % n] &&
           straight(from, count + 1)) {
      ++count;
    }
    if ((p[(from + count) % n] - p[from % n]).norm() > 0) {
      runs.push_back({p[from % n], p[(from + count) % n], room[from % n]});
    }
    done += count;
  }
  return runs;
}

struct DoorChain {
  std::vector<Vector2d> points;
  int room_a = -1, room_b = -1;  // left and right of its first segment
  double length_m = 0;
};

struct LevelGeometry {
  FloorPlanOutline outline;
  std::vector<WallRun> walls;
  std::vector<DoorChain> doors;
};

absl::StatusOr<LevelGeometry> Geometry(const Level& level, const FloorPlan& plan) {
  const std::string where = absl::StrCat("level ", level.index);
  if (!std::isfinite(level.floor_z)) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": floor_z is not finite"));
  }
  for (const Vector2d& v : plan.vertices) {
    if (!v.allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": a vertex is not finite"));
    }
  }
  for (size_t r = 0; r < plan.rooms.size(); ++r) {
    if (!std::isfinite(plan.rooms[r].floor_z) || !std::isfinite(plan.rooms[r].ceiling_z)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, " room ", r, ": floor_z or ceiling_z is not finite"));
    }
  }
  absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
  if (!outline.ok()) {
    return absl::Status(outline.status().code(),
                        absl::StrCat(where, ": ", outline.status().message()));
  }
  LevelGeometry g;
  g.outline = *std::move(outline);
  const EdgeRooms rooms(plan);
  for (const auto& loop : g.outline.walls) {
    for (WallRun& run : WallRuns(loop, rooms)) g.walls.push_back(run);
  }
  for (auto& chain : RoomBorders(plan)) {
    if (chain.size() < 2) continue;
    DoorChain door;
    door.room_a = rooms.LeftOf(chain[0], chain[1]);
    door.room_b = rooms.LeftOf(chain[1], chain[0]);
    for (size_t i = 1; i < chain.size(); ++i) door.length_m += (chain[i] - chain[i - 1]).norm();
    door.points = std::move(chain);
    g.doors.push_back(std::move(door));
  }
  return g;
}

// A room's floor and ceiling, or the level's for an edge of no known room.
std::pair<double, double> Heights(const Level& level, const FloorPlan& plan, int room) {
  if (room >= 0 && room < static_cast<int>(plan.rooms.size())) {
    return {plan.rooms[room].floor_z, plan.rooms[room].ceiling_z};
  }
  return {level.floor_z, level.ceiling_z};
}

}  // namespace

absl::StatusOr<BuildingIfcCounts> WriteBuildingIfc(
    const std::string& path, std::span<const std::pair<Level, FloorPlan>> plans,
    const BuildingIfcOptions& options) {
  if (!(options.wall_thickness_m > 0) || !(options.door_height_m > 0) ||
      !std::isfinite(options.wall_thickness_m) || !std::isfinite(options.door_height_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": wall_thickness_m and door_height_m must be positive"));
  }
  if (!(options.min_door_width_m >= 0) || !(options.max_door_width_m >= options.min_door_width_m) ||
      !std::isfinite(options.max_door_width_m)) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": door widths must be 0 ≤ min_door_width_m ≤ max_door_width_m"));
  }
  std::vector<LevelGeometry> geometry;
  for (const auto& [level, plan] : plans) {
    absl::StatusOr<LevelGeometry> g = Geometry(level, plan);
    if (!g.ok()) return g.status();
    geometry.push_back(*std::move(g));
  }
  const std::string key = BuildingKey(plans);
  const auto guid = [&key](absl::string_view role) { return Str(GlobalId(key, role)); };
  const double t = options.wall_thickness_m;

  StepData d;
  BuildingIfcCounts counts;
  // Shared geometry: the origin, the axes, the contexts and the units.
  const int origin = d.Point(0, 0, 0);
  const int z_axis = d.Direction(0, 0, 1);
  const int at_origin = d.Add("IFCAXIS2PLACEMENT3D", absl::StrCat(Ref(origin), ",$,$"));
  const int context = d.Add("IFCGEOMETRICREPRESENTATIONCONTEXT",
                            absl::StrCat("$,'Model',3,1.E-05,", Ref(at_origin), ",$"));
  // The subcontext's CoordinateSpaceDimension, Precision, WorldCoordinateSystem and TrueNorth
  // are derived from its parent: '*'.
  const int body =
      d.Add("IFCGEOMETRICREPRESENTATIONSUBCONTEXT",
            absl::StrCat("'Body','Model',*,*,*,*,", Ref(context), ",$,.MODEL_VIEW.,$"));
  std::vector<int> units;
  for (const auto& [type, name] :
       std::initializer_list<std::pair<const char*, const char*>>{{"LENGTHUNIT", "METRE"},
                                                                  {"AREAUNIT", "SQUARE_METRE"},
                                                                  {"VOLUMEUNIT", "CUBIC_METRE"},
                                                                  {"PLANEANGLEUNIT", "RADIAN"}}) {
    units.push_back(d.Add("IFCSIUNIT", absl::StrCat("*,.", type, ".,$,.", name, ".")));
  }
  const int unit_assignment = d.Add("IFCUNITASSIGNMENT", Refs(units));

  // The spatial hierarchy.
  const int project = d.Add("IFCPROJECT", absl::StrCat(guid("project"), ",$,'building',$,$,$,$,(",
                                                       Ref(context), "),", Ref(unit_assignment)));
  const int site_placement = d.Add("IFCLOCALPLACEMENT", absl::StrCat("$,", Ref(at_origin)));
  const int site = d.Add("IFCSITE", absl::StrCat(guid("site"), ",$,'site',$,$,",
                                                 Ref(site_placement), ",$,$,.ELEMENT.,$,$,$,$,$"));
  const int building_placement =
      d.Add("IFCLOCALPLACEMENT", absl::StrCat(Ref(site_placement), ",", Ref(at_origin)));
  const int building =
      d.Add("IFCBUILDING", absl::StrCat(guid("building"), ",$,'building',$,$,",
                                        Ref(building_placement), ",$,$,.ELEMENT.,$,$,$"));
  d.Add("IFCRELAGGREGATES",
        absl::StrCat(guid("project aggregates"), ",$,$,$,", Ref(project), ",", Refs({site})));
  d.Add("IFCRELAGGREGATES",
        absl::StrCat(guid("site aggregates"), ",$,$,$,", Ref(site), ",", Refs({building})));

  // A solid of `profile` extruded up by `depth` from its placement.
  const auto body_shape = [&](const std::vector<int>& solids) {
    const int rep = d.Add("IFCSHAPEREPRESENTATION",
                          absl::StrCat(Ref(body), ",'Body','SweptSolid',", Refs(solids)));
    return d.Add("IFCPRODUCTDEFINITIONSHAPE", absl::StrCat("$,$,", Refs({rep})));
  };
  const auto extrude = [&](int profile, double depth) {
    return d.Add("IFCEXTRUDEDAREASOLID", absl::StrCat(Ref(profile), ",", Ref(at_origin), ",",
                                                      Ref(z_axis), ",", Real(depth)));
  };
  const auto closed_profile = [&](const std::vector<Vector2d>& ring) {
    return d.Add("IFCARBITRARYCLOSEDPROFILEDEF",
                 absl::StrCat(".AREA.,$,", Ref(d.ClosedPolyline(ring))));
  };

  std::vector<int> storeys;
  for (size_t k = 0; k < plans.size(); ++k) {
    const Level& level = plans[k].first;
    const FloorPlan& plan = plans[k].second;
    const LevelGeometry& g = geometry[k];
    const std::string name = absl::StrCat("level ", level.index);
    const int storey_placement =
        d.Add("IFCLOCALPLACEMENT",
              absl::StrCat(Ref(building_placement), ",",
                           Ref(d.Add("IFCAXIS2PLACEMENT3D",
                                     absl::StrCat(Ref(d.Point(0, 0, level.floor_z)), ",$,$")))));
    const int storey =
        d.Add("IFCBUILDINGSTOREY",
              absl::StrCat(guid(name), ",$,", Str(name), ",$,$,", Ref(storey_placement),
                           ",$,$,.ELEMENT.,", Real(level.floor_z)));
    storeys.push_back(storey);
    // A product placed in the storey at (x, y, z − the storey's floor), its x axis along `dir`.
    const auto placement = [&](const Vector2d& at, double z, std::optional<Vector2d> dir) {
      const int point = d.Point(at.x(), at.y(), z - level.floor_z);
      const std::string axes =
          dir ? absl::StrCat(Ref(z_axis), ",", Ref(d.Direction(dir->x(), dir->y(), 0)))
              : std::string("$,$");
      return d.Add(
          "IFCLOCALPLACEMENT",
          absl::StrCat(Ref(storey_placement), ",",
                       Ref(d.Add("IFCAXIS2PLACEMENT3D", absl::StrCat(Ref(point), ",", axes)))));
    };

    // Spaces: each room's pieces (TraceFloorPlan) extruded from its floor to its ceiling.
    std::vector<int> spaces;
    std::vector<int> space_of_room(plan.rooms.size(), 0);
    for (size_t r = 0; r < plan.rooms.size(); ++r) {
      std::vector<const RoomPolygon*> pieces;
      double area = 0;
      for (const RoomPolygon& piece : g.outline.rooms) {
        if (piece.room == static_cast<int>(r) && piece.outer.size() >= 3) {
          pieces.push_back(&piece);
          area += piece.area_m2;
        }
      }
      if (pieces.empty()) continue;  // a room without triangles has no space
      const std::string room_name = absl::StrCat(name, " room ", r);
      const auto [floor_z, ceiling_z] = Heights(level, plan, static_cast<int>(r));
      const double height = ceiling_z - floor_z;
      int shape = 0;
      if (height > 0) {
        std::vector<int> solids;
        for (const RoomPolygon* piece : pieces) {
          std::vector<int> holes;
          for (const auto& hole : piece->holes) {
            if (hole.size() >= 3) holes.push_back(d.ClosedPolyline(hole));
          }
          const int profile =
              holes.empty() ? closed_profile(piece->outer)
                            : d.Add("IFCARBITRARYPROFILEDEFWITHVOIDS",
                                    absl::StrCat(".AREA.,$,", Ref(d.ClosedPolyline(piece->outer)),
                                                 ",", Refs(holes)));
          solids.push_back(extrude(profile, height));
        }
        shape = body_shape(solids);
      }
      const int space = d.Add(
          "IFCSPACE", absl::StrCat(guid(room_name), ",$,", Str(room_name), ",$,$,",
                                   Ref(placement(Vector2d::Zero(), floor_z, std::nullopt)), ",",
                                   shape ? Ref(shape) : "$", ",$,.ELEMENT.,.INTERNAL.,$"));
      spaces.push_back(space);
      space_of_room[r] = space;
      const int quantities = d.Add(
          "IFCELEMENTQUANTITY",
          absl::StrCat(
              guid(room_name + " quantities"), ",$,'Qto_SpaceBaseQuantities',$,$,",
              Refs({d.Add("IFCQUANTITYAREA", absl::StrCat("'NetFloorArea',$,$,", Real(area), ",$")),
                    d.Add("IFCQUANTITYLENGTH",
                          absl::StrCat("'Height',$,$,", Real(std::max(height, 0.0)), ",$")),
                    d.Add("IFCQUANTITYVOLUME",
                          absl::StrCat("'NetVolume',$,$,", Real(area * std::max(height, 0.0)),
                                       ",$"))})));
      d.Add("IFCRELDEFINESBYPROPERTIES",
            absl::StrCat(guid(room_name + " defines quantities"), ",$,$,$,", Refs({space}), ",",
                         Ref(quantities)));
      ++counts.spaces;
    }
    if (!spaces.empty()) {
      d.Add("IFCRELAGGREGATES",
            absl::StrCat(guid(name + " aggregates"), ",$,$,$,", Ref(storey), ",", Refs(spaces)));
    }

    // Walls: a slab behind each straight run's face, on the exterior side (the right of a
    // loop, whose interior is on its left), from the room's floor to its ceiling.
    std::vector<int> elements;
    const auto boundary = [&](const std::string& role, int room, int element,
                              bool physical = true) {
      if (room < 0 || room >= static_cast<int>(space_of_room.size()) || !space_of_room[room]) {
        return;
      }
      d.Add("IFCRELSPACEBOUNDARY",
            absl::StrCat(guid(role), ",$,$,$,", Ref(space_of_room[room]), ",", Ref(element), ",$,",
                         physical ? ".PHYSICAL." : ".VIRTUAL.", ",.NOTDEFINED."));
    };
    for (size_t w = 0; w < g.walls.size(); ++w) {
      const WallRun& run = g.walls[w];
      const std::string wall_name = absl::StrCat(name, " wall ", w);
      const auto [floor_z, ceiling_z] = Heights(level, plan, run.room);
      const double length = (run.b - run.a).norm();
      int shape = 0;
      if (ceiling_z > floor_z) {
        // In the wall's frame (x along the run, y to the interior) the slab is [0, L] × [−t, 0].
        const int position =
            d.Add("IFCAXIS2PLACEMENT2D", absl::StrCat(Ref(d.Point(length / 2, -t / 2)), ",$"));
        const int profile =
            d.Add("IFCRECTANGLEPROFILEDEF",
                  absl::StrCat(".AREA.,$,", Ref(position), ",", Real(length), ",", Real(t)));
        shape = body_shape({extrude(profile, ceiling_z - floor_z)});
      }
      const int wall =
          d.Add("IFCWALL", absl::StrCat(guid(wall_name), ",$,", Str(wall_name), ",$,$,",
                                        Ref(placement(run.a, floor_z, (run.b - run.a) / length)),
                                        ",", shape ? Ref(shape) : "$", ",$,.NOTDEFINED."));
      elements.push_back(wall);
      boundary(wall_name + " bounds", run.room, wall);
      ++counts.walls;
    }

    // Doors. §3.3 cuts the interior into rooms where it narrows; the plans have no wall across
    // such a doorway (the interior runs on through it) and see nothing above it, so an opening
    // in a wall over the doorway would stand in a wall we never observed. The door is a
    // standalone IfcDoor (IFC allows a door that fills no opening), contained in the storey:
    // as wide as the chain of borders is long, min(door_height_m, the lower room's height)
    // high, a slab across the doorway along the chain. A chain of another width is no door.
    for (size_t i = 0; i < g.doors.size(); ++i) {
      const DoorChain& door = g.doors[i];
      if (door.length_m < options.min_door_width_m || door.length_m > options.max_door_width_m) {
        // Not a door's width: the two spaces' virtual boundary, without a body.
        const std::string opening = absl::StrCat(name, " opening ", i);
        const int ifc_opening = d.Add(
            "IFCVIRTUALELEMENT",
            absl::StrCat(guid(opening), ",$,", Str(opening), ",$,$,",
                         Ref(placement(door.points.front(), level.floor_z, std::nullopt)), ",$,$"));
        elements.push_back(ifc_opening);
        boundary(opening + " bounds a", door.room_a, ifc_opening, false);
        if (door.room_b != door.room_a) {
          boundary(opening + " bounds b", door.room_b, ifc_opening, false);
        }
        ++counts.openings;
        continue;
      }
      const std::string door_name = absl::StrCat(name, " door ", i);
      const auto [floor_a, ceiling_a] = Heights(level, plan, door.room_a);
      const auto [floor_b, ceiling_b] = Heights(level, plan, door.room_b);
      const double floor_z = std::max(floor_a, floor_b);
      const double height =
          std::min(options.door_height_m, std::min(ceiling_a, ceiling_b) - floor_z);
      const Vector2d at = door.points.front();
      std::vector<int> solids;
      if (height > 0) {
        for (size_t s = 1; s < door.points.size(); ++s) {
          const Vector2d a = door.points[s - 1] - at, b = door.points[s] - at;
          const double len = (b - a).norm();
          if (!(len > 0)) continue;
          const Vector2d n = Vector2d(-(b - a).y(), (b - a).x()) * (t / 2 / len);
          solids.push_back(extrude(closed_profile({a - n, b - n, b + n, a + n}), height));
        }
      }
      const int shape = solids.empty() ? 0 : body_shape(solids);
      const int ifc_door = d.Add(
          "IFCDOOR",
          absl::StrCat(guid(door_name), ",$,", Str(door_name), ",$,$,",
                       Ref(placement(at, floor_z, std::nullopt)), ",", shape ? Ref(shape) : "$",
                       ",$,", height > 0 ? Real(height) : "$", ",",
                       door.length_m > 0 ? Real(door.length_m) : "$", ",.DOOR.,.NOTDEFINED.,$"));
      elements.push_back(ifc_door);
      boundary(door_name + " bounds a", door.room_a, ifc_door);
      if (door.room_b != door.room_a) boundary(door_name + " bounds b", door.room_b, ifc_door);
      ++counts.doors;
    }
    if (!elements.empty()) {
      d.Add("IFCRELCONTAINEDINSPATIALSTRUCTURE",
            absl::StrCat(guid(name + " contains"), ",$,$,$,", Refs(elements), ",", Ref(storey)));
    }
  }
  if (!storeys.empty()) {
    d.Add("IFCRELAGGREGATES",
          absl::StrCat(guid("building aggregates"), ",$,$,$,", Ref(building), ",", Refs(storeys)));
  }
  counts.storeys = storeys.size();
  counts.entities = static_cast<size_t>(d.last());

  // The header. No MVD is claimed (none was checked); the time stamp is fixed so that the same
  // plans give the same bytes (a merge run again gives byte-identical outputs).
  const std::string file_name = std::filesystem::path(path).filename().string();
  std::string text = absl::StrCat(
      "ISO-10303-21;\nHEADER;\n"
      "FILE_DESCRIPTION(('ViewDefinition [NotAssigned]'),'2;1');\n"
      "FILE_NAME(",
      Str(file_name),
      ",'1970-01-01T00:00:00',(''),(''),'carvemap','carvemap','');\n"
      "FILE_SCHEMA(('IFC4'));\nENDSEC;\nDATA;\n");
  text += d.text();
  text += "ENDSEC;\nEND-ISO-10303-21;\n";
  if (absl::Status s = WriteFileAtomically(path, [&text](std::ostream& out) { out << text; });
      !s.ok()) {
    return s;
  }
  return counts;
}

}  // namespace carvemap
