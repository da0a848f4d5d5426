#include "services/floorplan/model/room_polygons.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <utility>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

uint64_t EdgeKey(uint32_t a, uint32_t b) { return (static_cast<uint64_t>(a) << 32) | b; }

// A directed boundary edge a→b with its interior on the left, owned by `triangle`.
struct DirectedEdge {
  uint32_t a = 0;
  uint32_t b = 0;
  int triangle = -1;
};

// Splits the directed edges (in-degree = out-degree at every vertex: they are unions of
// boundaries) into closed simple rings, each a list of edge indices. Deterministic: walks start
// at the lowest unused edge.
std::vector<std::vector<int>> TraceRings(const std::vector<DirectedEdge>& edges,
                                         const std::vector<Eigen::Vector2d>& xy) {
  absl::flat_hash_map<uint32_t, std::vector<int>> out;
  out.reserve(edges.size());
  for (int e = 0; e < static_cast<int>(edges.size()); ++e) out[edges[e].a].push_back(e);
  std::vector<char> used(edges.size(), 0);
  std::vector<std::vector<int>> rings;
  for (int start = 0; start < static_cast<int>(edges.size()); ++start) {
    if (used[start]) continue;
    std::vector<int> walk;
    int cur = start;
    while (true) {
      used[cur] = 1;
      walk.push_back(cur);
      const uint32_t v = edges[cur].b;
      if (v == edges[start].a) break;
      const std::vector<int>& candidates = out[v];
      // Tightest clockwise turn from the way back (v→a): keeps the interior wedge on the left
      // to this ring, so regions touching at v come apart.
      const Eigen::Vector2d back = xy[edges[cur].a] - xy[v];
      const double back_angle = std::atan2(back.y(), back.x());
      int best = -1;
      double best_turn = 0;
      for (int c : candidates) {
        if (used[c]) continue;
        const Eigen::Vector2d d = xy[edges[c].b] - xy[v];
        double turn = back_angle - std::atan2(d.y(), d.x());
        while (turn <= 0) turn += 2 * std::numbers::pi;
        while (turn > 2 * std::numbers::pi) turn -= 2 * std::numbers::pi;
        if (best < 0 || turn < best_turn) {
          best = c;
          best_turn = turn;
        }
      }
      if (best < 0) break;  // unreachable for balanced input; ends the ring defensively
      cur = best;
    }
    // Cut at any vertex visited twice: each closed sub-walk becomes its own ring.
    std::vector<int> stack;
    absl::flat_hash_map<uint32_t, int> position;  // tail vertex → index in stack
    for (int e : walk) {
      const uint32_t v = edges[e].a;
      auto it = position.find(v);
      if (it != position.end()) {
        const int from = it->second;
        std::vector<int> sub(stack.begin() + from, stack.end());
        for (int s : sub) position.erase(edges[s].a);
        stack.resize(from);
        rings.push_back(std::move(sub));
      }
      position[v] = static_cast<int>(stack.size());
      stack.push_back(e);
    }
    if (!stack.empty()) rings.push_back(std::move(stack));
  }
  return rings;
}

std::vector<Eigen::Vector2d> RingPoints(const std::vector<int>& ring,
                                        const std::vector<DirectedEdge>& edges,
                                        const std::vector<Eigen::Vector2d>& xy) {
  std::vector<Eigen::Vector2d> points;
  points.reserve(ring.size());
  for (int e : ring) points.push_back(xy[edges[e].a]);
  return points;
}

bool Inside(const std::vector<Eigen::Vector2d>& ring, const Eigen::Vector2d& p) {
  bool inside = false;
  for (size_t i = 0, j = ring.size() - 1; i < ring.size(); j = i++) {
    const Eigen::Vector2d& a = ring[i];
    const Eigen::Vector2d& b = ring[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) &&
        p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x()) {
      inside = !inside;
    }
  }
  return inside;
}

}  // namespace

double RingSignedArea(const std::vector<Eigen::Vector2d>& ring) {
  double twice = 0;
  for (size_t i = 0, j = ring.size() - 1; i < ring.size(); j = i++) {
    twice += ring[j].x() * ring[i].y() - ring[i].x() * ring[j].y();
  }
  return 0.5 * twice;
}

absl::Status ValidateFloorPlan(const FloorPlan& plan) {
  const size_t n = plan.vertices.size();
  if (plan.vertex_floor_z.size() != n || plan.vertex_ceiling_z.size() != n) {
    return absl::InvalidArgumentError(
        absl::StrCat("floor plan: ", n, " vertices but ", plan.vertex_floor_z.size(), " floor and ",
                     plan.vertex_ceiling_z.size(), " ceiling heights"));
  }
  if (plan.triangle_room.size() != plan.triangles.size()) {
    return absl::InvalidArgumentError(absl::StrCat("floor plan: ", plan.triangles.size(),
                                                   " triangles but ", plan.triangle_room.size(),
                                                   " room labels"));
  }
  absl::flat_hash_map<uint64_t, int> directed;
  directed.reserve(plan.triangles.size() * 3);
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    for (int k = 0; k < 3; ++k) {
      if (tri[k] >= n) {
        return absl::InvalidArgumentError(absl::StrCat("floor plan: triangle ", t, " vertex ",
                                                       tri[k], " out of range (", n, ")"));
      }
    }
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) {
      return absl::InvalidArgumentError(
          absl::StrCat("floor plan: triangle ", t, " repeats a vertex"));
    }
    const int room = plan.triangle_room[t];
    if (room < 0 || room >= static_cast<int>(plan.rooms.size())) {
      return absl::InvalidArgumentError(absl::StrCat("floor plan: triangle ", t, " room ", room,
                                                     " out of range (", plan.rooms.size(), ")"));
    }
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = tri[k];
      const uint32_t b = tri[(k + 1) % 3];
      auto [it, inserted] = directed.try_emplace(EdgeKey(a, b), static_cast<int>(t));
      if (!inserted) {
        // Three triangles on one edge always use some direction twice.
        return absl::FailedPreconditionError(
            absl::StrCat("floor plan: non-manifold edge (", a, ", ", b,
                         "): used in the same direction by "
                         "triangles ",
                         it->second, " and ", t,
                         " (more than two triangles or inconsistent "
                         "orientation)"));
      }
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<FloorPlanOutline> TraceFloorPlan(const FloorPlan& plan) {
  if (absl::Status s = ValidateFloorPlan(plan); !s.ok()) return s;
  absl::flat_hash_map<uint64_t, int> directed;
  directed.reserve(plan.triangles.size() * 3);
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    for (int k = 0; k < 3; ++k) directed[EdgeKey(tri[k], tri[(k + 1) % 3])] = static_cast<int>(t);
  }
  const size_t room_count = plan.rooms.size();
  std::vector<std::vector<DirectedEdge>> room_edges(room_count);
  std::vector<DirectedEdge> wall_edges;
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    const auto& tri = plan.triangles[t];
    const int room = plan.triangle_room[t];
    for (int k = 0; k < 3; ++k) {
      const DirectedEdge e{tri[k], tri[(k + 1) % 3], static_cast<int>(t)};
      auto it = directed.find(EdgeKey(e.b, e.a));
      if (it == directed.end()) {
        wall_edges.push_back(e);
        room_edges[room].push_back(e);
      } else if (plan.triangle_room[it->second] != room) {
        room_edges[room].push_back(e);
      }
    }
  }

  FloorPlanOutline outline;
  const std::vector<Eigen::Vector2d>& xy = plan.vertices;
  for (size_t room = 0; room < room_count; ++room) {
    const std::vector<DirectedEdge>& edges = room_edges[room];
    std::vector<std::vector<int>> rings = TraceRings(edges, xy);
    std::vector<RoomPolygon> pieces;
    std::vector<double> outer_area;
    std::vector<std::pair<std::vector<Eigen::Vector2d>, Eigen::Vector2d>> holes;  // ring, probe
    for (const std::vector<int>& ring : rings) {
      std::vector<Eigen::Vector2d> points = RingPoints(ring, edges, xy);
      const double area = RingSignedArea(points);
      if (area > 0) {
        RoomPolygon piece;
        piece.room = static_cast<int>(room);
        piece.outer = std::move(points);
        piece.area_m2 = area;
        pieces.push_back(std::move(piece));
        outer_area.push_back(area);
      } else if (area < 0) {
        // A point strictly inside the room next to the hole: its owning triangle's centroid.
        const auto& tri = plan.triangles[edges[ring.front()].triangle];
        const Eigen::Vector2d probe = (xy[tri[0]] + xy[tri[1]] + xy[tri[2]]) / 3.0;
        holes.emplace_back(std::move(points), probe);
      }
      // Zero-area rings (collinear back-and-forth) bound nothing and are dropped.
    }
    for (auto& [ring, probe] : holes) {
      int best = -1;
      for (int i = 0; i < static_cast<int>(pieces.size()); ++i) {
        if ((best < 0 || outer_area[i] < outer_area[best]) && Inside(pieces[i].outer, probe)) {
          best = i;
        }
      }
      if (best < 0) {
        return absl::InternalError(
            absl::StrCat("floor plan: room ", room, " has a hole outside all its outer rings"));
      }
      pieces[best].area_m2 += RingSignedArea(ring);
      pieces[best].holes.push_back(std::move(ring));
    }
    for (RoomPolygon& piece : pieces) outline.rooms.push_back(std::move(piece));
  }

  for (const std::vector<int>& ring : TraceRings(wall_edges, xy)) {
    std::vector<Eigen::Vector2d> points = RingPoints(ring, wall_edges, xy);
    points.push_back(points.front());
    outline.walls.push_back(std::move(points));
  }
  return outline;
}

std::optional<Eigen::Vector2d> RoomLabelPoint(const FloorPlan& plan, int room) {
  // A triangle's centroid is inside its room, and the seed (§3.3.2, the largest circumcircle)
  // sits in the room's open middle.
  int label = plan.rooms[room].seed_triangle;
  if (label < 0 || label >= static_cast<int>(plan.triangles.size()) ||
      plan.triangle_room[label] != room) {
    label = -1;
    double best = 0;
    for (size_t t = 0; t < plan.triangles.size(); ++t) {
      if (plan.triangle_room[t] != room) continue;
      const auto& tri = plan.triangles[t];
      const Eigen::Vector2d e1 = plan.vertices[tri[1]] - plan.vertices[tri[0]];
      const Eigen::Vector2d e2 = plan.vertices[tri[2]] - plan.vertices[tri[0]];
      const double area = e1.x() * e2.y() - e1.y() * e2.x();
      if (label < 0 || area > best) {
        label = static_cast<int>(t);
        best = area;
      }
    }
  }
  if (label < 0) return std::nullopt;
  const auto& tri = plan.triangles[label];
  return (plan.vertices[tri[0]] + plan.vertices[tri[1]] + plan.vertices[tri[2]]) / 3.0;
}

}  // namespace carvemap
