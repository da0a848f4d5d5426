#include "services/mesh/planar_mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <deque>
#include <exception>
#include <functional>
#include <limits>
#include <numeric>
#include <utility>

#include <Eigen/SVD>

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include "absl/container/flat_hash_map.h"
#include "absl/container/inlined_vector.h"
#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "services/geometry/sorted_runs.h"
#include "services/mesh/face_surface.h"
#include "services/mesh/mesh_checks.h"
#include "services/mesh/planar_mesh_repair.h"

namespace carvemap {

absl::Status PlanarMeshOptions::Validate() const {
  if (!(alpha_fraction >= 0 && alpha_fraction <= 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("planar_mesh: alpha_fraction must be in [0, 1], got ", alpha_fraction));
  }
  if (!(max_displacement_cells > 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "planar_mesh: max_displacement_cells must be > 0, got ", max_displacement_cells));
  }
  if (!(chain_tolerance_cells >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "planar_mesh: chain_tolerance_cells must be >= 0, got ", chain_tolerance_cells));
  }
  if (min_quadtree_cells < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("planar_mesh: min_quadtree_cells must be >= 1, got ", min_quadtree_cells));
  }
  return absl::OkStatus();
}

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
struct CdtFaceInfo {
  int nesting = -1;
};
// tv: the boundary vertex (−1 for a quadtree point); out: a quadtree point's output vertex.
struct CdtVertexInfo {
  int tv = -1;
  int out = -1;
  int pid = -1;
  bool used = false;
  bool ambiguous = false;
};
using CdtVb = CGAL::Triangulation_vertex_base_with_info_2<CdtVertexInfo, K>;
using CdtFbInfo = CGAL::Triangulation_face_base_with_info_2<CdtFaceInfo, K>;
using CdtFb = CGAL::Constrained_triangulation_face_base_2<K, CdtFbInfo>;
using CdtTds = CGAL::Triangulation_data_structure_2<CdtVb, CdtFb>;
// Constraints are the regions' boundary chains, which must not cross or touch each other except
// at their shared vertices: any intersection would add a vertex one neighbour does not have.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<K, CdtTds, CGAL::No_constraint_intersection_tag>;

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

struct Segment2 {
  Eigen::Vector2d a, b;
};

bool PointInside(const Eigen::Vector2d& q, const std::vector<Segment2>& segs) {
  bool inside = false;
  for (const Segment2& s : segs) {
    if ((s.a.y() > q.y()) != (s.b.y() > q.y())) {
      const double x = s.a.x() + (q.y() - s.a.y()) / (s.b.y() - s.a.y()) * (s.b.x() - s.a.x());
      if (x > q.x()) inside = !inside;
    }
  }
  return inside;
}

double DistanceToSegments(const Eigen::Vector2d& q, const std::vector<Segment2>& segs) {
  double best = std::numeric_limits<double>::infinity();
  for (const Segment2& s : segs) {
    const Eigen::Vector2d ab = s.b - s.a;
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0 ? std::clamp((q - s.a).dot(ab) / len2, 0.0, 1.0) : 0.0;
    best = std::min(best, (s.a + t * ab - q).norm());
  }
  return best;
}

// Whether segment s meets the open box (lo, hi) (Liang–Barsky clipping).
bool SegmentMeetsOpenBox(const Segment2& s, const Eigen::Vector2d& lo, const Eigen::Vector2d& hi) {
  double t0 = 0, t1 = 1;
  const Eigen::Vector2d d = s.b - s.a;
  for (int k = 0; k < 2; ++k) {
    if (std::abs(d[k]) < 1e-300) {
      if (s.a[k] <= lo[k] || s.a[k] >= hi[k]) return false;
      continue;
    }
    double ta = (lo[k] - s.a[k]) / d[k], tb = (hi[k] - s.a[k]) / d[k];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 >= t1) return false;
  }
  return true;
}

// §4.2.5, Fig 4.7b–c: a quadtree aligned to the region's grid whose leaves are the largest
// squares lying inside the region; their centres (and their corners away from the boundary)
// become interior vertices, so big regions get big triangles and the constrained Delaunay
// triangulation around them keeps its angles bounded.
void QuadtreePoints(const std::vector<Segment2>& segs, const Eigen::Vector2d& lo, double side,
                    double min_side, double res, std::vector<Eigen::Vector2d>& out,
                    absl::flat_hash_map<std::pair<int64_t, int64_t>, char>& seen) {
  if (side < min_side) return;
  const Eigen::Vector2d hi = lo + Eigen::Vector2d(side, side);
  const double eps = 1e-6 * res;
  const Eigen::Vector2d lo_in = lo + Eigen::Vector2d(eps, eps), hi_in = hi - Eigen::Vector2d(eps, eps);
  bool crossed = false;
  for (const Segment2& s : segs) {
    if (SegmentMeetsOpenBox(s, lo_in, hi_in)) {
      crossed = true;
      break;
    }
  }
  const Eigen::Vector2d center = lo + Eigen::Vector2d(0.5 * side, 0.5 * side);
  if (!crossed) {
    if (!PointInside(center, segs)) return;
    auto emit = [&](const Eigen::Vector2d& q) {
      const std::pair<int64_t, int64_t> key{std::llround(4 * q.x() / res), std::llround(4 * q.y() / res)};
      if (!seen.try_emplace(key, 1).second) return;
      out.push_back(q);
    };
    emit(center);
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector2d q = lo + side * Eigen::Vector2d(i & 1, i >> 1);
      if (DistanceToSegments(q, segs) > 0.25 * side && PointInside(q, segs)) emit(q);
    }
    return;
  }
  const double half = 0.5 * side;
  for (int i = 0; i < 4; ++i) {
    QuadtreePoints(segs, lo + half * Eigen::Vector2d(i & 1, i >> 1), half, min_side, res, out, seen);
  }
}

void MarkDomains(Cdt& cdt) {
  for (Cdt::Face_handle f : cdt.all_face_handles()) f->info().nesting = -1;
  std::deque<Cdt::Edge> border;
  auto flood = [&](Cdt::Face_handle start, int level) {
    std::deque<Cdt::Face_handle> queue{start};
    start->info().nesting = level;
    while (!queue.empty()) {
      Cdt::Face_handle f = queue.front();
      queue.pop_front();
      for (int i = 0; i < 3; ++i) {
        Cdt::Face_handle n = f->neighbor(i);
        if (n->info().nesting != -1) continue;
        if (cdt.is_constrained(Cdt::Edge(f, i))) {
          border.push_back(Cdt::Edge(f, i));
        } else {
          n->info().nesting = level;
          queue.push_back(n);
        }
      }
    }
  };
  flood(cdt.infinite_face(), 0);
  while (!border.empty()) {
    const Cdt::Edge e = border.front();
    border.pop_front();
    Cdt::Face_handle n = e.first->neighbor(e.second);
    if (n->info().nesting == -1) flood(n, e.first->info().nesting + 1);
  }
}

// Everything about the surface and its regions that does not depend on the simplification.

// The plane of a region with a right-handed basis: e1 × e2 = n, so counter-clockwise in 2D is
// counter-clockwise seen from free space.
struct PlaneFrame {
  Eigen::Vector3d c, n, e1, e2;
  [[nodiscard]] Eigen::Vector2d To2(const Eigen::Vector3d& x) const {
    return {(x - c).dot(e1), (x - c).dot(e2)};
  }
  [[nodiscard]] Eigen::Vector3d Project(const Eigen::Vector3d& x) const {
    return x - n * n.dot(x - c);
  }
};

PlaneFrame FrameOf(const PlanarRegion& region) {
  PlaneFrame f;
  f.c = region.centroid;
  f.n = region.normal.normalized();
  int least = 0;
  for (int a = 1; a < 3; ++a) if (std::abs(f.n[a]) < std::abs(f.n[least])) least = a;
  f.e1 = Eigen::Vector3d::Unit(least).cross(f.n).normalized();
  f.e2 = f.n.cross(f.e1);
  return f;
}

// The surface as triangles that are simplified by edge collapses. Every collapse keeps the mesh
// a closed manifold (link condition), so watertightness never depends on geometry.
struct WorkMesh {
  enum Kind : char { kInterior, kChain, kAnchor };
  std::vector<Eigen::Vector3d> pos;
  std::vector<char> kind;
  std::vector<char> vertex_alive;
  std::vector<std::array<int, 3>> tri;
  std::vector<int> tri_region;
  std::vector<char> alive;
  // A lattice vertex has about six triangles around it: kept inline, as one small heap block
  // per vertex would be the largest part of the work mesh.
  using TriList = absl::InlinedVector<int, 6>;
  std::vector<TriList> incident;  // may hold stale entries; see Tris()

  // Alive triangles around v (compacts the list).
  const TriList& Tris(int v) {
    TriList& list = incident[v];
    list.erase(std::remove_if(list.begin(), list.end(),
                              [&](int t) {
                                return !alive[t] || (tri[t][0] != v && tri[t][1] != v && tri[t][2] != v);
                              }),
               list.end());
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    return list;
  }
  int AddTriangle(int a, int b, int c, int region) {
    const int t = static_cast<int>(tri.size());
    tri.push_back({a, b, c});
    tri_region.push_back(region);
    alive.push_back(1);
    for (int v : {a, b, c}) incident[v].push_back(t);
    return t;
  }
  void Reserve(size_t vertices, size_t triangles) {
    pos.reserve(vertices);
    kind.reserve(vertices);
    vertex_alive.reserve(vertices);
    incident.reserve(vertices);
    tri.reserve(triangles);
    tri_region.reserve(triangles);
    alive.reserve(triangles);
  }
  int AddVertex(const Eigen::Vector3d& x, Kind k) {
    pos.push_back(x);
    kind.push_back(k);
    vertex_alive.push_back(1);
    incident.emplace_back();
    return static_cast<int>(pos.size()) - 1;
  }
};

double SignedArea(const WorkMesh& m, const std::vector<PlaneFrame>& frames, int region, int a, int b,
                  int c) {
  return 0.5 * frames[region].n.dot((m.pos[b] - m.pos[a]).cross(m.pos[c] - m.pos[a]));
}

// Collapses u into v when that keeps the surface a manifold and no triangle gets worse than
// `min_area` in its region's plane (§4.2.5: the chains stay where the regions meet).
bool TryCollapse(WorkMesh& m, const std::vector<PlaneFrame>& frames, int u, int v, double min_area) {
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
    for (int w : m.tri[t]) if (w != u && w != v) opposite.push_back(w);
  }
  if (opposite.size() != 2 || opposite[0] == opposite[1]) return false;
  std::vector<int> nu, nv;
  for (int t : tu) for (int w : m.tri[t]) if (w != u && w != v) nu.push_back(w);
  for (int t : m.Tris(v)) for (int w : m.tri[t]) if (w != u && w != v) nv.push_back(w);
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
    for (int& w : x) if (w == u) w = v;
    const double after = SignedArea(m, frames, m.tri_region[t], x[0], x[1], x[2]);
    if (after < min_area && after < before) return false;
  }
  for (int t : shared) m.alive[t] = 0;
  for (int t : moved) {
    for (int& w : m.tri[t]) if (w == u) w = v;
    m.incident[v].push_back(t);
  }
  m.vertex_alive[u] = 0;
  m.incident[u].clear();
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
  if ((m.pos[x[1]] - m.pos[x[0]]).cross(m.pos[x[2]] - m.pos[x[0]]).norm() <= 2 * min_area) return true;
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
    for (int w : m.tri[u]) if (w == d) return false;  // c–d is already an edge
  }
  const int r = m.tri_region[t];
  if (SignedArea(m, frames, r, a, d, c) < min_area || SignedArea(m, frames, r, d, b, c) < min_area) {
    return false;
  }
  m.tri[t] = {a, d, c};
  m.tri[other] = {d, b, c};
  m.incident[d].push_back(t);
  m.incident[c].push_back(other);
  return true;
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
      std::vector<int> nbrs;
      for (int t : m.Tris(u)) for (int w : m.tri[t]) if (w != u) nbrs.push_back(w);
      std::sort(nbrs.begin(), nbrs.end());
      nbrs.erase(std::unique(nbrs.begin(), nbrs.end()), nbrs.end());
      if (kind == WorkMesh::kAnchor) {
        // Several octree corners placed on one point (noisy corners where three planes meet):
        // merge them, which changes no geometry.
        for (int v : nbrs) {
          if ((m.pos[v] - m.pos[u]).norm() < kCoincidentCells * res &&
              TryCollapse(m, frames, u, v, min_area)) {
            ++collapsed;
            break;
          }
        }
      } else if (kind == WorkMesh::kChain) {
        // Along its chain only, and only when the chain moves less than the tolerance.
        std::vector<int> chain;
        for (int w : nbrs) if (IsRegionEdge(m, u, w)) chain.push_back(w);
        if (chain.size() != 2) continue;
        for (int i = 0; i < 2; ++i) {
          const int v = chain[i], w = chain[1 - i];
          if (DistanceToSegment(m.pos[u], m.pos[w], m.pos[v]) > tolerance_m) continue;
          if (TryCollapse(m, frames, u, v, min_area)) {
            ++collapsed;
            break;
          }
        }
      } else {
        std::stable_sort(nbrs.begin(), nbrs.end(), [&](int a, int b) {
          return (m.pos[a] - m.pos[u]).squaredNorm() < (m.pos[b] - m.pos[u]).squaredNorm();
        });
        for (int v : nbrs) {
          if (TryCollapse(m, frames, u, v, min_area)) {
            ++collapsed;
            break;
          }
        }
      }
    }
    return collapsed;
  };
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
        if (TryCollapse(m, frames, a, b, min_area) || TryCollapse(m, frames, b, a, min_area)) ++fixed;
      }
    }
    if (fixed == 0) break;
  }
  // Still flat (a vertex wedged between two others on one line, with a chain on each side):
  // collapse the shortest edge on topology alone. The triangles around it are about as small
  // as the flat one, so any fold this leaves is of that size.
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
        const double no_check = -std::numeric_limits<double>::infinity();
        if (TryCollapse(m, frames, a, b, no_check) || TryCollapse(m, frames, b, a, no_check)) {
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
    for (int v : x) if (m.kind[v] < m.kind[pick]) pick = v;
    for (int i = 0; i < 3; ++i) {  // a zero-length edge: move one of its ends
      const int a = x[i], b = x[(i + 1) % 3];
      if ((m.pos[a] - m.pos[b]).norm() < kCoincidentCells * res) pick = m.kind[a] <= m.kind[b] ? a : b;
    }
    Eigen::Vector3d mid = Eigen::Vector3d::Zero();
    int n = 0;
    for (int u : m.Tris(pick)) {
      for (int w : m.tri[u]) if (w != pick) mid += m.pos[w], ++n;
    }
    Eigen::Vector3d dir = n > 0 ? Eigen::Vector3d(mid / n - m.pos[pick]) : Eigen::Vector3d::Zero();
    if (dir.norm() < 1e-9) dir = frames[m.tri_region[t]].e1;
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

// Re-triangulates one region of the simplified mesh in its plane: its boundary edges (the
// shared chains) as constraints plus quadtree points (§4.2.5). Returns false (and adds nothing)
// when the boundary is not a valid polygon in the plane; the caller keeps the collapsed
// triangles then.
bool RetriangulateRegion(const WorkMesh& m, const PlaneFrame& frame,
                         const std::vector<std::pair<int, int>>& segs, bool quadtree,
                         int min_quadtree_cells, double res,
                         std::vector<std::array<int, 3>>& tris_out,
                         std::vector<Eigen::Vector3d>& steiner_out) {
  std::vector<Segment2> segs2;
  for (auto [a, b] : segs) segs2.push_back({frame.To2(m.pos[a]), frame.To2(m.pos[b])});
  Cdt cdt;
  absl::flat_hash_map<int, Cdt::Vertex_handle> handle;
  // Two vertices of one region may project to one point (an octree corner split into two
  // sheets where two parts of the region touch); a triangle there takes the sheet of the
  // nearest constraint around it, looked up by the CGAL vertices' ids.
  absl::flat_hash_map<uint64_t, int> end_vertex;
  int num_points = 0;
  std::vector<Cdt::Vertex_handle> steiner;
  try {
    for (auto [a, b] : segs) {
      for (int w : {a, b}) {
        if (handle.contains(w)) continue;
        const Eigen::Vector2d q = frame.To2(m.pos[w]);
        Cdt::Vertex_handle vh = cdt.insert(K::Point_2(q.x(), q.y()));
        if (!vh->info().used) {
          vh->info().used = true;
          vh->info().tv = w;
          vh->info().pid = num_points++;
        } else if (vh->info().tv != w) {
          vh->info().ambiguous = true;
        }
        handle[w] = vh;
      }
      const uint64_t pa = static_cast<uint32_t>(handle[a]->info().pid);
      const uint64_t pb = static_cast<uint32_t>(handle[b]->info().pid);
      end_vertex[(pa << 32) | pb] = a;
      end_vertex[(pb << 32) | pa] = b;
    }
    for (auto [a, b] : segs) {
      if (handle[a] == handle[b]) return false;  // a chain edge of zero length in the plane
    }
    for (auto [a, b] : segs) cdt.insert_constraint(handle[a], handle[b]);
    if (quadtree) {
      Eigen::Vector2d lo = segs2[0].a, hi = segs2[0].a;
      for (const Segment2& s : segs2) {
        lo = lo.cwiseMin(s.a).cwiseMin(s.b);
        hi = hi.cwiseMax(s.a).cwiseMax(s.b);
      }
      const double extent = (hi - lo).maxCoeff();
      double side = res;
      while (side < extent) side *= 2;
      absl::flat_hash_map<std::pair<int64_t, int64_t>, char> seen;
      std::vector<Eigen::Vector2d> extra;
      QuadtreePoints(segs2, lo, side, min_quadtree_cells * res, res, extra, seen);
      for (const Eigen::Vector2d& q : extra) {
        Cdt::Vertex_handle vh = cdt.insert(K::Point_2(q.x(), q.y()));
        if (vh->info().used) return false;
        vh->info().used = true;
        steiner.push_back(vh);
      }
    }
  } catch (const std::exception&) {
    return false;  // constraints cross
  }
  MarkDomains(cdt);
  std::vector<std::array<int, 3>> tris;
  int next_steiner = -2;  // Steiner points are numbered −2, −3, … until they are emitted
  std::vector<Eigen::Vector3d> steiner_pos;
  for (Cdt::Face_handle f : cdt.finite_face_handles()) {
    if (f->info().nesting % 2 != 1) continue;
    std::array<int, 3> t;
    for (int i = 0; i < 3; ++i) {
      Cdt::Vertex_handle vh = f->vertex(i);
      if (vh->info().ambiguous) {
        // Turn around the vertex until a constraint: its end here names the sheet.
        Cdt::Face_handle g = f;
        int j = i, w = -1;
        for (int step = 0; step < 10000 && w < 0; ++step) {
          if (cdt.is_constrained(Cdt::Edge(g, Cdt::cw(j)))) {
            const uint64_t pq = static_cast<uint32_t>(g->vertex(Cdt::ccw(j))->info().pid);
            auto it = end_vertex.find((static_cast<uint64_t>(vh->info().pid) << 32) | pq);
            if (it == end_vertex.end()) return false;
            w = it->second;
          } else {
            g = g->neighbor(Cdt::cw(j));
            j = g->index(vh);
          }
        }
        if (w < 0) return false;
        t[i] = w;
      } else if (vh->info().tv >= 0) {
        t[i] = vh->info().tv;
      } else {
        if (vh->info().out == -1) {
          vh->info().out = next_steiner--;
          const Eigen::Vector3d x = frame.c + vh->point().x() * frame.e1 + vh->point().y() * frame.e2;
          steiner_pos.push_back(x);
        }
        t[i] = vh->info().out;
      }
    }
    tris.push_back(t);
  }
  // No sliver between nearly collinear chain vertices (the collapsed triangles are kept then).
  for (const auto& t : tris) {
    Eigen::Vector3d p[3];
    for (int i = 0; i < 3; ++i) p[i] = t[i] >= 0 ? m.pos[t[i]] : steiner_pos[-t[i] - 2];
    if ((p[1] - p[0]).cross(p[2] - p[0]).norm() <= 2e-6 * res * res) return false;
  }
  // The new triangles must have exactly the region's boundary as their boundary.
  absl::flat_hash_map<uint64_t, int> directed;
  auto key = [](int a, int b) {
    return (uint64_t{static_cast<uint32_t>(a)} << 32) | static_cast<uint32_t>(b);
  };
  for (const auto& t : tris) {
    for (int i = 0; i < 3; ++i) ++directed[key(t[i], t[(i + 1) % 3])];
  }
  absl::flat_hash_map<uint64_t, char> seg_set;
  for (auto [a, b] : segs) seg_set[key(a, b)] = 1;
  for (const auto& [k, n] : directed) {
    if (n != 1) return false;
    const int a = static_cast<int>(k >> 32), b = static_cast<int>(k & 0xffffffffu);
    const bool reverse = directed.contains(key(b, a));
    if (reverse == seg_set.contains(k)) return false;  // boundary iff a constraint
  }
  for (auto [a, b] : segs) {
    if (!directed.contains(key(a, b))) return false;
  }
  const int base = static_cast<int>(steiner_out.size());
  for (auto& t : tris) {
    for (int& w : t) if (w <= -2) w = -(base + (-w - 2)) - 2;
    tris_out.push_back(t);
  }
  steiner_out.insert(steiner_out.end(), steiner_pos.begin(), steiner_pos.end());
  return true;
}

// Everything about the surface and its regions before simplification.
absl::StatusOr<WorkMesh> BuildWorkMesh(std::span<const BoundaryFace> faces, const PlanarRegionSet& regions,
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
  // About one vertex per lattice vertex and two triangles per face (a few more where faces
  // of different sizes meet): made at their size, as the work mesh is this stage's peak.
  m.Reserve(s.num_tv, 2 * faces.size());
  for (int v = 0; v < s.num_tv; ++v) {
    const Eigen::Vector3d x0 = s.lattice[s.tv_lattice[v]].cast<double>() * res;
    const std::vector<int>& regs = tv_regions[v];
    if (regs.size() == 1) {
      m.AddVertex(frames[regs[0]].Project(x0), WorkMesh::kInterior);
    } else {
      const WorkMesh::Kind k = regs.size() == 2 && out_count[v] == 2 ? WorkMesh::kChain : WorkMesh::kAnchor;
      m.AddVertex(PlaceVertex(x0, regs, regions, options, res), k);
    }
  }
  std::vector<std::vector<int>>().swap(tv_regions);
  // Two sheets may still share an edge when the faces around both of its ends are connected
  // (interior cells touching along the edge and joined through their other neighbours): give
  // each sheet its own midpoint on that edge.
  auto edge_key = [](int a, int b) {
    return (uint64_t{static_cast<uint32_t>(std::min(a, b))} << 32) | static_cast<uint32_t>(std::max(a, b));
  };
  // The edges used by more than two corners, found by sorting all the edges' keys once
  // (a sorted array of 8 bytes per corner, freed at once, rather than a hash map of all edges
  // held to the end): there are few of them.
  std::vector<uint64_t> shared_edges;
  {
    std::vector<uint64_t> keys(num_corners);
    for (int c = 0; c < num_corners; ++c) keys[c] = edge_key(s.corner_tv[c], s.corner_tv[s.Next(c)]);
    std::sort(keys.begin(), keys.end());
    ForEachRun(keys, [](uint64_t k) { return k; }, [&](size_t i, size_t e) {
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
        0.5 * res * (s.lattice[s.corner_vertex[c]] + s.lattice[s.corner_vertex[s.Next(c)]]).cast<double>();
    std::vector<int> regs{region_of_corner(c), region_of_corner(s.twin[c])};
    std::sort(regs.begin(), regs.end());
    regs.erase(std::unique(regs.begin(), regs.end()), regs.end());
    const int v = regs.size() == 1
                      ? m.AddVertex(frames[regs[0]].Project(x0), WorkMesh::kInterior)
                      : m.AddVertex(PlaceVertex(x0, regs, regions, options, res), WorkMesh::kChain);
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
  return m;
}

// Directed edge (a, b) as a key; undirected when a < b.
uint64_t EdgeKey(int a, int b) {
  return (uint64_t{static_cast<uint32_t>(a)} << 32) | static_cast<uint32_t>(b);
}
uint64_t UndirectedKey(int a, int b) { return EdgeKey(std::min(a, b), std::max(a, b)); }

absl::Status CheckFaceRegions(std::span<const BoundaryFace> faces, const PlanarRegionSet& regions) {
  if (regions.face_region.size() != faces.size()) {
    return absl::InvalidArgumentError(absl::StrCat("planar_mesh: ", faces.size(), " faces but ",
                                                   regions.face_region.size(), " face regions"));
  }
  const int num_regions = static_cast<int>(regions.regions.size());
  for (size_t f = 0; f < faces.size(); ++f) {
    if (regions.face_region[f] < 0 || regions.face_region[f] >= num_regions) {
      return absl::InvalidArgumentError(absl::StrCat("planar_mesh: face ", f, " has region ",
                                                     regions.face_region[f], " of ", num_regions));
    }
  }
  return absl::OkStatus();
}

// Each region of the simplified mesh: its triangles, and its boundary as directed edges
// (counter-clockwise about the region's normal) whose twin lies in another region.
struct RegionOutlines {
  std::vector<std::vector<std::pair<int, int>>> segs;
  std::vector<std::vector<int>> tris;
};

absl::StatusOr<RegionOutlines> OutlinesOf(const WorkMesh& m, int num_regions) {
  absl::flat_hash_map<uint64_t, int> edge_tri;
  for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
    if (!m.alive[t]) continue;
    for (int i = 0; i < 3; ++i) edge_tri[EdgeKey(m.tri[t][i], m.tri[t][(i + 1) % 3])] = t;
  }
  RegionOutlines out;
  out.segs.resize(num_regions);
  out.tris.resize(num_regions);
  for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
    if (!m.alive[t]) continue;
    const int r = m.tri_region[t];
    out.tris[r].push_back(t);
    for (int i = 0; i < 3; ++i) {
      const int a = m.tri[t][i], b = m.tri[t][(i + 1) % 3];
      auto it = edge_tri.find(EdgeKey(b, a));
      if (it == edge_tri.end()) return absl::InternalError("planar_mesh: simplified mesh is open");
      if (m.tri_region[it->second] != r) out.segs[r].push_back({a, b});
    }
  }
  return out;
}

// How many triangles' edges join each pair of vertices of the simplified mesh, kept current
// as regions are re-triangulated: a region's new triangulation must not add an edge that
// another region already has (two regions joining the same two corners would make the mesh
// non-manifold).
class EdgeUsers {
 public:
  // `m` closed (OutlinesOf checked it): each edge is counted once, from its a < b side.
  explicit EdgeUsers(const WorkMesh& m) {
    for (int t = 0; t < static_cast<int>(m.tri.size()); ++t) {
      if (!m.alive[t]) continue;
      for (int i = 0; i < 3; ++i) {
        const int a = m.tri[t][i], b = m.tri[t][(i + 1) % 3];
        if (a < b) ++count_[UndirectedKey(a, b)];
      }
    }
  }

  // Replaces the inner edges of `old_tris` by those of `new_tris` (both of one region whose
  // boundary is `segs`; negative ids are new Steiner points, whose edges are new) when no new
  // inner edge is already in use elsewhere; false, and nothing changed, otherwise.
  bool TryReplace(std::span<const std::pair<int, int>> segs,
                  std::span<const std::array<int, 3>> old_tris,
                  std::span<const std::array<int, 3>> new_tris) {
    absl::flat_hash_map<uint64_t, char> boundary;
    for (auto [a, b] : segs) boundary[UndirectedKey(a, b)] = 1;
    const auto inner = [&](std::span<const std::array<int, 3>> tris) {
      std::vector<uint64_t> e;
      for (const auto& t : tris) {
        for (int i = 0; i < 3; ++i) {
          const int a = t[i], b = t[(i + 1) % 3];
          if (a >= 0 && a < b && !boundary.contains(UndirectedKey(a, b))) {
            e.push_back(UndirectedKey(a, b));
          }
        }
      }
      return e;
    };
    const std::vector<uint64_t> old_inner = inner(old_tris), new_inner = inner(new_tris);
    for (uint64_t e : old_inner) --count_[e];
    bool free = true;
    for (uint64_t e : new_inner) free = free && count_[e] <= 0;
    for (uint64_t e : free ? new_inner : old_inner) ++count_[e];
    return free;
  }

 private:
  absl::flat_hash_map<uint64_t, int> count_;
};

// The output mesh: each region re-triangulated in its plane (RetriangulateRegion) where its
// outline allows and no edge would be shared with another region, else its simplified
// triangles as they are.
PlanarMesh Retriangulate(const WorkMesh& m, const std::vector<PlaneFrame>& frames,
                         const RegionOutlines& outlines, const PlanarMeshOptions& options,
                         double res) {
  PlanarMesh out;
  std::vector<int> out_vertex(m.pos.size(), -1);
  const auto vertex_id = [&](int v) {
    if (out_vertex[v] < 0) {
      out_vertex[v] = static_cast<int>(out.mesh.vertices.size());
      out.mesh.vertices.push_back(m.pos[v].cast<float>());
    }
    return out_vertex[v];
  };
  EdgeUsers users(m);
  for (int r = 0; r < static_cast<int>(outlines.tris.size()); ++r) {
    std::vector<std::array<int, 3>> old_tris;
    for (int t : outlines.tris[r]) old_tris.push_back(m.tri[t]);
    std::vector<std::array<int, 3>> tris;
    std::vector<Eigen::Vector3d> steiner;
    const bool remeshed = !outlines.segs[r].empty() &&
                          RetriangulateRegion(m, frames[r], outlines.segs[r],
                                              options.quadtree_points, options.min_quadtree_cells,
                                              res, tris, steiner) &&
                          users.TryReplace(outlines.segs[r], old_tris, tris);
    if (!remeshed) {
      tris = std::move(old_tris);
      steiner.clear();
    }
    std::vector<int> steiner_id(steiner.size(), -1);
    for (const auto& t : tris) {
      Eigen::Vector3i o;
      for (int i = 0; i < 3; ++i) {
        if (t[i] >= 0) {
          o[i] = vertex_id(t[i]);
          continue;
        }
        const int s = -t[i] - 2;
        if (steiner_id[s] < 0) {
          steiner_id[s] = static_cast<int>(out.mesh.vertices.size());
          out.mesh.vertices.push_back(steiner[s].cast<float>());
        }
        o[i] = steiner_id[s];
      }
      out.mesh.triangles.push_back(o);
      out.triangle_region.push_back(r);
    }
  }
  return out;
}

}  // namespace

absl::StatusOr<PlanarMesh> BuildPlanarMesh(std::span<const BoundaryFace> faces,
                                           const PlanarRegionSet& regions, const OctreeGrid& grid,
                                           const PlanarMeshOptions& options) {
  if (absl::Status st = options.Validate(); !st.ok()) return st;
  if (absl::Status st = CheckFaceRegions(faces, regions); !st.ok()) return st;
  const double res = grid.resolution_m();
  std::vector<PlaneFrame> frames;
  frames.reserve(regions.regions.size());
  for (const PlanarRegion& r : regions.regions) frames.push_back(FrameOf(r));
  absl::StatusOr<WorkMesh> work = BuildWorkMesh(faces, regions, frames, options, res);
  if (!work.ok()) return work.status();
  Simplify(*work, frames, options.chain_tolerance_cells * res, res);
  absl::StatusOr<RegionOutlines> outlines =
      OutlinesOf(*work, static_cast<int>(regions.regions.size()));
  if (!outlines.ok()) return outlines.status();
  PlanarMesh out = Retriangulate(*work, frames, *outlines, options, res);
  RepairPlanarMesh(out, res);
  const MeshCheck check = CheckMesh(out.mesh);
  if (!check.watertight()) {
    return absl::InternalError(absl::StrCat("planar_mesh: not watertight: ", check.ToString()));
  }
  return out;
}

}  // namespace carvemap
