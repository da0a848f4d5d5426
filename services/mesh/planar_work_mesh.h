// Internal to the planar mesh (planar_mesh.cc): the boundary faces' surface made into a
// triangle mesh whose vertices sit on the regions' planes (eq 4.9, §4.3.3), and its
// simplification by edge collapses that keep it a closed manifold (§4.2.5). planar_mesh.cc
// then re-triangulates each region in its plane; planar_mesh_test.cc tests them together.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "absl/container/flat_hash_map.h"
#include "absl/container/inlined_vector.h"
#include "absl/status/statusor.h"
#include "services/mesh/boundary_faces.h"
#include "services/mesh/planar_mesh.h"
#include "services/mesh/planar_regions.h"

namespace carvemap::planar_mesh_internal {

// The plane of a region and its 2D coordinates. §4.2.5 (Fig 4.7a): the region is projected
// along its dominant axis (the coordinate axis nearest its normal) onto an axis-aligned plane,
// triangulated there, and the triangulation is projected back onto the region's plane along
// that axis. Along the axis, the lattice faces of a region never overlap: its dominant faces
// project to squares, and the risers and steps it absorbed (up to ~105° from its normal,
// planar_regions.h) to lines. Orthogonal projection onto the plane would turn every riser
// that faces a little away from the normal into a reversed sliver, a fold of the region over
// itself. (a1, a2) are the other two axes ordered so that e_a1 × e_a2 = `up` = ±e_axis, the
// side of the normal: counter-clockwise in 2D is counter-clockwise seen from free space.
struct PlaneFrame {
  Eigen::Vector3d c, n, up;
  int axis = 2, a1 = 0, a2 = 1;
  [[nodiscard]] Eigen::Vector2d To2(const Eigen::Vector3d& x) const {
    return {x[a1] - c[a1], x[a2] - c[a2]};
  }
  // The point of the plane with x's 2D coordinates (x moved along the dominant axis).
  [[nodiscard]] Eigen::Vector3d Project(const Eigen::Vector3d& x) const { return Lift(To2(x)); }
  [[nodiscard]] Eigen::Vector3d Lift(const Eigen::Vector2d& q) const {
    Eigen::Vector3d x = c;
    x[a1] += q.x();
    x[a2] += q.y();
    x[axis] -= (n[a1] * q.x() + n[a2] * q.y()) / n[axis];
    return x;
  }
  // Twice the signed area of (a, b, c) in the 2D coordinates.
  [[nodiscard]] double Area2(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                             const Eigen::Vector3d& c3) const {
    return up.dot((b - a).cross(c3 - a));
  }
};

PlaneFrame FrameOf(const PlanarRegion& region);

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
  // The vertices BuildWorkMesh moved from their octree corners towards their eq 4.9 positions
  // (only as far as no triangle folds over), each with its corner and its group (vertices
  // that move together); Simplify takes the moves left short farther on the coarser mesh.
  struct Move {
    int v;
    int group;
    Eigen::Vector3d corner;
  };
  std::vector<Move> moves;
  std::vector<Eigen::Vector3d> group_target;  // per group: its eq 4.9 position
  std::vector<int> group_quarters;            // per group: how far it is, in quarters of the way

  // Alive triangles around v (compacts the list).
  const TriList& Tris(int v) {
    TriList& list = incident[v];
    list.erase(std::remove_if(list.begin(), list.end(),
                              [&](int t) {
                                return !alive[t] ||
                                       (tri[t][0] != v && tri[t][1] != v && tri[t][2] != v);
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

// Everything about the surface and its regions before simplification.
absl::StatusOr<WorkMesh> BuildWorkMesh(std::span<const BoundaryFace> faces,
                                       const PlanarRegionSet& regions,
                                       const std::vector<PlaneFrame>& frames,
                                       const PlanarMeshOptions& options, double res);

// Chains first, while the regions' interiors are still fine (collapsing interiors first would
// leave triangles spanning three vertices of one straight chain, which block its collapse),
// then interiors, until nothing changes.
void Simplify(WorkMesh& m, const std::vector<PlaneFrame>& frames, double tolerance_m, double res);

// Whether triangles a and b (vertex ids and positions) meet other than at the vertices they
// share, with CGAL's exact predicates (as CountSelfIntersections tests the written mesh).
bool TrianglesMeet(const std::array<int, 3>& a, const std::array<Eigen::Vector3d, 3>& pa,
                   const std::array<int, 3>& b, const std::array<Eigen::Vector3d, 3>& pb);

// Ids by cell of a coarse grid over their boxes: the candidates for an exact test near a box
// (Untangle's work triangles, Retriangulate's output). An id added again after its box changed
// stays in its old cells too; callers check the boxes they get. Written here because the
// triangles change one collapse at a time, and CGAL's box_intersection_d finds all pairs of a
// fixed set at once.
class BoxGrid {
 public:
  explicit BoxGrid(double cell) : inv_cell_(1.0 / cell) {}
  void Add(int id, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi);
  // The ids listed in the cells that [lo, hi] meets, each once.
  [[nodiscard]] std::vector<int> Candidates(const Eigen::Vector3d& lo,
                                            const Eigen::Vector3d& hi) const;

 private:
  void ForCells(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                const std::function<void(uint64_t)>& f) const;
  double inv_cell_;
  absl::flat_hash_map<uint64_t, std::vector<int>> cells_;
};

// Where the simplified surface passes through itself (the two faces of a part one or two cells
// thick, moved and collapsed into each other; a fan folded at a vertex), for each vertex of the
// meeting triangles: collapse it into a neighbour at most `max_edge_m` away, or else move it up
// to `max_move_m` towards its neighbours' centroid or one of the nearest, when that leaves
// fewer meeting pairs around it and TryCollapse's conditions hold (no triangle turned over in
// its region's plane, no region wrapped around a vertex). In rounds, until one changes fewer
// than 2 % of the vertices it tried.
struct UntangleCounts {
  int collapses = 0;
  int moves = 0;
};
UntangleCounts Untangle(WorkMesh& m, const std::vector<PlaneFrame>& frames, double max_edge_m,
                        double max_move_m, double res);

}  // namespace carvemap::planar_mesh_internal
