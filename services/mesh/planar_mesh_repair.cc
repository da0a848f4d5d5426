#include "services/mesh/planar_mesh_repair.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

#include "absl/container/flat_hash_map.h"
#include "geometry/sorted_runs.h"
#include "geometry/union_find.h"

namespace carvemap {

std::vector<int> TinyPieces(int num_tris, const std::function<std::array<int, 3>(int)>& tri,
                            const std::function<bool(int)>& alive,
                            const std::function<Eigen::Vector3d(int)>& pos,
                            const std::function<bool(int)>& bad, double res) {
  UnionFind<int> pieces(num_tris);
  absl::flat_hash_map<uint64_t, int> first_user;  // undirected edge ➜ a triangle on it
  for (int t = 0; t < num_tris; ++t) {
    if (!alive(t)) continue;
    const std::array<int, 3> x = tri(t);
    for (int i = 0; i < 3; ++i) {
      const uint32_t a = x[i], b = x[(i + 1) % 3];
      const uint64_t key = (uint64_t{std::min(a, b)} << 32) | std::max(a, b);
      auto [it, inserted] = first_user.try_emplace(key, t);
      if (inserted) continue;
      pieces.Union(it->second, t);
    }
  }
  absl::flat_hash_map<int, std::vector<int>> piece_vertices;
  for (int t = 0; t < num_tris; ++t) {
    if (!alive(t)) continue;
    std::vector<int>& list = piece_vertices[pieces.Find(t)];
    if (list.size() > kTinyPieceVertices) continue;  // big: not counted further
    for (int v : tri(t)) {
      if (std::find(list.begin(), list.end(), v) == list.end()) list.push_back(v);
    }
  }
  absl::flat_hash_map<int, double> volume6;  // 6 × signed volume about the piece's first vertex
  absl::flat_hash_map<int, char> flat;
  for (int t = 0; t < num_tris; ++t) {
    if (!alive(t)) continue;
    const int piece = pieces.Find(t);
    const std::vector<int>& list = piece_vertices[piece];
    if (list.size() > kTinyPieceVertices) continue;
    const std::array<int, 3> x = tri(t);
    const Eigen::Vector3d o = pos(list[0]);
    volume6[piece] += (pos(x[0]) - o).dot((pos(x[1]) - o).cross(pos(x[2]) - o));
    if (bad(t)) flat[piece] = 1;
  }
  std::vector<int> drop(num_tris, -1);
  for (int t = 0; t < num_tris; ++t) {
    if (!alive(t)) continue;
    auto it = volume6.find(pieces.Find(t));
    if (it == volume6.end()) continue;
    if (flat.contains(it->first) || std::abs(it->second) / 6 < res * res * res) drop[t] = it->first;
  }
  return drop;
}

namespace {

// Adjacency of an output mesh for the repairs below: the alive triangles around each vertex.
struct OutAdjacency {
  std::vector<std::vector<int>> around;  // per vertex; may hold dead or stale entries
  std::vector<char> alive;

  explicit OutAdjacency(const PlanarMesh& m)
      : around(m.mesh.vertices.size()), alive(m.mesh.triangles.size(), 1) {
    for (int t = 0; t < static_cast<int>(m.mesh.triangles.size()); ++t) {
      for (int i = 0; i < 3; ++i) around[m.mesh.triangles[t][i]].push_back(t);
    }
  }
  // Alive triangles that still use v (compacts the list).
  const std::vector<int>& Tris(const PlanarMesh& m, int v) {
    std::vector<int>& list = around[v];
    list.erase(std::remove_if(
                   list.begin(), list.end(),
                   [&](int t) { return !alive[t] || (m.mesh.triangles[t].array() != v).all(); }),
               list.end());
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    return list;
  }
};

Eigen::Vector3d OutPos(const PlanarMesh& m, int v) { return m.mesh.vertices[v].cast<double>(); }

// Twice the area vector of (a, b, c) from the float positions the PLY will hold.
Eigen::Vector3d OutCross(const PlanarMesh& m, int a, int b, int c) {
  const Eigen::Vector3d p = OutPos(m, a);
  return (OutPos(m, b) - p).cross(OutPos(m, c) - p);
}

// A triangle about to replace one that was sound must keep an area and face the same way
// (an edge flip or collapse must not fold the surface).
bool SoundReplacement(const Eigen::Vector3d& before, const Eigen::Vector3d& after,
                      double min_area) {
  if (0.5 * after.norm() < min_area) return false;
  return 0.5 * before.norm() < min_area || before.dot(after) > 0;
}

// Flips the edge opposite vertex `k` of triangle t with the triangle across it (Lawson's flip):
// (m, a, b) + (b, a, d) ➜ (m, a, d) + (m, d, b). Skipped when m–d is already an edge (the flip
// would make it non-manifold) or a new triangle would be flat or folded.
bool OutFlip(PlanarMesh& m, OutAdjacency& adj, int t, int k, double min_area) {
  auto& tris = m.mesh.triangles;
  const Eigen::Vector3i x = tris[t];
  const int mv = x[k], a = x[(k + 1) % 3], b = x[(k + 2) % 3];
  int s = -1, d = -1;
  for (int u : adj.Tris(m, a)) {
    if (u == t) continue;
    const Eigen::Vector3i& y = tris[u];
    for (int i = 0; i < 3; ++i) {
      if (y[i] == b && y[(i + 1) % 3] == a) s = u, d = y[(i + 2) % 3];
    }
  }
  if (s < 0 || d == mv || m.triangle_region[s] != m.triangle_region[t]) return false;
  for (int u : adj.Tris(m, mv)) {
    if ((tris[u].array() == d).any()) return false;
  }
  const Eigen::Vector3d ref = OutCross(m, b, a, d);  // the sound triangle of the pair
  if (!SoundReplacement(ref, OutCross(m, mv, a, d), min_area) ||
      !SoundReplacement(ref, OutCross(m, mv, d, b), min_area)) {
    return false;
  }
  tris[t] = Eigen::Vector3i(mv, a, d);
  tris[s] = Eigen::Vector3i(mv, d, b);
  adj.around[d].push_back(t);
  adj.around[mv].push_back(s);
  return true;
}

// Merges vertex u into v (edge u–v of a closed manifold mesh): the two triangles on the edge
// go, the others of u take v. Only when the mesh stays a closed manifold (the link condition:
// u and v share exactly the two opposite vertices, which keep three triangles or more) and
// no moved triangle becomes flat or folds over.
bool OutCollapse(PlanarMesh& m, OutAdjacency& adj, int u, int v, double min_area) {
  auto& tris = m.mesh.triangles;
  const std::vector<int> tu = adj.Tris(m, u);
  const std::vector<int> tv = adj.Tris(m, v);
  std::vector<int> shared, moved;
  for (int t : tu) ((tris[t].array() == v).any() ? shared : moved).push_back(t);
  if (shared.size() != 2) return false;
  std::vector<int> opposite, nu, nv;
  for (int t : shared) {
    for (int i = 0; i < 3; ++i) {
      if (tris[t][i] != u && tris[t][i] != v) opposite.push_back(tris[t][i]);
    }
  }
  if (opposite.size() != 2 || opposite[0] == opposite[1]) return false;
  for (int t : tu)
    for (int i = 0; i < 3; ++i)
      if (tris[t][i] != u && tris[t][i] != v) nu.push_back(tris[t][i]);
  for (int t : tv)
    for (int i = 0; i < 3; ++i)
      if (tris[t][i] != u && tris[t][i] != v) nv.push_back(tris[t][i]);
  for (auto* list : {&nu, &nv, &opposite}) {
    std::sort(list->begin(), list->end());
    list->erase(std::unique(list->begin(), list->end()), list->end());
  }
  std::vector<int> common;
  std::set_intersection(nu.begin(), nu.end(), nv.begin(), nv.end(), std::back_inserter(common));
  if (common != opposite) return false;
  if (tu.size() + tv.size() - 4 < 3) return false;
  for (int w : opposite) {
    if (adj.Tris(m, w).size() < 4) return false;
  }
  for (int t : moved) {
    Eigen::Vector3i y = tris[t];
    const Eigen::Vector3d before = OutCross(m, y[0], y[1], y[2]);
    for (int i = 0; i < 3; ++i)
      if (y[i] == u) y[i] = v;
    if (!SoundReplacement(before, OutCross(m, y[0], y[1], y[2]), min_area)) return false;
  }
  for (int t : shared) adj.alive[t] = 0;
  for (int t : moved) {
    for (int i = 0; i < 3; ++i)
      if (tris[t][i] == u) tris[t][i] = v;
    adj.around[v].push_back(t);
  }
  adj.around[u].clear();
  return true;
}

// Moves vertex v by `step` m off the line of a flat triangle: along the normal of its sound
// triangles (either way), or across the line in their plane, whichever keeps every triangle
// around v sound. Geometry moves by a hundredth of a cell, far below anything the grid shows.
bool OutNudge(PlanarMesh& m, OutAdjacency& adj, int v, const Eigen::Vector3d& line, double step,
              double min_area) {
  const std::vector<int> around = adj.Tris(m, v);
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (int t : around) {
    const Eigen::Vector3i& y = m.mesh.triangles[t];
    normal += OutCross(m, y[0], y[1], y[2]);
  }
  std::vector<Eigen::Vector3d> dirs;
  if (normal.norm() > 0) {
    const Eigen::Vector3d n = normal.normalized();
    const Eigen::Vector3d across =
        line.norm() > 0 ? Eigen::Vector3d(n.cross(line).normalized()) : Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& d : {across, Eigen::Vector3d(-across), n, Eigen::Vector3d(-n)}) {
      if (d.allFinite() && d.norm() > 0.5) dirs.push_back(d);
    }
  }
  for (int a = 0; a < 3; ++a) {
    dirs.push_back(Eigen::Vector3d::Unit(a));
    dirs.push_back(-Eigen::Vector3d::Unit(a));
  }
  const Eigen::Vector3f old = m.mesh.vertices[v];
  std::vector<Eigen::Vector3d> before;
  for (int t : around) {
    const Eigen::Vector3i& y = m.mesh.triangles[t];
    before.push_back(OutCross(m, y[0], y[1], y[2]));
  }
  for (const Eigen::Vector3d& d : dirs) {
    m.mesh.vertices[v] = (old.cast<double>() + step * d).cast<float>();
    bool ok = true;
    for (size_t i = 0; i < around.size() && ok; ++i) {
      const Eigen::Vector3i& y = m.mesh.triangles[around[i]];
      ok = SoundReplacement(before[i], OutCross(m, y[0], y[1], y[2]), min_area);
    }
    if (ok) return true;
  }
  m.mesh.vertices[v] = old;
  return false;
}

// (3) of RepairPlanarMesh: how far apart the coincident vertices of sheets that meet at a
// point are moved, in grid cells: far below the grid's detail, far above float rounding at
// building coordinates (~1e-5 m at 100 m; 0.02 cells is 1.25 mm at 6.25 cm).
constexpr double kSheetSeparationCells = 0.02;

// Moves each vertex that shares its position with another `step` m toward the centroids of its
// own triangles (the mean of the unit directions to them), when no triangle around it then
// loses its area or turns over. Returns the vertices moved.
int SeparateCoincidentVertices(PlanarMesh& mesh, double step, double min_area_m2) {
  const auto& vs = mesh.mesh.vertices;
  std::vector<int> order(vs.size());
  std::iota(order.begin(), order.end(), 0);
  const auto position = [&](int v) {
    return std::array<float, 3>{vs[v].x(), vs[v].y(), vs[v].z()};
  };
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return std::make_pair(position(a), a) < std::make_pair(position(b), b);
  });
  // The coincident vertices in vertex order (the result depends on the order: a vertex's
  // direction uses its neighbours' positions), each with its triangles.
  std::vector<int> coincident;
  ForEachRun(order, position, [&](size_t b, size_t e) {
    for (size_t i = b; e - b > 1 && i < e; ++i) coincident.push_back(order[i]);
  });
  if (coincident.empty()) return 0;
  std::sort(coincident.begin(), coincident.end());
  std::vector<int> slot(vs.size(), -1);
  for (size_t i = 0; i < coincident.size(); ++i) slot[coincident[i]] = static_cast<int>(i);
  std::vector<std::vector<int>> around(coincident.size());
  for (int t = 0; t < static_cast<int>(mesh.mesh.triangles.size()); ++t) {
    for (int i = 0; i < 3; ++i) {
      if (const int k = slot[mesh.mesh.triangles[t][i]]; k >= 0) around[k].push_back(t);
    }
  }
  int moved = 0;
  for (size_t k = 0; k < coincident.size(); ++k) {
    const int v = coincident[k];
    const std::vector<int>& tris = around[k];
    const Eigen::Vector3d p = OutPos(mesh, v);
    Eigen::Vector3d inward = Eigen::Vector3d::Zero();
    for (int t : tris) {
      const Eigen::Vector3i& y = mesh.mesh.triangles[t];
      const Eigen::Vector3d c = (OutPos(mesh, y[0]) + OutPos(mesh, y[1]) + OutPos(mesh, y[2])) / 3;
      if ((c - p).norm() > 0) inward += (c - p).normalized();
    }
    if (!(inward.norm() > 1e-9)) continue;
    const Eigen::Vector3f to = (p + step * inward.normalized()).cast<float>();
    std::vector<Eigen::Vector3d> before;
    for (int t : tris) {
      const Eigen::Vector3i& y = mesh.mesh.triangles[t];
      before.push_back(OutCross(mesh, y[0], y[1], y[2]));
    }
    const Eigen::Vector3f from = mesh.mesh.vertices[v];
    mesh.mesh.vertices[v] = to;
    bool sound = true;
    for (size_t i = 0; i < tris.size() && sound; ++i) {
      const Eigen::Vector3i& y = mesh.mesh.triangles[tris[i]];
      sound = SoundReplacement(before[i], OutCross(mesh, y[0], y[1], y[2]), min_area_m2);
    }
    if (sound) {
      ++moved;
    } else {
      mesh.mesh.vertices[v] = from;
    }
  }
  return moved;
}

}  // namespace

PlanarMeshRepair RepairPlanarMesh(PlanarMesh& mesh, double res, double min_area_m2) {
  PlanarMeshRepair report;
  auto& tris = mesh.mesh.triangles;
  auto flat = [&](int t) {
    const Eigen::Vector3i& y = tris[t];
    return 0.5 * OutCross(mesh, y[0], y[1], y[2]).norm() < min_area_m2;
  };
  // Small closed pieces that enclose less than one grid cell (a one-cell pocket whose corners
  // eq 4.9 placed onto nearly one plane, down to two triangles on the same three vertices):
  // carving noise below the grid's resolution; dropping them leaves the rest closed.
  {
    const std::vector<int> drop = TinyPieces(
        static_cast<int>(tris.size()),
        [&](int t) {
          return std::array<int, 3>{tris[t][0], tris[t][1], tris[t][2]};
        },
        [](int) { return true; }, [&](int v) { return OutPos(mesh, v); }, [](int) { return false; },
        res);
    absl::flat_hash_map<int, char> pieces;
    PlanarMesh kept;
    for (size_t t = 0; t < drop.size(); ++t) {
      if (drop[t] >= 0) {
        pieces[drop[t]] = 1;
        continue;
      }
      kept.mesh.triangles.push_back(tris[t]);
      kept.triangle_region.push_back(mesh.triangle_region[t]);
    }
    if (!pieces.empty()) {
      report.dropped_pieces = static_cast<int>(pieces.size());
      kept.mesh.vertices = std::move(mesh.mesh.vertices);
      mesh = std::move(kept);
    }
  }
  // Triangles without area: a flip of their longest edge, else a collapse of their shortest
  // edge (the region border moves by that edge, a fraction of a cell), else a nudge of the
  // vertex lying on the longest edge.
  OutAdjacency adj(mesh);
  const double step = 0.01 * res;
  for (int round = 0; round < 8; ++round) {
    int left = 0;
    for (int t = 0; t < static_cast<int>(tris.size()); ++t) {
      if (!adj.alive[t] || !flat(t)) continue;
      const Eigen::Vector3i x = tris[t];
      std::array<int, 3> by_length = {0, 1, 2};  // edge i = (x[i], x[i+1])
      std::array<double, 3> len;
      for (int i = 0; i < 3; ++i)
        len[i] = (OutPos(mesh, x[(i + 1) % 3]) - OutPos(mesh, x[i])).norm();
      std::sort(by_length.begin(), by_length.end(), [&](int i, int j) { return len[i] < len[j]; });
      const int longest = by_length[2];
      if (OutFlip(mesh, adj, t, (longest + 2) % 3, min_area_m2)) {
        ++report.flips;
        continue;
      }
      // The apex (the middle one of three points on a line) onto the nearer end of the long
      // edge when that is a short move, else a nudge off the line, else any collapse.
      const int apex = x[(longest + 2) % 3];
      std::array<int, 2> ends = {x[longest], x[(longest + 1) % 3]};
      if ((OutPos(mesh, ends[1]) - OutPos(mesh, apex)).norm() <
          (OutPos(mesh, ends[0]) - OutPos(mesh, apex)).norm()) {
        std::swap(ends[0], ends[1]);
      }
      if ((OutPos(mesh, ends[0]) - OutPos(mesh, apex)).norm() <= 0.25 * res &&
          OutCollapse(mesh, adj, apex, ends[0], min_area_m2)) {
        ++report.collapses;
        continue;
      }
      const Eigen::Vector3d line = OutPos(mesh, ends[1]) - OutPos(mesh, ends[0]);
      if (OutNudge(mesh, adj, apex, line, step, min_area_m2)) {
        ++report.nudges;
        continue;
      }
      bool done = OutCollapse(mesh, adj, apex, ends[0], min_area_m2) ||
                  OutCollapse(mesh, adj, apex, ends[1], min_area_m2);
      for (int i : by_length) {
        const int a = x[i], b = x[(i + 1) % 3];
        if (done) break;
        done =
            OutCollapse(mesh, adj, a, b, min_area_m2) || OutCollapse(mesh, adj, b, a, min_area_m2);
      }
      if (done) {
        ++report.collapses;
        continue;
      }
      if (OutNudge(mesh, adj, ends[0], line, step, min_area_m2) ||
          OutNudge(mesh, adj, ends[1], line, step, min_area_m2)) {
        ++report.nudges;
        continue;
      }
      ++left;
    }
    report.left = left;
    if (left == 0) {
      bool any_flat = false;
      for (int t = 0; t < static_cast<int>(tris.size()) && !any_flat; ++t)
        any_flat = adj.alive[t] && flat(t);
      if (!any_flat) break;
    }
  }
  report.left = 0;
  for (int t = 0; t < static_cast<int>(tris.size()); ++t) report.left += adj.alive[t] && flat(t);
  // Compact: dead triangles and vertices no triangle uses any more.
  PlanarMesh out;
  std::vector<int> index(mesh.mesh.vertices.size(), -1);
  for (int t = 0; t < static_cast<int>(tris.size()); ++t) {
    if (!adj.alive[t]) continue;
    Eigen::Vector3i y = tris[t];
    for (int i = 0; i < 3; ++i) {
      if (index[y[i]] < 0) {
        index[y[i]] = static_cast<int>(out.mesh.vertices.size());
        out.mesh.vertices.push_back(mesh.mesh.vertices[y[i]]);
      }
      y[i] = index[y[i]];
    }
    out.mesh.triangles.push_back(y);
    out.triangle_region.push_back(mesh.triangle_region[t]);
  }
  mesh = std::move(out);
  report.separated = SeparateCoincidentVertices(mesh, kSheetSeparationCells * res, min_area_m2);
  return report;
}

}  // namespace carvemap
