#include "services/mesh/planar_mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <deque>
#include <exception>
#include <limits>
#include <utility>

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include "absl/container/flat_hash_map.h"
#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "services/mesh/mesh_checks.h"
#include "services/mesh/planar_mesh_repair.h"
#include "services/mesh/planar_work_mesh.h"

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
  if (!(untangle_edge_cells >= 0) || !(untangle_move_cells >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("planar_mesh: untangle_edge_cells and untangle_move_cells must be >= 0, got ",
                     untangle_edge_cells, " and ", untangle_move_cells));
  }
  if (min_quadtree_cells < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("planar_mesh: min_quadtree_cells must be >= 1, got ", min_quadtree_cells));
  }
  return absl::OkStatus();
}

namespace {

using planar_mesh_internal::BoxGrid;
using planar_mesh_internal::BuildWorkMesh;
using planar_mesh_internal::FrameOf;
using planar_mesh_internal::PlaneFrame;
using planar_mesh_internal::Simplify;
using planar_mesh_internal::TrianglesMeet;
using planar_mesh_internal::Untangle;
using planar_mesh_internal::WorkMesh;

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
using Cdt =
    CGAL::Constrained_Delaunay_triangulation_2<K, CdtTds, CGAL::No_constraint_intersection_tag>;

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
  const Eigen::Vector2d lo_in = lo + Eigen::Vector2d(eps, eps),
                        hi_in = hi - Eigen::Vector2d(eps, eps);
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
      const std::pair<int64_t, int64_t> key{std::llround(4 * q.x() / res),
                                            std::llround(4 * q.y() / res)};
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
    QuadtreePoints(segs, lo + half * Eigen::Vector2d(i & 1, i >> 1), half, min_side, res, out,
                   seen);
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

// Re-triangulates one region of the simplified mesh in its plane: its boundary edges (the
// shared chains) as constraints plus quadtree points (§4.2.5). Returns false (and adds nothing)
// when the boundary is not a valid polygon in the plane; the caller keeps the collapsed
// triangles then.
bool RetriangulateRegion(const WorkMesh& m, const PlaneFrame& frame,
                         const std::vector<std::pair<int, int>>& outline,
                         std::span<const Eigen::Vector2d> splits, bool quadtree,
                         int min_quadtree_cells, double res,
                         std::vector<std::array<int, 3>>& tris_out,
                         std::vector<Eigen::Vector3d>& steiner_out) {
  // A step of the region seen edge-on (vertices of its outline one above the other along the
  // dominant axis, PlaneFrame: the corners of a riser that could not move onto one point) is
  // a run of outline edges x → a1 → … → ak whose a1 … ak share one point in 2D. The outline is
  // triangulated with x → ak in their place, and the step gets its own triangles (x, a_i,
  // a_i+1), which stand across the plane like the riser they replace.
  std::vector<std::pair<int, int>> segs;
  std::vector<std::array<int, 3>> steps;
  {
    absl::flat_hash_map<int, int> next, prev;
    for (auto [a, b] : outline) {
      if (!next.try_emplace(a, b).second) next[a] = -1;  // a vertex the outline passes twice
      if (!prev.try_emplace(b, a).second) prev[b] = -1;
    }
    auto zero = [&](int a, int b) {
      return (frame.To2(m.pos[a]) - frame.To2(m.pos[b])).norm() < 1e-6 * res;
    };
    absl::flat_hash_map<int, int> run_end;   // a1 of each run ➜ ak
    absl::flat_hash_map<int, char> skipped;  // a1 … ak−1: their outgoing edges go
    for (auto [x, a1] : outline) {
      if (zero(x, a1) || next[a1] < 0 || !zero(a1, next[a1])) continue;
      int a = a1;
      for (size_t steps_left = outline.size(); next[a] >= 0 && zero(a, next[a]); --steps_left) {
        if (steps_left == 0 || next[a] == a1) return false;
        steps.push_back({x, a, next[a]});
        skipped[a] = 1;
        a = next[a];
      }
      run_end[a1] = a;
    }
    for (auto [a, b] : outline) {
      if (skipped.contains(a)) continue;
      if (zero(a, b)) return false;  // not part of a run: the outline passes a or b twice
      auto it = run_end.find(b);
      segs.push_back({a, it == run_end.end() ? b : it->second});
    }
  }
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
    for (const Eigen::Vector2d& q : splits) {
      Cdt::Vertex_handle vh = cdt.insert(K::Point_2(q.x(), q.y()));
      if (vh->info().used) return false;
      vh->info().used = true;
      steiner.push_back(vh);
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
          const Eigen::Vector3d x = frame.Lift({vh->point().x(), vh->point().y()});
          steiner_pos.push_back(x);
        }
        t[i] = vh->info().out;
      }
    }
    tris.push_back(t);
  }
  // No sliver between nearly collinear chain vertices (the collapsed triangles are kept then).
  for (const auto& t : tris) {
    if (t[0] >= 0 && t[1] >= 0 && t[2] >= 0 &&
        std::find(steps.begin(), steps.end(), t) != steps.end()) {
      continue;
    }
    Eigen::Vector3d p[3];
    for (int i = 0; i < 3; ++i) p[i] = t[i] >= 0 ? m.pos[t[i]] : steiner_pos[-t[i] - 2];
    if ((p[1] - p[0]).cross(p[2] - p[0]).norm() <= 2e-6 * res * res) return false;
  }
  // The new triangles must have exactly the region's boundary as their boundary.
  tris.insert(tris.end(), steps.begin(), steps.end());
  absl::flat_hash_map<uint64_t, int> directed;
  auto key = [](int a, int b) {
    return (uint64_t{static_cast<uint32_t>(a)} << 32) | static_cast<uint32_t>(b);
  };
  for (const auto& t : tris) {
    for (int i = 0; i < 3; ++i) ++directed[key(t[i], t[(i + 1) % 3])];
  }
  absl::flat_hash_map<uint64_t, char> seg_set;
  for (auto [a, b] : outline) seg_set[key(a, b)] = 1;
  for (const auto& [k, n] : directed) {
    if (n != 1) return false;
    const int a = static_cast<int>(k >> 32), b = static_cast<int>(k & 0xffffffffu);
    const bool reverse = directed.contains(key(b, a));
    if (reverse == seg_set.contains(k)) return false;  // boundary iff a constraint
  }
  for (auto [a, b] : outline) {
    if (!directed.contains(key(a, b))) return false;
  }
  const int base = static_cast<int>(steiner_out.size());
  for (auto& t : tris) {
    for (int& w : t)
      if (w <= -2) w = -(base + (-w - 2)) - 2;
    tris_out.push_back(t);
  }
  steiner_out.insert(steiner_out.end(), steiner_pos.begin(), steiner_pos.end());
  return true;
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

// Where a region's outline passes a vertex more than once, which outgoing outline edge each
// fan of its triangles around the vertex starts from and which incoming one it ends at. A
// re-triangulation must keep these pairs: pairing them otherwise keeps every edge manifold but
// pinches the surface at the vertex (its triangles then make two separate fans).
absl::flat_hash_map<uint64_t, int> PinchedFans(std::span<const std::pair<int, int>> outline,
                                               std::span<const std::array<int, 3>> tris) {
  absl::flat_hash_map<int, int> passes;
  for (auto [a, b] : outline) ++passes[a];
  absl::flat_hash_map<uint64_t, int> next;  // (v, a) ➜ b for each triangle (v, a, b)
  for (const auto& t : tris) {
    for (int i = 0; i < 3; ++i) {
      auto it = passes.find(t[i]);
      if (it != passes.end() && it->second > 1 && t[(i + 1) % 3] >= 0 && t[(i + 2) % 3] >= 0) {
        next[EdgeKey(t[i], t[(i + 1) % 3])] = t[(i + 2) % 3];
      }
    }
  }
  absl::flat_hash_map<uint64_t, int> fans;  // (v, first) ➜ last
  for (auto [v, b] : outline) {
    if (passes[v] < 2) continue;
    int x = b;
    for (size_t steps = 0; steps <= next.size(); ++steps) {
      auto it = next.find(EdgeKey(v, x));
      if (it == next.end()) break;
      x = it->second;
    }
    fans[EdgeKey(v, b)] = x;
  }
  return fans;
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
                  std::span<const std::array<int, 3>> new_tris,
                  std::vector<std::pair<int, int>>* conflicts = nullptr) {
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
    for (uint64_t e : new_inner) {
      if (count_[e] <= 0) continue;
      free = false;
      if (conflicts != nullptr) {
        conflicts->push_back({static_cast<int>(e >> 32), static_cast<int>(e & 0xffffffffu)});
      }
    }
    for (uint64_t e : free ? new_inner : old_inner) ++count_[e];
    return free;
  }

 private:
  absl::flat_hash_map<uint64_t, int> count_;
};

// A region's triangles in the output: ids of the work mesh's vertices, or −2 − i for its
// Steiner point i.
struct RegionTriangles {
  std::vector<std::array<int, 3>> tris;
  std::vector<Eigen::Vector3d> steiner;
};

// Whether each region's new triangles meet more triangles of the other regions (as the output
// would have them: `chosen`) than its simplified ones do. Lifted onto its plane, a region can
// pass through a neighbour that its simplified triangles, off the plane where eq 4.9's moves
// were clamped, stayed clear of (the two faces of a thin part).
std::vector<char> MeetMoreOnPlane(const WorkMesh& m, const std::vector<RegionTriangles>& chosen,
                                  const std::vector<std::vector<std::array<int, 3>>>& old_tris,
                                  const std::vector<char>& remeshed, double res) {
  struct Placed {
    int region;
    std::array<int, 3> id;  // Steiner points: ids below any other region's
    std::array<Eigen::Vector3d, 3> p;
    Eigen::Vector3d lo, hi;
  };
  auto place = [&](int r, const std::array<int, 3>& t, std::span<const Eigen::Vector3d> steiner,
                   int steiner_base) {
    Placed x{r, t, {}, {}, {}};
    for (int i = 0; i < 3; ++i) {
      x.p[i] = t[i] >= 0 ? m.pos[t[i]] : steiner[-t[i] - 2];
      if (t[i] < 0) x.id[i] = steiner_base + t[i] + 2;
    }
    x.lo = x.p[0].cwiseMin(x.p[1]).cwiseMin(x.p[2]);
    x.hi = x.p[0].cwiseMax(x.p[1]).cwiseMax(x.p[2]);
    return x;
  };
  std::vector<Placed> placed;
  // Region r's triangles: placed[first[r]] up to placed[first[r + 1]].
  std::vector<size_t> first(chosen.size() + 1, 0);
  int next_steiner = -2;
  for (int r = 0; r < static_cast<int>(chosen.size()); ++r) {
    first[r] = placed.size();
    for (const auto& t : chosen[r].tris)
      placed.push_back(place(r, t, chosen[r].steiner, next_steiner));
    next_steiner -= static_cast<int>(chosen[r].steiner.size());
  }
  first[chosen.size()] = placed.size();
  BoxGrid grid(8 * res);
  for (int i = 0; i < static_cast<int>(placed.size()); ++i) grid.Add(i, placed[i].lo, placed[i].hi);
  auto meets = [&](int r, std::span<const Placed> tris) {
    int n = 0;
    for (const Placed& x : tris) {
      for (int i : grid.Candidates(x.lo, x.hi)) {
        const Placed& y = placed[i];
        if (y.region == r || (y.hi.array() < x.lo.array()).any() ||
            (y.lo.array() > x.hi.array()).any()) {
          continue;
        }
        n += TrianglesMeet(x.id, x.p, y.id, y.p);
      }
    }
    return n;
  };
  std::vector<char> more(chosen.size(), 0);
  for (int r = 0; r < static_cast<int>(chosen.size()); ++r) {
    if (!remeshed[r]) continue;
    std::vector<Placed> before;
    for (const auto& t : old_tris[r]) before.push_back(place(r, t, {}, 0));
    const std::span<const Placed> now(placed.data() + first[r], first[r + 1] - first[r]);
    more[r] = meets(r, now) > meets(r, before);
  }
  return more;
}

// The output mesh: each region re-triangulated in its plane (RetriangulateRegion) where its
// outline allows, no edge would be shared with another region, and its new triangles meet no
// more of the others' than its simplified ones (MeetMoreOnPlane), else its simplified
// triangles as they are (not_retriangulated[r] set, for a region with an outline; those of
// them kept for meeting more counted in kept_off_plane).
PlanarMesh Retriangulate(const WorkMesh& m, const std::vector<PlaneFrame>& frames,
                         const RegionOutlines& outlines, const PlanarMeshOptions& options,
                         double res, std::vector<char>& not_retriangulated, int& kept_off_plane) {
  const int num_regions = static_cast<int>(outlines.tris.size());
  std::vector<RegionTriangles> chosen(num_regions);
  std::vector<std::vector<std::array<int, 3>>> old_tris(num_regions);
  std::vector<char> remeshed(num_regions, 0);
  EdgeUsers users(m);
  for (int r = 0; r < num_regions; ++r) {
    for (int t : outlines.tris[r]) old_tris[r].push_back(m.tri[t]);
    std::vector<std::array<int, 3>>& tris = chosen[r].tris;
    std::vector<Eigen::Vector3d>& steiner = chosen[r].steiner;
    // A new inner edge that another region already has (the two regions meet along two
    // chains, and both would join the same two corners across): split it by a point at its
    // middle, which lies inside this region, and triangulate again.
    std::vector<Eigen::Vector2d> splits;
    for (int attempt = 0; attempt < 4 && !outlines.segs[r].empty(); ++attempt) {
      tris.clear();
      steiner.clear();
      if (!RetriangulateRegion(m, frames[r], outlines.segs[r], splits, options.quadtree_points,
                               options.min_quadtree_cells, res, tris, steiner)) {
        break;
      }
      // Steiner points (negative ids) never sit on the outline, so the fans' ends compare.
      if (PinchedFans(outlines.segs[r], old_tris[r]) != PinchedFans(outlines.segs[r], tris)) {
        break;
      }
      std::vector<std::pair<int, int>> conflicts;
      if (users.TryReplace(outlines.segs[r], old_tris[r], tris, &conflicts)) {
        remeshed[r] = 1;
        break;
      }
      for (auto [a, b] : conflicts) {
        splits.push_back(0.5 * (frames[r].To2(m.pos[a]) + frames[r].To2(m.pos[b])));
      }
    }
    if (!remeshed[r]) {
      tris = old_tris[r];
      steiner.clear();
    }
  }
  PlanarMesh out;
  const std::vector<char> more = MeetMoreOnPlane(m, chosen, old_tris, remeshed, res);
  for (int r = 0; r < num_regions; ++r) {
    // Back to the simplified triangles, unless another region took one of their inner edges.
    if (more[r] && users.TryReplace(outlines.segs[r], chosen[r].tris, old_tris[r])) {
      remeshed[r] = 0;
      chosen[r].tris = old_tris[r];
      chosen[r].steiner.clear();
      ++kept_off_plane;
    }
    not_retriangulated[r] = !remeshed[r] && !outlines.segs[r].empty();
  }
  std::vector<int> out_vertex(m.pos.size(), -1);
  for (int r = 0; r < num_regions; ++r) {
    const std::vector<Eigen::Vector3d>& steiner = chosen[r].steiner;
    std::vector<int> steiner_id(steiner.size(), -1);
    for (const auto& t : chosen[r].tris) {
      Eigen::Vector3i o;
      for (int i = 0; i < 3; ++i) {
        int& id = t[i] >= 0 ? out_vertex[t[i]] : steiner_id[-t[i] - 2];
        if (id < 0) {
          id = static_cast<int>(out.mesh.vertices.size());
          out.mesh.vertices.push_back((t[i] >= 0 ? m.pos[t[i]] : steiner[-t[i] - 2]).cast<float>());
        }
        o[i] = id;
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
  const planar_mesh_internal::UntangleCounts untangled = Untangle(
      *work, frames, options.untangle_edge_cells * res, options.untangle_move_cells * res, res);
  absl::StatusOr<RegionOutlines> outlines =
      OutlinesOf(*work, static_cast<int>(regions.regions.size()));
  if (!outlines.ok()) return outlines.status();
  std::vector<char> not_retriangulated(regions.regions.size(), 0);
  int kept_off_plane = 0;
  PlanarMesh out =
      Retriangulate(*work, frames, *outlines, options, res, not_retriangulated, kept_off_plane);
  RepairPlanarMesh(out, res);  // a new PlanarMesh: the counts go in after it
  out.regions_kept_off_plane = kept_off_plane;
  out.untangle_collapses = untangled.collapses;
  out.untangle_moves = untangled.moves;
  for (char n : not_retriangulated) out.regions_not_retriangulated += n;
  for (int r : out.triangle_region) out.triangles_not_retriangulated += not_retriangulated[r];
  const MeshCheck check = CheckMesh(out.mesh);
  if (!check.watertight()) {
    return absl::InternalError(absl::StrCat("planar_mesh: not watertight: ", check.ToString()));
  }
  return out;
}

}  // namespace carvemap
