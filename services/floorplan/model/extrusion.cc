#include "services/floorplan/model/extrusion.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "geometry/union_find.h"
#include "services/floorplan/model/room_polygons.h"

namespace carvemap {
namespace {

uint64_t EdgeKey(uint32_t a, uint32_t b) { return (static_cast<uint64_t>(a) << 32) | b; }

// How far apart the columns of a vertex where the plan touches itself are moved, m: far below
// the plan's accuracy (§3.3: centimetres), far above float rounding at building coordinates
// (~1e-5 m at 100 m).
constexpr double kPinchSeparationM = 1e-3;

double Median(std::vector<double>& values) {
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  const double upper = values[mid];
  if (values.size() % 2 == 1) return upper;
  const double lower = *std::max_element(values.begin(), values.begin() + mid);
  return 0.5 * (lower + upper);
}

}  // namespace

void AssignRoomHeights(FloorPlan& plan) {
  std::vector<std::vector<uint32_t>> room_vertices(plan.rooms.size());
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    for (uint32_t v : plan.triangles[t]) room_vertices[plan.triangle_room[t]].push_back(v);
  }
  for (size_t r = 0; r < plan.rooms.size(); ++r) {
    std::vector<uint32_t>& vs = room_vertices[r];
    if (vs.empty()) continue;
    std::sort(vs.begin(), vs.end());
    vs.erase(std::unique(vs.begin(), vs.end()), vs.end());
    std::vector<double> floors, ceilings;
    floors.reserve(vs.size());
    ceilings.reserve(vs.size());
    for (uint32_t v : vs) {
      floors.push_back(plan.vertex_floor_z[v]);
      ceilings.push_back(plan.vertex_ceiling_z[v]);
    }
    plan.rooms[r].floor_z = Median(floors);
    plan.rooms[r].ceiling_z = Median(ceilings);
  }
}

absl::StatusOr<TriangleMesh> ExtrudeFloorPlan(const FloorPlan& plan) {
  if (absl::Status s = ValidateFloorPlan(plan); !s.ok()) return s;
  std::vector<char> used_room(plan.rooms.size(), 0);
  for (int r : plan.triangle_room) used_room[r] = 1;
  for (size_t r = 0; r < plan.rooms.size(); ++r) {
    const FloorPlanRoom& room = plan.rooms[r];
    if (used_room[r] && !(std::isfinite(room.floor_z) && std::isfinite(room.ceiling_z) &&
                          room.floor_z < room.ceiling_z)) {
      return absl::InvalidArgumentError(
          absl::StrCat("extrusion: room ", r, " has floor_z ", room.floor_z, " and ceiling_z ",
                       room.ceiling_z, " (need finite, floor < ceiling; run AssignRoomHeights)"));
    }
  }

  // Triangle corners (3t + k) around one 2D vertex are grouped into fans: corners of triangles
  // that share an edge at that vertex. A vertex where the plan's boundary touches itself has
  // several fans, and each gets its own column, so the solid is not pinched there.
  const size_t corners = plan.triangles.size() * 3;
  UnionFind<uint32_t> fans(corners);
  absl::flat_hash_map<uint64_t, uint32_t> directed;  // directed edge → corner of its tail
  directed.reserve(corners);
  for (uint32_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    for (uint32_t k = 0; k < 3; ++k) directed[EdgeKey(tri[k], tri[(k + 1) % 3])] = 3 * t + k;
  }
  auto next_corner = [](uint32_t c) { return c - c % 3 + (c % 3 + 1) % 3; };
  for (uint32_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    for (uint32_t k = 0; k < 3; ++k) {
      auto it = directed.find(EdgeKey(tri[(k + 1) % 3], tri[k]));
      if (it == directed.end()) continue;
      // Edge a→b here is b→a there: a's corners and b's corners are the same fans.
      fans.Union(3 * t + k, next_corner(it->second));
      fans.Union(next_corner(3 * t + k), it->second);
    }
  }
  // Per fan, the sorted distinct heights of its rooms, and their 3D vertices.
  std::vector<int> column_of(corners, -1);
  std::vector<std::vector<double>> column;
  std::vector<uint32_t> column_vertex;
  std::vector<Eigen::Vector2d> column_inward;  // Σ unit vectors to the fan's triangles' centroids
  std::vector<int> fans_at(plan.vertices.size(), 0);
  for (uint32_t c = 0; c < corners; ++c) {
    const uint32_t root = fans.Find(c);
    const auto& tri = plan.triangles[c / 3];
    if (column_of[root] < 0) {
      column_of[root] = static_cast<int>(column.size());
      column.emplace_back();
      column_vertex.push_back(tri[c % 3]);
      column_inward.push_back(Eigen::Vector2d::Zero());
      ++fans_at[tri[c % 3]];
    }
    column_of[c] = column_of[root];
    const FloorPlanRoom& room = plan.rooms[plan.triangle_room[c / 3]];
    column[column_of[c]].push_back(room.floor_z);
    column[column_of[c]].push_back(room.ceiling_z);
    const Eigen::Vector2d centroid =
        (plan.vertices[tri[0]] + plan.vertices[tri[1]] + plan.vertices[tri[2]]) / 3.0;
    column_inward[column_of[c]] += (centroid - plan.vertices[tri[c % 3]]).normalized();
  }
  TriangleMesh mesh;
  std::vector<int> first(column.size(), 0);
  for (size_t k = 0; k < column.size(); ++k) {
    std::vector<double>& c = column[k];
    std::sort(c.begin(), c.end());
    c.erase(std::unique(c.begin(), c.end()), c.end());
    first[k] = static_cast<int>(mesh.vertices.size());
    Eigen::Vector2d xy = plan.vertices[column_vertex[k]];
    // Where the boundary touches itself, the fans' columns would coincide: the solid would
    // touch itself along them (a self-intersection to CGAL, and no longer a surface once equal
    // positions are welded). Each moves kPinchSeparationM into its own fan instead.
    if (fans_at[column_vertex[k]] > 1 && column_inward[k].norm() > 0) {
      xy += kPinchSeparationM * column_inward[k].normalized();
    }
    for (double z : c) {
      mesh.vertices.emplace_back(static_cast<float>(xy.x()), static_cast<float>(xy.y()),
                                 static_cast<float>(z));
    }
  }
  // Index of the 3D vertex of corner c at a height present in its column.
  auto at = [&](uint32_t c, double z) {
    const std::vector<double>& h = column[column_of[c]];
    return first[column_of[c]] +
           static_cast<int>(std::lower_bound(h.begin(), h.end(), z) - h.begin());
  };
  // Column indices of corner c with heights in [z0, z1], bottom to top.
  auto span = [&](uint32_t c, double z0, double z1) {
    const std::vector<double>& h = column[column_of[c]];
    const int lo = static_cast<int>(std::lower_bound(h.begin(), h.end(), z0) - h.begin());
    const int hi = static_cast<int>(std::upper_bound(h.begin(), h.end(), z1) - h.begin());
    return std::pair<int, int>(first[column_of[c]] + lo, first[column_of[c]] + hi);  // [lo, hi)
  };
  // A vertical face over edge a→b (corners ca, cb) between heights z0 < z1, facing right of a→b:
  // the two columns zipped together, lower next vertex first, so every column vertex is a face
  // corner.
  auto wall = [&](uint32_t ca, uint32_t cb, double z0, double z1) {
    const auto [a0, a1] = span(ca, z0, z1);
    const auto [b0, b1] = span(cb, z0, z1);
    int i = a0, j = b0;
    while (i + 1 < a1 || j + 1 < b1) {
      const bool step_b =
          i + 1 >= a1 || (j + 1 < b1 && mesh.vertices[j + 1].z() <= mesh.vertices[i + 1].z());
      if (step_b) {
        mesh.triangles.emplace_back(i, j, j + 1);
        ++j;
      } else {
        mesh.triangles.emplace_back(i, j, i + 1);
        ++i;
      }
    }
  };

  for (uint32_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    const int r = plan.triangle_room[t];
    const FloorPlanRoom& room = plan.rooms[r];
    const uint32_t c0 = 3 * t, c1 = 3 * t + 1, c2 = 3 * t + 2;
    // Floor seen from below is clockwise in plan view; the ceiling keeps the plan's CCW order.
    mesh.triangles.emplace_back(at(c0, room.floor_z), at(c2, room.floor_z), at(c1, room.floor_z));
    mesh.triangles.emplace_back(at(c0, room.ceiling_z), at(c1, room.ceiling_z),
                                at(c2, room.ceiling_z));
    for (uint32_t k = 0; k < 3; ++k) {
      const uint32_t a = tri[k], b = tri[(k + 1) % 3];
      const uint32_t ca = 3 * t + k, cb = next_corner(ca);
      auto it = directed.find(EdgeKey(b, a));
      if (it == directed.end()) {  // §3.3.4: a wall, extruded over the room's height range
        wall(ca, cb, room.floor_z, room.ceiling_z);
        continue;
      }
      const int s = plan.triangle_room[it->second / 3];
      if (s == r) continue;
      // A step between rooms: the part of R's range that S does not cover faces S.
      const FloorPlanRoom& other = plan.rooms[s];
      if (room.floor_z < other.floor_z) {
        wall(ca, cb, room.floor_z, std::min(room.ceiling_z, other.floor_z));
      }
      if (room.ceiling_z > other.ceiling_z) {
        wall(ca, cb, std::max(room.floor_z, other.ceiling_z), room.ceiling_z);
      }
    }
  }
  return mesh;
}

absl::StatusOr<TriangleMesh> ExtrudeRoom(const FloorPlan& plan, int room) {
  if (room < 0 || room >= static_cast<int>(plan.rooms.size())) {
    return absl::OutOfRangeError(
        absl::StrCat("floor plan: no room ", room, " (", plan.rooms.size(), " rooms)"));
  }
  FloorPlan one;
  one.level = plan.level;
  one.vertices = plan.vertices;
  one.vertex_floor_z = plan.vertex_floor_z;
  one.vertex_ceiling_z = plan.vertex_ceiling_z;
  one.rooms = {plan.rooms[room]};
  one.rooms[0].seed_triangle = -1;
  for (size_t t = 0; t < plan.triangles.size() && t < plan.triangle_room.size(); ++t) {
    if (plan.triangle_room[t] != room) continue;
    if (static_cast<int>(t) == plan.rooms[room].seed_triangle) {
      one.rooms[0].seed_triangle = static_cast<int>(one.triangles.size());
    }
    one.triangles.push_back(plan.triangles[t]);
    one.triangle_room.push_back(0);
  }
  return ExtrudeFloorPlan(one);
}

}  // namespace carvemap
