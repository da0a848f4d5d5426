#include "services/mesh/planar_work_mesh.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/intersections.h>

#include <Eigen/SVD>
#include <cmath>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <utility>

#include "absl/container/flat_hash_map.h"
#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_cat.h"
#include "geometry/sorted_runs.h"
#include "geometry/union_find.h"
#include "services/mesh/face_surface.h"
#include "services/mesh/planar_mesh_repair.h"

namespace carvemap::planar_mesh_internal {
namespace {

// ---------------------------------------------------------------------------------------------
// eq 4.9 (§4.3.3): the vertex of an octree corner x0 touched by the regions with normals n_i
// (rows of M) through points P_i, p = diag(P Mᵀ) = (n_i · P_i):
//   x = Σ_i (δ_i (p · u_i) / s_i + (1 − δ_i) (x0 · v_i)) v_i,   M = U S Vᵀ,
// δ_i = 1 when s_i ≥ α. The dissertation sets α = 0.2 · s_min; read literally every s_i ≥ s_min > α
// and nothing would ever be dropped (Fig 4.10 could not happen), so we read s as the largest
// singular value, the scale of M: α = alpha_fraction · s_max. For two planes at angle θ the
// singular values are √(1 ± cos θ), so their line is trusted only when tan(θ/2) ≥ 0.2, θ ≳ 22.6°
// — just above the 15° of relaxation (§4.2.4); closer planes keep x0's coordinate along the
// weak direction instead of flying to a far intersection (Fig 4.10's green star).
Eigen::Vector3d PlaceVertex(const Eigen::Vector3d& x0, const std::vector<int>& region_ids,
                            const PlanarRegionSet& regions, const PlanarMeshOptions& options,
                            double res) {
  const int m = static_cast<int>(region_ids.size());
  Eigen::MatrixXd M(m, 3);
  Eigen::VectorXd p(m);
  for (int i = 0; i < m; ++i) {
    const PlanarRegion& r = regions.regions[region_ids[i]];
    M.row(i) = r.normal.transpose();
    p[i] = r.normal.dot(r.centroid);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(M, Eigen::ComputeThinU | Eigen::ComputeFullV);
  const Eigen::VectorXd& s = svd.singularValues();
  const double alpha = options.alpha_fraction * (s.size() > 0 ? s[0] : 0.0);
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d v = svd.matrixV().col(i);
    const bool excited = i < s.size() && s[i] > 1e-9 && s[i] >= alpha;
    const double coord = excited ? p.dot(svd.matrixU().col(i)) / s[i] : x0.dot(v);
    x += coord * v;
  }
  // §4.2.5: shared vertices may move only up to a threshold from their grid position.
  const double max_move = options.max_displacement_cells * res;
  const Eigen::Vector3d move = x - x0;
  if (move.norm() > max_move) x = x0 + move * (max_move / move.norm());
  return x;
}

double DistanceToSegment(const Eigen::Vector3d& x, const Eigen::Vector3d& a,
                         const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0 ? std::clamp((x - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (a + t * ab - x).norm();
}

// 2D helpers for one region, in its plane basis.

double SignedArea(const WorkMesh& m, const std::vector<PlaneFrame>& frames, int region, int a,
                  int b, int c) {
  return 0.5 * frames[region].Area2(m.pos[a], m.pos[b], m.pos[c]);
}

// Whether the triangles of one region around w turn more than once around it in the region's
// 2D coordinates: each triangle has a positive area, yet together they overlap (a vertex on
// the region's border moved or collapsed so far that its fan wraps past itself), and the
// region's outline crosses itself there. Neighbours the region sees on w's point (a riser
// seen edge-on) count as w: the angles of their triangles are summed with w's, and triangles
// with two vertices on the point, or without area, add nothing.
bool Overwound(WorkMesh& m, const std::vector<PlaneFrame>& frames, int w, double min_area2) {
  const WorkMesh::TriList around = m.Tris(w);
  absl::InlinedVector<int, 4> regions;
  for (int t : around) {
    if (std::find(regions.begin(), regions.end(), m.tri_region[t]) == regions.end()) {
      regions.push_back(m.tri_region[t]);
    }
  }
  for (int r : regions) {
    const PlaneFrame& f = frames[r];
    const Eigen::Vector2d p = f.To2(m.pos[w]);
    const double eps2 = 1e-3 * min_area2;  // (2D distance)² on the point
    auto on_point = [&](int v) { return (f.To2(m.pos[v]) - p).squaredNorm() <= eps2; };
    absl::InlinedVector<int, 4> cluster = {w};
    absl::InlinedVector<int, 16> tris;
    for (int t : around) {
      if (m.tri_region[t] != r) continue;
      tris.push_back(t);
      for (int v : m.tri[t]) {
        if (v != w && on_point(v) &&
            std::find(cluster.begin(), cluster.end(), v) == cluster.end()) {
          cluster.push_back(v);
        }
      }
    }
    if (cluster.size() > 1) {
      for (size_t c = 1; c < cluster.size(); ++c) {
        for (int t : m.Tris(cluster[c])) {
          if (m.tri_region[t] == r) tris.push_back(t);
        }
      }
      std::sort(tris.begin(), tris.end());
      tris.erase(std::unique(tris.begin(), tris.end()), tris.end());
    }
    // Each triangle's angle is below π: fewer than three cannot turn past 2π.
    if (tris.size() < 3) continue;
    double sum = 0;
    for (int t : tris) {
      const auto& x = m.tri[t];
      int k = -1, on = 0;
      for (int i = 0; i < 3; ++i) {
        if (on_point(x[i])) ++on, k = i;
      }
      if (on != 1) continue;
      const Eigen::Vector2d a = f.To2(m.pos[x[(k + 1) % 3]]) - p;
      const Eigen::Vector2d b = f.To2(m.pos[x[(k + 2) % 3]]) - p;
      const double cross = a.x() * b.y() - a.y() * b.x();
      if (cross < min_area2) continue;
      sum += std::atan2(cross, a.dot(b));
    }
    if (sum > 2 * M_PI + 1e-9) return true;
  }
  return false;
}

// The vertices of the triangles around each of `vs`.
std::vector<int> Around(WorkMesh& m, std::span<const int> vs) {
  std::vector<int> out;
  for (int v : vs) {
    for (int t : m.Tris(v))
      for (int w : m.tri[t]) out.push_back(w);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// The vertices that share a triangle with u, sorted.
std::vector<int> Neighbours(WorkMesh& m, int u) {
  const int one[1] = {u};
  std::vector<int> out = Around(m, one);
  out.erase(std::remove(out.begin(), out.end(), u), out.end());
  return out;
}

// Collapses u into v when that keeps the surface a manifold, no triangle gets worse than
// `min_area` in its region's plane (§4.2.5: the chains stay where the regions meet) and no
// region wraps around a vertex (Overwound).
bool TryCollapse(WorkMesh& m, const std::vector<PlaneFrame>& frames, int u, int v, double min_area,
                 double res) {
  const WorkMesh::TriList tu = m.Tris(u);
  std::vector<int> shared, moved;
  for (int t : tu) {
    const auto& x = m.tri[t];
    (x[0] == v || x[1] == v || x[2] == v ? shared : moved).push_back(t);
  }
  if (shared.size() != 2) return false;
  // Link condition: the common neighbours of u and v are the two opposite vertices.
  std::vector<int> opposite;
  for (int t : shared) {
    for (int w : m.tri[t])
      if (w != u && w != v) opposite.push_back(w);
  }
  if (opposite.size() != 2 || opposite[0] == opposite[1]) return false;
  std::vector<int> nu, nv;
  for (int t : tu)
    for (int w : m.tri[t])
      if (w != u && w != v) nu.push_back(w);
  for (int t : m.Tris(v))
    for (int w : m.tri[t])
      if (w != u && w != v) nv.push_back(w);
  std::sort(nu.begin(), nu.end());
  nu.erase(std::unique(nu.begin(), nu.end()), nu.end());
  std::sort(nv.begin(), nv.end());
  nv.erase(std::unique(nv.begin(), nv.end()), nv.end());
  std::vector<int> common;
  std::set_intersection(nu.begin(), nu.end(), nv.begin(), nv.end(), std::back_inserter(common));
  std::sort(opposite.begin(), opposite.end());
  if (common != opposite) return false;
  // Small closed pieces (a tetrahedron) would fold into two coincident triangles: every vertex
  // keeps at least three triangles.
  if (tu.size() + m.Tris(v).size() - 4 < 3) return false;
  for (int w : opposite) {
    if (m.Tris(w).size() < 4) return false;
  }
  for (int t : moved) {
    std::array<int, 3> x = m.tri[t];
    const double before = SignedArea(m, frames, m.tri_region[t], x[0], x[1], x[2]);
    for (int& w : x)
      if (w == u) w = v;
    const double after = SignedArea(m, frames, m.tri_region[t], x[0], x[1], x[2]);
    if (after < min_area && after < before) return false;
  }
  const int uv[2] = {u, v};
  const std::vector<int> near = Around(m, uv);
  // Triangles below a millionth of a cell do not count in the winding (as a flat triangle
  // would not), whatever area this collapse asks for.
  const double min_area2 = 2e-6 * res * res;
  const WorkMesh::TriList u_incident = m.incident[u];
  auto apply = [&] {
    for (int t : shared) m.alive[t] = 0;
    for (int t : moved) {
      for (int& w : m.tri[t])
        if (w == u) w = v;
      m.incident[v].push_back(t);
    }
    m.vertex_alive[u] = 0;
    m.incident[u].clear();
  };
  auto undo = [&] {
    for (int t : shared) {
      m.alive[t] = 1;  // and back in the lists Tris() compacted meanwhile
      for (int w : m.tri[t]) m.incident[w].push_back(t);
    }
    for (int t : moved) {
      for (int& w : m.tri[t])
        if (w == v) w = u;
    }
    m.vertex_alive[u] = 1;
    m.incident[u] = u_incident;
  };
  apply();
  // No region may wrap around a vertex it did not wrap around before (its outline would cross
  // itself, and the re-triangulation would fail). Checked after the collapse first, as a
  // vertex is rarely wrapped around at all.
  std::vector<int> wound;
  for (int w : near) {
    if (w != u && Overwound(m, frames, w, min_area2)) wound.push_back(w);
  }
  if (wound.empty()) return true;
  undo();
  for (int w : wound) {
    if (!Overwound(m, frames, w, min_area2)) return false;
  }
  apply();
  return true;
}

// The two triangles on edge (a, b) differ in region: a boundary edge between regions.
bool IsRegionEdge(WorkMesh& m, int a, int b) {
  int regs[2], n = 0;
  for (int t : m.Tris(a)) {
    const auto& x = m.tri[t];
    if (x[0] == b || x[1] == b || x[2] == b) {
      if (n < 2) regs[n] = m.tri_region[t];
      ++n;
    }
  }
  return n == 2 && regs[0] != regs[1];
}

// Vertices closer than this (grid cells) are one point: the output is float, whose step at
// building coordinates (~5e-7 m at 5 m) would otherwise merge them into a flat triangle.
constexpr double kCoincidentCells = 1e-3;

// A triangle without area, or with an edge shorter than float can keep.
bool Flat(const WorkMesh& m, const std::array<int, 3>& x, double min_area, double res) {
  if ((m.pos[x[1]] - m.pos[x[0]]).cross(m.pos[x[2]] - m.pos[x[0]]).norm() <= 2 * min_area)
    return true;
  for (int i = 0; i < 3; ++i) {
    if ((m.pos[x[(i + 1) % 3]] - m.pos[x[i]]).norm() < kCoincidentCells * res) return true;
  }
  return false;
}

// A triangle whose third vertex lies on its longest edge: flip that edge when the triangle
// beyond it is of the same region (the region's border does not move).
bool FlipLongestEdge(WorkMesh& m, const std::vector<PlaneFrame>& frames, int t, double min_area) {
  const auto x = m.tri[t];
  int i = 0;
  double longest = -1;
  for (int k = 0; k < 3; ++k) {
    const double len = (m.pos[x[(k + 1) % 3]] - m.pos[x[k]]).squaredNorm();
    if (len > longest) longest = len, i = k;
  }
  const int a = x[i], b = x[(i + 1) % 3], c = x[(i + 2) % 3];
  int other = -1, d = -1;
  for (int u : m.Tris(a)) {
    const auto& y = m.tri[u];
    for (int k = 0; k < 3; ++k) {
      if (u != t && y[k] == b && y[(k + 1) % 3] == a) other = u, d = y[(k + 2) % 3];
    }
  }
  if (other < 0 || m.tri_region[other] != m.tri_region[t] || d == c) return false;
  for (int u : m.Tris(c)) {
    for (int w : m.tri[u])
      if (w == d) return false;  // c–d is already an edge
  }
  const int r = m.tri_region[t];
  if (SignedArea(m, frames, r, a, d, c) < min_area ||
      SignedArea(m, frames, r, d, b, c) < min_area) {
    return false;
  }
  m.tri[t] = {a, d, c};
  m.tri[other] = {d, b, c};
  m.incident[d].push_back(t);
  m.incident[c].push_back(other);
  return true;
}

// A vertex where regions meet, at its octree corner, and the regions it touches.
struct SharedVertex {
  int v;
  absl::InlinedVector<int, 4> regions;
};

// Moves the vertices where regions meet from their octree corners to their eq 4.9 positions
// as far as no triangle folds over in its region's 2D coordinates (§4.2.5: "to limit
// self-intersections in the final surface, the vertices shared by multiple regions are
// allowed to be displaced up to a distance threshold from their original position"; here the
// threshold is also per vertex, where its triangles would turn over). With every shared
// vertex at its corner and the others on their plane along the dominant axis (PlaneFrame), no
// triangle has a negative area in its region's coordinates: the regions' outlines are simple
// polygons that the re-triangulation can fill.
//
// Shared vertices joined by an edge that a region sees edge-on (the corners of a step or riser
// of the region, one above the other along its axis) move as one: to the eq 4.9 point of all
// their regions, from each corner the same fraction of the way, so that the region keeps
// seeing them as one point and the riser's triangles (no area in its coordinates) stay flat
// rather than turning over; so do the vertices of one region such a region sees on their
// point (the top of a riser whose foot is on a chain). All vertices move at once; then each
// triangle that lost area it needs (below `min_area2` and below its area at the corners) sends
// the groups of its moved vertices a quarter of the way back, until none does, and so does
// each vertex a region wraps around (Overwound) for the groups around it. A group goes back at
// most four times, and with all at their corners nothing is folded, so this ends; the order of
// the work is fixed. The moves are kept in m.moves, where ResumeMoves goes on from.
void MoveWithoutFolds(WorkMesh& m, const std::vector<PlaneFrame>& frames,
                      const std::vector<SharedVertex>& shared, const PlanarRegionSet& regions,
                      const PlanarMeshOptions& options, double res) {
  const double min_area2 = 2e-6 * res * res;
  const double rounding = 1e-12 * res * res;
  const int num_tris = static_cast<int>(m.tri.size());
  auto area2 = [&](int t) {
    const auto& x = m.tri[t];
    return frames[m.tri_region[t]].Area2(m.pos[x[0]], m.pos[x[1]], m.pos[x[2]]);
  };
  std::vector<double> at_corners(num_tris);
  for (int t = 0; t < num_tris; ++t) at_corners[t] = area2(t);
  // The moving vertices: the shared ones, and vertices of one region that such a region sees
  // on the same point as a shared one (the top of a riser whose foot is on a chain), which
  // must stay on that point.
  std::vector<SharedVertex> nodes = shared;
  absl::flat_hash_map<int, int> index;  // vertex → its entry in `nodes`
  for (int i = 0; i < static_cast<int>(nodes.size()); ++i) index[nodes[i].v] = i;
  std::vector<std::pair<int, int>> edge_on;  // pairs of entries seen on one point
  for (int t = 0; t < num_tris; ++t) {
    const auto& x = m.tri[t];
    const PlaneFrame& frame = frames[m.tri_region[t]];
    for (int k = 0; k < 3; ++k) {
      const int u = x[k], w = x[(k + 1) % 3];
      if ((frame.To2(m.pos[u]) - frame.To2(m.pos[w])).norm() > 1e-6 * res) continue;
      const bool su = index.contains(u), sw = index.contains(w);
      if (!su && !sw) continue;
      for (int y : {u, w}) {
        if (index.contains(y)) continue;
        index[y] = static_cast<int>(nodes.size());
        nodes.push_back({y, {m.tri_region[t]}});
      }
      edge_on.push_back({index[u], index[w]});
    }
  }
  const int n = static_cast<int>(nodes.size());
  UnionFind<int> groups(n);
  for (auto [a, b] : edge_on) groups.Union(a, b);
  // Per group (by its root): the mean of its corners and the union of its regions.
  absl::flat_hash_map<int, std::pair<Eigen::Vector3d, int>> mean;
  absl::flat_hash_map<int, std::vector<int>> group_regions;
  for (int i = 0; i < n; ++i) {
    const int g = groups.Find(i);
    auto& [sum, count] = mean.try_emplace(g, Eigen::Vector3d::Zero(), 0).first->second;
    sum += m.pos[nodes[i].v];
    ++count;
    std::vector<int>& regs = group_regions[g];
    regs.insert(regs.end(), nodes[i].regions.begin(), nodes[i].regions.end());
  }
  absl::flat_hash_map<int, Eigen::Vector3d> target;
  for (int i = 0; i < n; ++i) {
    const int g = groups.Find(i);
    if (target.contains(g)) continue;
    std::vector<int>& regs = group_regions[g];
    std::sort(regs.begin(), regs.end());
    regs.erase(std::unique(regs.begin(), regs.end()), regs.end());
    const auto& [sum, count] = mean[g];
    target[g] = PlaceVertex(sum / count, regs, regions, options, res);
  }
  // Vertices a region already wraps around at the corners (a region that overlaps itself
  // along its axis): their winding is no move's fault.
  absl::flat_hash_set<int> wound_at_corners;
  {
    std::vector<int> all;
    for (const SharedVertex& s : nodes) all.push_back(s.v);
    for (int w : Around(m, all)) {
      if (Overwound(m, frames, w, min_area2)) wound_at_corners.insert(w);
    }
  }
  absl::flat_hash_map<int, int> group_id;  // root ➜ index in m.group_target
  std::vector<std::vector<int>> members;
  std::vector<Eigen::Vector3d> corner(n);
  for (int i = 0; i < n; ++i) {
    const int root = groups.Find(i);
    auto [it, added] = group_id.try_emplace(root, static_cast<int>(m.group_target.size()));
    if (added) {
      m.group_target.push_back(target[root]);
      members.emplace_back();
    }
    members[it->second].push_back(i);
    corner[i] = m.pos[nodes[i].v];
    m.pos[nodes[i].v] = target[root];
  }
  std::vector<int> group_of(n);
  for (int g = 0; g < static_cast<int>(members.size()); ++g) {
    for (int i : members[g]) group_of[i] = g;
  }
  m.group_quarters.assign(members.size(), 4);
  std::deque<int> work;
  std::vector<char> queued(num_tris, 1);
  for (int t = 0; t < num_tris; ++t) work.push_back(t);
  // Sends vertex v's group (if it moves) a quarter of the way back.
  auto step_back = [&](int v) {
    auto it = index.find(v);
    if (it == index.end()) return;
    const int g = group_of[it->second];
    int& q = m.group_quarters[g];
    if (q == 0) return;
    --q;
    for (int i : members[g]) {
      const int w = nodes[i].v;
      m.pos[w] = corner[i] + 0.25 * q * (m.group_target[g] - corner[i]);
      for (int u : m.incident[w]) {
        if (!queued[u]) queued[u] = 1, work.push_back(u);
      }
    }
  };
  for (int pass = 0; pass < 64; ++pass) {
    while (!work.empty()) {
      const int t = work.front();
      work.pop_front();
      queued[t] = 0;
      const double a = area2(t);
      if (a >= min_area2 || a >= at_corners[t] - rounding) continue;
      for (int v : m.tri[t]) step_back(v);
    }
    // Then no region may wrap around a vertex (Overwound; with all at their corners, none
    // does): the moving vertices around one that is wrapped go back a quarter.
    std::vector<int> moving;
    for (int i = 0; i < n; ++i) {
      if (m.group_quarters[group_of[i]] > 0) moving.push_back(nodes[i].v);
    }
    bool wound = false;
    for (int w : Around(m, moving)) {
      if (wound_at_corners.contains(w) || !Overwound(m, frames, w, min_area2)) continue;
      wound = true;
      const int one[1] = {w};
      for (int v : Around(m, one)) step_back(v);
    }
    if (!wound) break;
  }
  for (int i = 0; i < n; ++i) {
    m.moves.push_back({nodes[i].v, group_of[i], corner[i]});
  }
}

// The alive members of each group of moved vertices (entries of m.moves).
std::vector<std::vector<int>> GroupMembers(const WorkMesh& m) {
  std::vector<std::vector<int>> members(m.group_target.size());
  for (int i = 0; i < static_cast<int>(m.moves.size()); ++i) {
    if (m.vertex_alive[m.moves[i].v]) members[m.moves[i].group].push_back(i);
  }
  return members;
}

// Puts group g (its alive `members`) at the first of `quarters` (of the way from their corners
// to the group's eq 4.9 position) at which none of their triangles loses area it needs (below
// 2e-6 cells² and below what it had) and no region wraps around a vertex it did not wrap
// around before (Overwound). Returns whether it moved; if not, nothing changed.
bool TryGroupAt(WorkMesh& m, const std::vector<PlaneFrame>& frames, int g,
                const std::vector<int>& members, std::span<const int> quarters, double res) {
  const double min_area2 = 2e-6 * res * res;
  const double rounding = 1e-12 * res * res;
  auto area2 = [&](int t) {
    const auto& x = m.tri[t];
    return frames[m.tri_region[t]].Area2(m.pos[x[0]], m.pos[x[1]], m.pos[x[2]]);
  };
  std::vector<int> tris, vs;
  std::vector<Eigen::Vector3d> saved;
  for (int i : members) {
    const int v = m.moves[i].v;
    vs.push_back(v);
    saved.push_back(m.pos[v]);
    for (int t : m.Tris(v)) tris.push_back(t);
  }
  std::sort(tris.begin(), tris.end());
  tris.erase(std::unique(tris.begin(), tris.end()), tris.end());
  std::vector<double> before(tris.size());
  for (size_t k = 0; k < tris.size(); ++k) before[k] = area2(tris[k]);
  const std::vector<int> near = Around(m, vs);
  // Whether a region wraps around near[k] where the members were: found only when it does
  // where they are tried (rare).
  std::vector<signed char> wound_before(near.size(), -1);
  auto place = [&](int to) {
    for (int i : members) {
      const WorkMesh::Move& mv = m.moves[i];
      m.pos[mv.v] = mv.corner + 0.25 * to * (m.group_target[g] - mv.corner);
    }
  };
  auto restore = [&] {
    for (size_t j = 0; j < members.size(); ++j) m.pos[m.moves[members[j]].v] = saved[j];
  };
  for (int to : quarters) {
    place(to);
    bool ok = true;
    for (size_t k = 0; k < tris.size() && ok; ++k) {
      const double a = area2(tris[k]);
      ok = a >= min_area2 || a >= before[k] - rounding;
    }
    for (size_t k = 0; k < near.size() && ok; ++k) {
      if (!Overwound(m, frames, near[k], min_area2)) continue;
      if (wound_before[k] < 0) {
        restore();
        wound_before[k] = Overwound(m, frames, near[k], min_area2);
        place(to);
      }
      ok = wound_before[k] == 1;
    }
    if (ok) {
      m.group_quarters[g] = to;
      return true;
    }
    restore();
  }
  return false;
}

// The moves MoveWithoutFolds left short, tried again on the simplified mesh, whose bigger
// triangles let a vertex go farther before one turns over: each group, in order, goes as far
// towards its eq 4.9 position as TryGroupAt allows. Returns how many groups moved.
int ResumeMoves(WorkMesh& m, const std::vector<PlaneFrame>& frames, double res) {
  const std::vector<std::vector<int>> members = GroupMembers(m);
  int moved = 0;
  for (int sweep = 0; sweep < 4; ++sweep) {
    int changed = 0;
    for (int g = 0; g < static_cast<int>(members.size()); ++g) {
      const int q = m.group_quarters[g];
      if (q == 4 || members[g].empty()) continue;
      std::vector<int> quarters;
      for (int to = 4; to > q; --to) quarters.push_back(to);
      changed += TryGroupAt(m, frames, g, members[g], quarters, res);
    }
    moved += changed;
    if (changed == 0) break;
  }
  return moved;
}

// ---------------------------------------------------------------------------------------------
// Untangle: triangles of the work mesh that meet other than at what they share, decided with
// CGAL's exact predicates (the same test CountSelfIntersections makes on the written mesh).

using UK = CGAL::Exact_predicates_inexact_constructions_kernel;

UK::Point_3 P3(const Eigen::Vector3d& x) { return {x.x(), x.y(), x.z()}; }

bool WorkTrianglesMeet(const WorkMesh& m, const std::array<int, 3>& a,
                       const std::array<int, 3>& b) {
  return TrianglesMeet(a, {m.pos[a[0]], m.pos[a[1]], m.pos[a[2]]}, b,
                       {m.pos[b[0]], m.pos[b[1]], m.pos[b[2]]});
}

void TriangleBox(const WorkMesh& m, const std::array<int, 3>& x, Eigen::Vector3d& lo,
                 Eigen::Vector3d& hi) {
  lo = m.pos[x[0]].cwiseMin(m.pos[x[1]]).cwiseMin(m.pos[x[2]]);
  hi = m.pos[x[0]].cwiseMax(m.pos[x[1]]).cwiseMax(m.pos[x[2]]);
}

// The alive triangles in `grid` whose box meets [lo, hi] now.
std::vector<int> AliveNear(const WorkMesh& m, const BoxGrid& grid, const Eigen::Vector3d& lo,
                           const Eigen::Vector3d& hi) {
  std::vector<int> out = grid.Candidates(lo, hi);
  std::erase_if(out, [&](int t) {
    if (!m.alive[t]) return true;
    Eigen::Vector3d a, b;
    TriangleBox(m, m.tri[t], a, b);
    return (b.array() < lo.array()).any() || (a.array() > hi.array()).any();
  });
  return out;
}

// Triangles near a vertex, with their boxes as they are now, for Untangle's counts.
struct Nearby {
  int t;
  Eigen::Vector3d lo, hi;
};

// Pairs that meet among `changed` (triangle ids with the vertices they would have, at the
// positions m holds now) and between them and the `near` triangles that are neither changed
// nor in `gone`.
int MeetingPairs(const WorkMesh& m, std::span<const Nearby> near,
                 std::span<const std::pair<int, std::array<int, 3>>> changed,
                 std::span<const int> gone, int limit = std::numeric_limits<int>::max()) {
  auto skip = [&](int t) {
    if (std::find(gone.begin(), gone.end(), t) != gone.end()) return true;
    for (const auto& c : changed)
      if (c.first == t) return true;
    return false;
  };
  int n = 0;
  for (size_t i = 0; i < changed.size() && n < limit; ++i) {
    const std::array<int, 3>& x = changed[i].second;
    for (size_t j = i + 1; j < changed.size(); ++j) n += WorkTrianglesMeet(m, x, changed[j].second);
    Eigen::Vector3d lo, hi;
    TriangleBox(m, x, lo, hi);
    for (const Nearby& o : near) {
      if ((o.hi.array() < lo.array()).any() || (o.lo.array() > hi.array()).any()) continue;
      if (!skip(o.t)) n += WorkTrianglesMeet(m, x, m.tri[o.t]);
      if (n >= limit) break;
    }
  }
  return n;
}

}  // namespace

// Sharing a vertex s, two triangles meet elsewhere iff the edge of one opposite s meets the
// other; sharing an edge, iff they lie in one plane on the same side of it (folded onto each
// other).
bool TrianglesMeet(const std::array<int, 3>& a, const std::array<Eigen::Vector3d, 3>& pa,
                   const std::array<int, 3>& b, const std::array<Eigen::Vector3d, 3>& pb) {
  const UK::Triangle_3 ta(P3(pa[0]), P3(pa[1]), P3(pa[2]));
  const UK::Triangle_3 tb(P3(pb[0]), P3(pb[1]), P3(pb[2]));
  // Vertices on one point count as shared, as CountSelfIntersections welds them: sheets that
  // touch there are RepairPlanarMesh's to separate.
  int ia[3], ib[3], shared = 0;  // positions of the shared vertices in a and in b
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (shared < 3 && (a[i] == b[j] || pa[i] == pb[j])) {
        ia[shared] = i;
        ib[shared] = j;
        ++shared;
      }
  if (shared == 3) return true;
  // CGAL's exact test only where doubles cannot tell: an area well above rounding has area.
  auto flat = [](const std::array<Eigen::Vector3d, 3>& p, const UK::Triangle_3& t) {
    const Eigen::Vector3d e1 = p[1] - p[0], e2 = p[2] - p[0];
    const double scale = std::max(e1.squaredNorm(), e2.squaredNorm());
    return e1.cross(e2).squaredNorm() <= 1e-20 * scale * scale && t.is_degenerate();
  };
  const bool da = flat(pa, ta), db = flat(pb, tb);
  if (da || db) {
    // CGAL's triangle tests need area: a flat triangle is tested as its longest edge, and only
    // against a triangle it shares nothing with.
    if (shared > 0 || (da && db)) return false;
    const UK::Triangle_3& d = da ? ta : tb;
    int k = 0;
    for (int i = 1; i < 3; ++i) {
      if (CGAL::squared_distance(d[i], d[(i + 1) % 3]) >
          CGAL::squared_distance(d[k], d[(k + 1) % 3]))
        k = i;
    }
    if (d[k] == d[(k + 1) % 3]) return false;
    return CGAL::do_intersect(UK::Segment_3(d[k], d[(k + 1) % 3]), da ? tb : ta);
  }
  if (shared == 0) return CGAL::do_intersect(ta, tb);
  if (shared == 1) {
    const UK::Segment_3 ea(ta[(ia[0] + 1) % 3], ta[(ia[0] + 2) % 3]);
    const UK::Segment_3 eb(tb[(ib[0] + 1) % 3], tb[(ib[0] + 2) % 3]);
    return CGAL::do_intersect(ea, tb) || CGAL::do_intersect(eb, ta);
  }
  const UK::Point_3& s = ta[ia[0]];
  const UK::Point_3& t = ta[ia[1]];
  const UK::Point_3& x = ta[3 - ia[0] - ia[1]];
  const UK::Point_3& y = tb[3 - ib[0] - ib[1]];
  return CGAL::coplanar(s, t, x, y) && CGAL::coplanar_orientation(s, t, x, y) == CGAL::POSITIVE;
}

void BoxGrid::Add(int id, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  ForCells(lo, hi, [&](uint64_t c) { cells_[c].push_back(id); });
}

std::vector<int> BoxGrid::Candidates(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
  std::vector<int> out;
  ForCells(lo, hi, [&](uint64_t c) {
    if (auto it = cells_.find(c); it != cells_.end())
      out.insert(out.end(), it->second.begin(), it->second.end());
  });
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

void BoxGrid::ForCells(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                       const std::function<void(uint64_t)>& f) const {
  int64_t l[3], h[3];
  for (int i = 0; i < 3; ++i) {
    l[i] = static_cast<int64_t>(std::floor(lo[i] * inv_cell_));
    h[i] = static_cast<int64_t>(std::floor(hi[i] * inv_cell_));
  }
  for (int64_t x = l[0]; x <= h[0]; ++x)
    for (int64_t y = l[1]; y <= h[1]; ++y)
      for (int64_t z = l[2]; z <= h[2]; ++z)
        f((static_cast<uint64_t>(x & 0x1fffff) << 42) |
          (static_cast<uint64_t>(y & 0x1fffff) << 21) | static_cast<uint64_t>(z & 0x1fffff));
}

// Untangle's moves: towards the centroid and the nearest few neighbours.
constexpr size_t kMoveTowardsNearest = 3;

UntangleCounts Untangle(WorkMesh& m, const std::vector<PlaneFrame>& frames, double max_edge_m,
                        double max_move_m, double res) {
  const double min_area = 1e-6 * res * res;
  const double min_area2 = 2e-6 * res * res;  // as TryCollapse's winding test
  UntangleCounts counts;
  if (max_edge_m <= 0 && max_move_m <= 0) return counts;
  for (int round = 0; round < 8; ++round) {
    BoxGrid grid(8 * res);
    auto add = [&](int t) {
      Eigen::Vector3d lo, hi;
      TriangleBox(m, m.tri[t], lo, hi);
      grid.Add(t, lo, hi);
    };
    for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
      if (m.alive[t]) add(t);
    }
    // The vertices of every triangle that meets another.
    std::vector<int> tangled;
    for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
      if (!m.alive[t]) continue;
      Eigen::Vector3d lo, hi;
      TriangleBox(m, m.tri[t], lo, hi);
      for (int o : AliveNear(m, grid, lo, hi)) {
        if (o <= t || !WorkTrianglesMeet(m, m.tri[t], m.tri[o])) continue;
        tangled.insert(tangled.end(), m.tri[t].begin(), m.tri[t].end());
        tangled.insert(tangled.end(), m.tri[o].begin(), m.tri[o].end());
      }
    }
    std::sort(tangled.begin(), tangled.end());
    tangled.erase(std::unique(tangled.begin(), tangled.end()), tangled.end());
    int changed = 0;
    for (int u : tangled) {
      if (!m.vertex_alive[u]) continue;
      std::vector<int> nbrs = Neighbours(m, u);
      std::stable_sort(nbrs.begin(), nbrs.end(), [&](int a, int b) {
        return (m.pos[a] - m.pos[u]).squaredNorm() < (m.pos[b] - m.pos[u]).squaredNorm();
      });
      // Every triangle a collapse or move of u can reach: within the box of u's two rings,
      // grown by the longest move.
      Eigen::Vector3d lo = m.pos[u], hi = m.pos[u];
      for (int w : nbrs) {
        for (int t : m.Tris(w))
          for (int x : m.tri[t]) {
            lo = lo.cwiseMin(m.pos[x]);
            hi = hi.cwiseMax(m.pos[x]);
          }
      }
      lo.array() -= max_move_m;
      hi.array() += max_move_m;
      std::vector<Nearby> near;
      for (int t : AliveNear(m, grid, lo, hi)) {
        Nearby o{t, {}, {}};
        TriangleBox(m, m.tri[t], o.lo, o.hi);
        near.push_back(o);
      }
      std::vector<std::pair<int, std::array<int, 3>>> star;
      for (int t : m.Tris(u)) star.push_back({t, m.tri[t]});
      bool done = false;
      for (int v : nbrs) {
        if ((m.pos[v] - m.pos[u]).norm() > max_edge_m) break;
        std::vector<std::pair<int, std::array<int, 3>>> before = star, after;
        std::vector<int> shared;
        for (int t : m.Tris(v)) {
          const auto& x = m.tri[t];
          if (x[0] == u || x[1] == u || x[2] == u) {
            shared.push_back(t);
          } else {
            before.push_back({t, x});
            after.push_back({t, x});
          }
        }
        for (const auto& [t, x0] : star) {
          if (std::find(shared.begin(), shared.end(), t) != shared.end()) continue;
          std::array<int, 3> x = x0;
          for (int& w : x)
            if (w == u) w = v;
          after.push_back({t, x});
        }
        const int n_before = MeetingPairs(m, near, before, {});
        if (n_before == 0 || MeetingPairs(m, near, after, shared, n_before) >= n_before) continue;
        if (!TryCollapse(m, frames, u, v, min_area, res)) continue;
        for (int t : m.Tris(v)) add(t);
        ++counts.collapses;
        done = true;
        break;
      }
      if (done) {
        ++changed;
        continue;
      }
      if (max_move_m <= 0) continue;
      // No collapse helps: move u part of the way towards its neighbours' centroid or one of
      // the nearest of them, as far as no triangle around it gets worse below min_area in its
      // region's plane and its regions do not wrap around it (TryCollapse's conditions).
      const int n_before = MeetingPairs(m, near, star, {});
      if (n_before == 0) continue;
      const Eigen::Vector3d from = m.pos[u];
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      for (int w : nbrs) centroid += m.pos[w];
      std::vector<Eigen::Vector3d> targets = {centroid / std::max<size_t>(nbrs.size(), 1)};
      for (size_t i = 0; i < nbrs.size() && i < kMoveTowardsNearest; ++i) {
        targets.push_back(m.pos[nbrs[i]]);
      }
      std::vector<double> area_before;
      for (const auto& [t, x] : star) {
        area_before.push_back(SignedArea(m, frames, m.tri_region[t], x[0], x[1], x[2]));
      }
      for (size_t k = 0; k < targets.size() && !done; ++k) {
        for (double f : {0.1, 0.25, 0.5}) {
          const Eigen::Vector3d to = from + f * (targets[k] - from);
          if ((to - from).norm() > max_move_m) break;
          m.pos[u] = to;
          bool ok = true;
          for (size_t i = 0; i < star.size() && ok; ++i) {
            const auto& x = star[i].second;
            const double a = SignedArea(m, frames, m.tri_region[star[i].first], x[0], x[1], x[2]);
            ok = a >= min_area || a >= area_before[i];
          }
          ok = ok && MeetingPairs(m, near, star, {}, n_before) < n_before;
          // No region may wrap around u or a neighbour that it did not wrap around before.
          for (size_t i = 0; i <= nbrs.size() && ok; ++i) {
            const int w = i < nbrs.size() ? nbrs[i] : u;
            if (!Overwound(m, frames, w, min_area2)) continue;
            m.pos[u] = from;
            ok = Overwound(m, frames, w, min_area2);
            m.pos[u] = to;
          }
          if (ok) {
            for (const auto& [t, x] : star) add(t);
            ++counts.moves;
            done = true;
            break;
          }
          m.pos[u] = from;
        }
      }
      changed += done;
    }
    // Later rounds find less and less to do, at the cost of a whole round each.
    if (changed * 50 < static_cast<int>(tangled.size())) break;
  }
  return counts;
}

PlaneFrame FrameOf(const PlanarRegion& region) {
  PlaneFrame f;
  f.c = region.centroid;
  f.n = region.normal.normalized();
  f.axis = 0;
  for (int a = 1; a < 3; ++a)
    if (std::abs(f.n[a]) > std::abs(f.n[f.axis])) f.axis = a;
  const bool positive = f.n[f.axis] > 0;
  f.up = Eigen::Vector3d::Unit(f.axis) * (positive ? 1.0 : -1.0);
  f.a1 = (f.axis + (positive ? 1 : 2)) % 3;
  f.a2 = (f.axis + (positive ? 2 : 1)) % 3;
  return f;
}

// Everything about the surface and its regions before simplification.
absl::StatusOr<WorkMesh> BuildWorkMesh(std::span<const BoundaryFace> faces,
                                       const PlanarRegionSet& regions,
                                       const std::vector<PlaneFrame>& frames,
                                       const PlanarMeshOptions& options, double res) {
  absl::StatusOr<FaceSurface> surface = BuildSurface(faces, res);
  if (!surface.ok()) return surface.status();
  const FaceSurface& s = *surface;
  const int num_corners = static_cast<int>(s.corner_vertex.size());
  auto region_of_corner = [&](int c) { return regions.face_region[s.corner_face[c]]; };
  std::vector<std::vector<int>> tv_regions(s.num_tv);
  for (int c = 0; c < num_corners; ++c) tv_regions[s.corner_tv[c]].push_back(region_of_corner(c));
  for (auto& list : tv_regions) {
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
  }
  // Region changes around each vertex: 2 for a vertex inside a chain between two regions.
  std::vector<int> out_count(s.num_tv, 0);
  for (int c = 0; c < num_corners; ++c) {
    if (region_of_corner(c) != region_of_corner(s.twin[c])) ++out_count[s.corner_tv[c]];
  }
  WorkMesh m;
  // Vertices where regions meet start at their octree corner and are moved to their eq 4.9
  // position afterwards (MoveWithoutFolds).
  std::vector<SharedVertex> shared;
  // About one vertex per lattice vertex and two triangles per face (a few more where faces
  // of different sizes meet): made at their size, as the work mesh is this stage's peak.
  m.Reserve(s.num_tv, 2 * faces.size());
  for (int v = 0; v < s.num_tv; ++v) {
    const Eigen::Vector3d x0 = s.lattice[s.tv_lattice[v]].cast<double>() * res;
    const std::vector<int>& regs = tv_regions[v];
    if (regs.size() == 1) {
      m.AddVertex(frames[regs[0]].Project(x0), WorkMesh::kInterior);
    } else {
      const WorkMesh::Kind k =
          regs.size() == 2 && out_count[v] == 2 ? WorkMesh::kChain : WorkMesh::kAnchor;
      const int v = m.AddVertex(x0, k);
      shared.push_back({v, {regs.begin(), regs.end()}});
    }
  }
  std::vector<std::vector<int>>().swap(tv_regions);
  // Two sheets may still share an edge when the faces around both of its ends are connected
  // (interior cells touching along the edge and joined through their other neighbours): give
  // each sheet its own midpoint on that edge.
  auto edge_key = [](int a, int b) {
    return (uint64_t{static_cast<uint32_t>(std::min(a, b))} << 32) |
           static_cast<uint32_t>(std::max(a, b));
  };
  // The edges used by more than two corners, found by sorting all the edges' keys once
  // (a sorted array of 8 bytes per corner, freed at once, rather than a hash map of all edges
  // held to the end): there are few of them.
  std::vector<uint64_t> shared_edges;
  {
    std::vector<uint64_t> keys(num_corners);
    for (int c = 0; c < num_corners; ++c)
      keys[c] = edge_key(s.corner_tv[c], s.corner_tv[s.Next(c)]);
    std::sort(keys.begin(), keys.end());
    ForEachRun(
        keys, [](uint64_t k) { return k; },
        [&](size_t i, size_t e) {
          if (e - i > 2) shared_edges.push_back(keys[i]);
        });
  }
  absl::flat_hash_map<int, int> midpoint;  // min(corner, twin) → vertex
  auto midpoint_of = [&](int c) {
    if (!std::binary_search(shared_edges.begin(), shared_edges.end(),
                            edge_key(s.corner_tv[c], s.corner_tv[s.Next(c)]))) {
      return -1;
    }
    const int k = std::min(c, s.twin[c]);
    auto it = midpoint.find(k);
    if (it != midpoint.end()) return it->second;
    const Eigen::Vector3d x0 =
        0.5 * res *
        (s.lattice[s.corner_vertex[c]] + s.lattice[s.corner_vertex[s.Next(c)]]).cast<double>();
    std::vector<int> regs{region_of_corner(c), region_of_corner(s.twin[c])};
    std::sort(regs.begin(), regs.end());
    regs.erase(std::unique(regs.begin(), regs.end()), regs.end());
    int v;
    if (regs.size() == 1) {
      v = m.AddVertex(frames[regs[0]].Project(x0), WorkMesh::kInterior);
    } else {
      v = m.AddVertex(x0, WorkMesh::kChain);
      shared.push_back({v, {regs.begin(), regs.end()}});
    }
    midpoint[k] = v;
    return v;
  };
  for (size_t f = 0; f < faces.size(); ++f) {
    const int r = regions.face_region[f];
    std::vector<int> poly;
    for (int c = s.poly_start[f]; c < s.poly_start[f + 1]; ++c) {
      poly.push_back(s.corner_tv[c]);
      if (const int mid = midpoint_of(c); mid >= 0) poly.push_back(mid);
    }
    const int n = static_cast<int>(poly.size());
    if (n == 4) {
      m.AddTriangle(poly[0], poly[1], poly[2], r);
      m.AddTriangle(poly[0], poly[2], poly[3], r);
    } else {
      // A face with T-junction vertices on its sides: a fan around its centre.
      const int center = m.AddVertex(frames[r].Project(faces[f].center), WorkMesh::kInterior);
      for (int i = 0; i < n; ++i) m.AddTriangle(center, poly[i], poly[(i + 1) % n], r);
    }
  }
  // The surface's corners and the edges' midpoints are not read by the moves, whose own
  // buffers come on top of the work mesh: freed first, as the moves are this stage's peak.
  *surface = FaceSurface{};
  absl::flat_hash_map<int, int>().swap(midpoint);
  std::vector<uint64_t>().swap(shared_edges);
  MoveWithoutFolds(m, frames, shared, regions, options, res);
  return m;
}

// Chains first, while the regions' interiors are still fine (collapsing interiors first would
// leave triangles spanning three vertices of one straight chain, which block its collapse),
// then interiors, until nothing changes.
void Simplify(WorkMesh& m, const std::vector<PlaneFrame>& frames, double tolerance_m, double res) {
  const double min_area = 1e-6 * res * res;
  auto pass = [&](WorkMesh::Kind kind) {
    int collapsed = 0;
    for (int u = 0; u < static_cast<int>(m.pos.size()); ++u) {
      if (!m.vertex_alive[u] || m.kind[u] != kind) continue;
      std::vector<int> nbrs = Neighbours(m, u);
      if (kind == WorkMesh::kAnchor) {
        // Several octree corners placed on one point (noisy corners where three planes meet):
        // merge them, which changes no geometry.
        for (int v : nbrs) {
          if ((m.pos[v] - m.pos[u]).norm() < kCoincidentCells * res &&
              TryCollapse(m, frames, u, v, min_area, res)) {
            ++collapsed;
            break;
          }
        }
      } else if (kind == WorkMesh::kChain) {
        // Along its chain only, and only when the chain moves less than the tolerance.
        std::vector<int> chain;
        for (int w : nbrs)
          if (IsRegionEdge(m, u, w)) chain.push_back(w);
        if (chain.size() != 2) continue;
        for (int i = 0; i < 2; ++i) {
          const int v = chain[i], w = chain[1 - i];
          if (DistanceToSegment(m.pos[u], m.pos[w], m.pos[v]) > tolerance_m) continue;
          if (TryCollapse(m, frames, u, v, min_area, res)) {
            ++collapsed;
            break;
          }
        }
      } else {
        std::stable_sort(nbrs.begin(), nbrs.end(), [&](int a, int b) {
          return (m.pos[a] - m.pos[u]).squaredNorm() < (m.pos[b] - m.pos[u]).squaredNorm();
        });
        for (int v : nbrs) {
          if (TryCollapse(m, frames, u, v, min_area, res)) {
            ++collapsed;
            break;
          }
        }
      }
    }
    return collapsed;
  };
  auto rounds = [&] {
    for (int round = 0; round < 32; ++round) {
      int changed = 0;
      changed += pass(WorkMesh::kAnchor);
      for (int i = 0; i < 8; ++i) {
        const int n = pass(WorkMesh::kChain);
        changed += n;
        if (n == 0) break;
      }
      for (int i = 0; i < 8; ++i) {
        const int n = pass(WorkMesh::kInterior);
        changed += n;
        if (n == 0) break;
      }
      if (changed == 0) break;
    }
  };
  rounds();
  // Vertices that could not reach their eq 4.9 position on the fine mesh try again on the
  // coarser one, which may then simplify further.
  for (int i = 0; i < 4 && ResumeMoves(m, frames, res) > 0; ++i) rounds();
  std::vector<WorkMesh::Move>().swap(m.moves);
  // Last resort for triangles left without area (their vertices were placed onto one line or
  // point): collapse one of their edges whatever the vertices' kinds, which moves a region
  // border by at most that edge.
  for (int round = 0; round < 8; ++round) {
    int fixed = 0;
    for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
      if (!m.alive[t]) continue;
      const auto x = m.tri[t];
      if (!Flat(m, x, min_area, res)) continue;
      if (FlipLongestEdge(m, frames, t, min_area)) {
        ++fixed;
        continue;
      }
      for (int i = 0; i < 3 && m.alive[t]; ++i) {
        const int a = x[i], b = x[(i + 1) % 3];
        if (TryCollapse(m, frames, a, b, min_area, res) ||
            TryCollapse(m, frames, b, a, min_area, res))
          ++fixed;
      }
    }
    if (fixed == 0) break;
  }
  // Still flat (a vertex wedged between two others on one line, with a chain on each side):
  // collapse the shortest edge even where a triangle around it then loses its area, but not
  // by more than a thousandth of a cell (a fold of that size can cross a neighbour) and not
  // where a region would wrap around a vertex.
  for (int round = 0; round < 8; ++round) {
    int fixed = 0;
    for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
      if (!m.alive[t]) continue;
      const auto x = m.tri[t];
      if (!Flat(m, x, min_area, res)) continue;
      std::array<int, 3> order = {0, 1, 2};
      std::sort(order.begin(), order.end(), [&](int i, int j) {
        return (m.pos[x[(i + 1) % 3]] - m.pos[x[i]]).squaredNorm() <
               (m.pos[x[(j + 1) % 3]] - m.pos[x[j]]).squaredNorm();
      });
      for (int i : order) {
        const int a = x[i], b = x[(i + 1) % 3];
        const double hardly = -1e-3 * res * res;
        if (TryCollapse(m, frames, a, b, hardly, res) ||
            TryCollapse(m, frames, b, a, hardly, res)) {
          ++fixed;
          break;
        }
      }
    }
    if (fixed == 0) break;
  }
  // Whatever is still flat (two sheets' vertices on one point, or a vertex exactly between
  // two others with no collapse allowed) gets a nudge of 1% of a cell towards the middle of
  // its neighbours: geometry unchanged at any visible scale, and no zero-area triangle.
  for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
    if (!m.alive[t] || !Flat(m, m.tri[t], min_area, res)) continue;
    const auto x = m.tri[t];
    int pick = x[0];
    for (int v : x)
      if (m.kind[v] < m.kind[pick]) pick = v;
    for (int i = 0; i < 3; ++i) {  // a zero-length edge: move one of its ends
      const int a = x[i], b = x[(i + 1) % 3];
      if ((m.pos[a] - m.pos[b]).norm() < kCoincidentCells * res)
        pick = m.kind[a] <= m.kind[b] ? a : b;
    }
    Eigen::Vector3d mid = Eigen::Vector3d::Zero();
    int n = 0;
    for (int u : m.Tris(pick)) {
      for (int w : m.tri[u])
        if (w != pick) mid += m.pos[w], ++n;
    }
    Eigen::Vector3d dir = n > 0 ? Eigen::Vector3d(mid / n - m.pos[pick]) : Eigen::Vector3d::Zero();
    if (dir.norm() < 1e-9) dir = Eigen::Vector3d::Unit(frames[m.tri_region[t]].a1);
    m.pos[pick] += 0.01 * res * dir.normalized();
  }
  // Tiny closed pieces that still have a flat or folded triangle, or enclose less than one grid
  // cell (a pocket of one or two cells whose corners were placed onto nearly parallel planes,
  // e.g. a floor and the pocket's top) are dropped whole: they are carving noise, and the rest
  // stays closed. RepairPlanarMesh applies the volume test again after re-triangulation.
  const std::vector<int> drop = TinyPieces(
      static_cast<int>(m.tri.size()), [&](int t) { return m.tri[t]; },
      [&](int t) { return m.alive[t] != 0; }, [&](int v) { return m.pos[v]; },
      [&](int t) {
        const auto& x = m.tri[t];
        return Flat(m, x, min_area, res) ||
               SignedArea(m, frames, m.tri_region[t], x[0], x[1], x[2]) < min_area;
      },
      res);
  for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
    if (drop[t] >= 0) m.alive[t] = 0;
  }
}

}  // namespace carvemap::planar_mesh_internal
