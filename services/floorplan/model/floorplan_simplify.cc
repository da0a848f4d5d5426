#include "services/floorplan/model/floorplan_simplify.h"

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <queue>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "services/floorplan/model/room_polygons.h"

namespace carvemap {
namespace {

uint64_t EdgeKey(uint32_t a, uint32_t b) { return (static_cast<uint64_t>(a) << 32) | b; }

double Cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
}

constexpr double kMinTwiceArea = 2e-12;  // m²: smaller triangles count as degenerate
constexpr int kNone = -1;

// The mutable triangulation and boundary of one SimplifyFloorPlan call.
class Simplifier {
 public:
  Simplifier(FloorPlan& plan, double max_error_m) : plan_(plan), max_error_m_(max_error_m) {}

  void Run(SimplifyReport& report);

 private:
  struct Candidate {
    double error;
    uint32_t vertex;
    uint32_t version;
    bool operator<(const Candidate& o) const {  // min-heap on error, then vertex
      return error != o.error ? error > o.error : vertex > o.vertex;
    }
  };

  void Build();
  [[nodiscard]] bool Removable(uint32_t u) const {
    return !fixed_[u] && !dead_[u] && next_[u] != kNone && !pinch_[u];
  }
  double Error(uint32_t u) const;
  void Push(uint32_t u);
  // Checks the half-edge collapse u→v (v = next or prev of u along the boundary); fills the
  // triangle to delete.
  bool Valid(uint32_t u, uint32_t v, uint32_t p, uint32_t n, int& deleted) const;
  void Collapse(uint32_t u, uint32_t v, uint32_t p, uint32_t n, int deleted);
  void Neighbours(uint32_t v, std::vector<uint32_t>& out) const;
  void Finish(SimplifyReport& report);
  uint64_t CellKey(int64_t ix, int64_t iy) const {
    return (static_cast<uint64_t>(ix + (1 << 30)) << 32) | static_cast<uint64_t>(iy + (1 << 30));
  }

  FloorPlan& plan_;
  const double max_error_m_;
  std::vector<Eigen::Vector2d> xy_;  // centred, so the moment sums keep their precision
  std::vector<std::array<uint32_t, 3>> tris_;
  std::vector<char> alive_;
  std::vector<std::vector<int>> incident_;    // may list dead triangles and ones without v
  absl::flat_hash_map<uint64_t, int> edges_;  // directed edge → triangle
  std::vector<int> next_, prev_;              // along the boundary, interior on the left
  std::vector<char> fixed_, pinch_, dead_;
  std::vector<uint32_t> version_;
  absl::flat_hash_map<uint64_t, Eigen::Matrix3d> segment_;  // boundary edge → Σ x̂x̂ᵀ inside
  double cell_m_ = 1;
  absl::flat_hash_map<uint64_t, std::vector<uint32_t>> grid_;  // boundary vertices by cell
  std::priority_queue<Candidate> heap_;
  size_t collapses_ = 0, rejected_ = 0;
  double max_made_ = 0;
};

void Simplifier::Build() {
  const size_t n = plan_.vertices.size();
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  for (const auto& p : plan_.vertices) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector2d centre = n ? Eigen::Vector2d(0.5 * (lo + hi)) : Eigen::Vector2d::Zero();
  xy_.resize(n);
  for (size_t i = 0; i < n; ++i) xy_[i] = plan_.vertices[i] - centre;
  tris_ = plan_.triangles;
  alive_.assign(tris_.size(), 1);
  incident_.assign(n, {});
  edges_.reserve(tris_.size() * 3);
  // §3.3.3: vertices in several rooms, and their neighbours, keep the doorways' detail.
  std::vector<int> room_of(n, kNone);
  std::vector<char> multi(n, 0);
  for (size_t t = 0; t < tris_.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = tris_[t][k];
      incident_[v].push_back(static_cast<int>(t));
      edges_[EdgeKey(v, tris_[t][(k + 1) % 3])] = static_cast<int>(t);
      if (room_of[v] == kNone)
        room_of[v] = plan_.triangle_room[t];
      else if (room_of[v] != plan_.triangle_room[t])
        multi[v] = 1;
    }
  }
  fixed_.assign(n, 0);
  for (const auto& tri : tris_) {
    const bool any = multi[tri[0]] || multi[tri[1]] || multi[tri[2]];
    if (any) fixed_[tri[0]] = fixed_[tri[1]] = fixed_[tri[2]] = 1;
  }
  next_.assign(n, kNone);
  prev_.assign(n, kNone);
  pinch_.assign(n, 0);
  dead_.assign(n, 0);
  version_.assign(n, 0);
  for (const auto& tri : tris_) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = tri[k], b = tri[(k + 1) % 3];
      if (edges_.contains(EdgeKey(b, a))) continue;
      if (next_[a] != kNone) pinch_[a] = 1;  // the boundary touches itself at a
      next_[a] = static_cast<int>(b);
      prev_[b] = static_cast<int>(a);
      segment_[EdgeKey(a, b)] = Eigen::Matrix3d::Zero();
    }
  }
  cell_m_ = std::max(4 * max_error_m_, 1e-3);
  for (uint32_t v = 0; v < n; ++v) {
    if (next_[v] == kNone) continue;
    grid_[CellKey(static_cast<int64_t>(std::floor(xy_[v].x() / cell_m_)),
                  static_cast<int64_t>(std::floor(xy_[v].y() / cell_m_)))]
        .push_back(v);
  }
}

double Simplifier::Error(uint32_t u) const {
  const uint32_t p = prev_[u], n = next_[u];
  const Eigen::Vector2d d = xy_[n] - xy_[p];
  const double length = d.norm();
  if (p == n || length < 1e-12) return std::numeric_limits<double>::infinity();
  // Eq. 3.4's line ax + by + c = 0, a² + b² = 1, through p and n.
  const Eigen::Vector3d l(-d.y() / length, d.x() / length,
                          (d.y() * xy_[p].x() - d.x() * xy_[p].y()) / length);
  const Eigen::Vector3d uh(xy_[u].x(), xy_[u].y(), 1.0);
  const Eigen::Matrix3d m =
      segment_.at(EdgeKey(p, u)) + segment_.at(EdgeKey(u, n)) + uh * uh.transpose();
  return std::sqrt(std::max(0.0, l.dot(m * l)));
}

void Simplifier::Push(uint32_t u) {
  ++version_[u];  // whatever happens, an older entry of u is stale now
  if (!Removable(u)) return;
  const double e = Error(u);
  if (!(e < max_error_m_)) return;
  heap_.push({e, u, version_[u]});
}

void Simplifier::Neighbours(uint32_t v, std::vector<uint32_t>& out) const {
  out.clear();
  for (int t : incident_[v]) {
    if (!alive_[t]) continue;
    const auto& tri = tris_[t];
    if (tri[0] != v && tri[1] != v && tri[2] != v) continue;
    for (uint32_t w : tri) {
      if (w != v) out.push_back(w);
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

bool Simplifier::Valid(uint32_t u, uint32_t v, uint32_t p, uint32_t n, int& deleted) const {
  // The interior triangle on the boundary edge between u and v is the one collapsed.
  const uint64_t key = v == n ? EdgeKey(u, v) : EdgeKey(v, u);
  auto it = edges_.find(key);
  if (it == edges_.end()) return false;
  deleted = it->second;
  const auto& gone = tris_[deleted];
  uint32_t w = gone[0];
  for (uint32_t x : gone) {
    if (x != u && x != v) w = x;
  }
  // An isolated triangle (a 3-vertex boundary loop) is never collapsed away.
  if ((w == p || w == n) && !edges_.contains(EdgeKey(gone[1], gone[0])) &&
      !edges_.contains(EdgeKey(gone[2], gone[1])) && !edges_.contains(EdgeKey(gone[0], gone[2]))) {
    return false;
  }
  // Link condition: u and v share only w, else the collapse pinches the plan.
  std::vector<uint32_t> nu, nv;
  Neighbours(u, nu);
  Neighbours(v, nv);
  for (uint32_t x : nu) {
    if (x != w && x != v && std::binary_search(nv.begin(), nv.end(), x)) return false;
  }
  // Orientation: every triangle moving from u to v stays counter-clockwise and non-degenerate;
  // v's fan (v is on the boundary) must not wrap past 360°.
  double fan = 0;
  auto angle_at = [&](const std::array<uint32_t, 3>& tri, uint32_t at) {
    int k = 0;
    while (tri[k] != at) ++k;
    const Eigen::Vector2d a = xy_[tri[(k + 1) % 3]] - xy_[at];
    const Eigen::Vector2d b = xy_[tri[(k + 2) % 3]] - xy_[at];
    return std::atan2(a.x() * b.y() - a.y() * b.x(), a.dot(b));
  };
  for (int t : incident_[u]) {
    if (!alive_[t] || t == deleted) continue;
    std::array<uint32_t, 3> tri = tris_[t];
    bool has_u = false;
    for (uint32_t& x : tri) {
      if (x == u) {
        x = v;
        has_u = true;
      }
    }
    if (!has_u) continue;
    if (Cross(xy_[tri[0]], xy_[tri[1]], xy_[tri[2]]) < kMinTwiceArea) return false;
    fan += angle_at(tri, v);
  }
  for (int t : incident_[v]) {
    if (!alive_[t] || t == deleted) continue;
    const auto& tri = tris_[t];
    if (tri[0] == v || tri[1] == v || tri[2] == v) fan += angle_at(tri, v);
  }
  if (fan > 2 * std::numbers::pi - 1e-9) return false;
  // A reflex u: the plan grows by the sliver (p, n, u); no other wall may lie in it.
  if (Cross(xy_[p], xy_[u], xy_[n]) < 0) {
    const Eigen::Vector2d lo = xy_[p].cwiseMin(xy_[n]).cwiseMin(xy_[u]);
    const Eigen::Vector2d hi = xy_[p].cwiseMax(xy_[n]).cwiseMax(xy_[u]);
    for (int64_t ix = static_cast<int64_t>(std::floor(lo.x() / cell_m_));
         ix <= static_cast<int64_t>(std::floor(hi.x() / cell_m_)); ++ix) {
      for (int64_t iy = static_cast<int64_t>(std::floor(lo.y() / cell_m_));
           iy <= static_cast<int64_t>(std::floor(hi.y() / cell_m_)); ++iy) {
        auto cell = grid_.find(CellKey(ix, iy));
        if (cell == grid_.end()) continue;
        for (uint32_t x : cell->second) {
          if (x == p || x == n || x == u || dead_[x]) continue;
          const Eigen::Vector2d& q = xy_[x];
          if (Cross(xy_[p], xy_[n], q) >= 0 && Cross(xy_[n], xy_[u], q) >= 0 &&
              Cross(xy_[u], xy_[p], q) >= 0) {
            return false;
          }
        }
      }
    }
  }
  return true;
}

void Simplifier::Collapse(uint32_t u, uint32_t v, uint32_t p, uint32_t n, int deleted) {
  auto drop_edges = [&](int t) {
    for (int k = 0; k < 3; ++k) edges_.erase(EdgeKey(tris_[t][k], tris_[t][(k + 1) % 3]));
  };
  drop_edges(deleted);
  alive_[deleted] = 0;
  for (int t : incident_[u]) {
    if (!alive_[t]) continue;
    auto& tri = tris_[t];
    if (tri[0] != u && tri[1] != u && tri[2] != u) continue;
    drop_edges(t);
    for (uint32_t& x : tri) {
      if (x == u) x = v;
    }
    for (int k = 0; k < 3; ++k) edges_[EdgeKey(tri[k], tri[(k + 1) % 3])] = t;
    incident_[v].push_back(t);
  }
  incident_[u].clear();
  dead_[u] = 1;
  const Eigen::Vector3d uh(xy_[u].x(), xy_[u].y(), 1.0);
  const Eigen::Matrix3d m =
      segment_.at(EdgeKey(p, u)) + segment_.at(EdgeKey(u, n)) + uh * uh.transpose();
  segment_.erase(EdgeKey(p, u));
  segment_.erase(EdgeKey(u, n));
  segment_[EdgeKey(p, n)] = m;
  if (!pinch_[p]) next_[p] = static_cast<int>(n);
  if (!pinch_[n]) prev_[n] = static_cast<int>(p);
  next_[u] = prev_[u] = kNone;
  Push(p);
  Push(n);
}

void Simplifier::Run(SimplifyReport& report) {
  Build();
  for (uint32_t v = 0; v < xy_.size(); ++v) {
    if (next_[v] != kNone) ++report.boundary_vertices_before;
  }
  for (uint32_t v = 0; v < xy_.size(); ++v) Push(v);
  while (!heap_.empty()) {
    const Candidate c = heap_.top();
    heap_.pop();
    if (c.version != version_[c.vertex] || !Removable(c.vertex)) continue;
    const uint32_t u = c.vertex, p = prev_[u], n = next_[u];
    int deleted = kNone;
    if (Valid(u, n, p, n, deleted)) {
      Collapse(u, n, p, n, deleted);
    } else if (Valid(u, p, p, n, deleted)) {
      Collapse(u, p, p, n, deleted);
    } else {
      ++rejected_;
      continue;
    }
    ++collapses_;
    max_made_ = std::max(max_made_, c.error);
  }
  Finish(report);
}

void Simplifier::Finish(SimplifyReport& report) {
  const size_t n = xy_.size();
  std::vector<uint32_t> renumber(n, 0);
  FloorPlan out;
  out.level = plan_.level;
  for (size_t v = 0; v < n; ++v) {
    if (dead_[v]) continue;
    renumber[v] = static_cast<uint32_t>(out.vertices.size());
    out.vertices.push_back(plan_.vertices[v]);
    out.vertex_floor_z.push_back(plan_.vertex_floor_z[v]);
    out.vertex_ceiling_z.push_back(plan_.vertex_ceiling_z[v]);
    if (next_[v] != kNone) ++report.boundary_vertices_after;
  }
  std::vector<int> new_index(tris_.size(), kNone);
  for (size_t t = 0; t < tris_.size(); ++t) {
    if (!alive_[t]) continue;
    new_index[t] = static_cast<int>(out.triangles.size());
    out.triangles.push_back({renumber[tris_[t][0]], renumber[tris_[t][1]], renumber[tris_[t][2]]});
    out.triangle_room.push_back(plan_.triangle_room[t]);
  }
  out.rooms = plan_.rooms;
  std::vector<int> largest(out.rooms.size(), kNone);
  std::vector<double> largest_area(out.rooms.size(), 0);
  for (FloorPlanRoom& room : out.rooms) room.area_m2 = 0;
  for (size_t t = 0; t < out.triangles.size(); ++t) {
    const auto& tri = out.triangles[t];
    const double area =
        0.5 * Cross(out.vertices[tri[0]], out.vertices[tri[1]], out.vertices[tri[2]]);
    const int r = out.triangle_room[t];
    out.rooms[r].area_m2 += area;
    if (largest[r] == kNone || area > largest_area[r]) {
      largest[r] = static_cast<int>(t);
      largest_area[r] = area;
    }
  }
  for (size_t r = 0; r < out.rooms.size(); ++r) {
    FloorPlanRoom& room = out.rooms[r];
    const int old = room.seed_triangle;
    if (old >= 0 && old < static_cast<int>(new_index.size()) && new_index[old] != kNone) {
      room.seed_triangle = new_index[old];
      continue;
    }
    if (old < 0) continue;
    room.seed_triangle = largest[r];
    if (largest[r] == kNone) continue;
    // Circumradius R = abc / (4·area) of the replacement seed.
    const auto& tri = out.triangles[largest[r]];
    const Eigen::Vector2d& a = out.vertices[tri[0]];
    const Eigen::Vector2d& b = out.vertices[tri[1]];
    const Eigen::Vector2d& c = out.vertices[tri[2]];
    room.seed_radius_m = (a - b).norm() * (b - c).norm() * (c - a).norm() / (4 * largest_area[r]);
  }
  report.collapses = collapses_;
  report.rejected = rejected_;
  report.max_error_m = max_made_;
  plan_ = std::move(out);
}

}  // namespace

absl::Status FloorPlanSimplifyOptions::Validate() const {
  if (!std::isfinite(max_error_m) || max_error_m <= 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "floorplan simplify: max_error_m must be finite and > 0 (pass the samples' spacing r), "
        "got ",
        max_error_m));
  }
  return absl::OkStatus();
}

absl::Status SimplifyFloorPlan(FloorPlan& plan, const FloorPlanSimplifyOptions& options,
                               SimplifyReport* report) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (absl::Status s = ValidateFloorPlan(plan); !s.ok()) return s;
  SimplifyReport local;
  Simplifier(plan, options.max_error_m).Run(local);
  if (report != nullptr) *report = local;
  return absl::OkStatus();
}

}  // namespace carvemap
