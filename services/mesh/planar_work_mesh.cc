#include "services/mesh/planar_work_mesh.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include <Eigen/SVD>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "services/geometry/sorted_runs.h"
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
  return 0.5 * frames[region].n.dot((m.pos[b] - m.pos[a]).cross(m.pos[c] - m.pos[a]));
}

// Collapses u into v when that keeps the surface a manifold and no triangle gets worse than
// `min_area` in its region's plane (§4.2.5: the chains stay where the regions meet).
bool TryCollapse(WorkMesh& m, const std::vector<PlaneFrame>& frames, int u, int v,
                 double min_area) {
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
  for (int t : shared) m.alive[t] = 0;
  for (int t : moved) {
    for (int& w : m.tri[t])
      if (w == u) w = v;
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

}  // namespace

PlaneFrame FrameOf(const PlanarRegion& region) {
  PlaneFrame f;
  f.c = region.centroid;
  f.n = region.normal.normalized();
  int least = 0;
  for (int a = 1; a < 3; ++a)
    if (std::abs(f.n[a]) < std::abs(f.n[least])) least = a;
  f.e1 = Eigen::Vector3d::Unit(least).cross(f.n).normalized();
  f.e2 = f.n.cross(f.e1);
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
      m.AddVertex(PlaceVertex(x0, regs, regions, options, res), k);
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
      for (int t : m.Tris(u))
        for (int w : m.tri[t])
          if (w != u) nbrs.push_back(w);
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
        for (int w : nbrs)
          if (IsRegionEdge(m, u, w)) chain.push_back(w);
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
        if (TryCollapse(m, frames, a, b, min_area) || TryCollapse(m, frames, b, a, min_area))
          ++fixed;
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

}  // namespace carvemap::planar_mesh_internal
