#include "services/mesh/face_surface.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <utility>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "geometry/sorted_runs.h"
#include "geometry/union_find.h"

namespace carvemap {
namespace {

using LatticeKey = std::array<int, 3>;

struct FaceSquare {
  int axis = 0;
  int sign = 1;                // normal = sign · e_axis
  Eigen::Vector3i min_corner;  // lattice
  int size = 1;                // lattice cells
};

absl::StatusOr<FaceSquare> SquareOf(const BoundaryFace& face, double res, size_t index) {
  FaceSquare sq;
  sq.axis = face.axis;
  if (face.axis < 0 || face.axis > 2) {
    return absl::InvalidArgumentError(absl::StrCat("planar_mesh: face ", index, ": bad axis"));
  }
  sq.sign = face.sign;
  const double size_cells = face.size_m / res;
  sq.size = static_cast<int>(std::llround(size_cells));
  bool ok = sq.size >= 1 && std::abs(size_cells - sq.size) < 1e-6;
  for (int d = 0; d < 3 && ok; ++d) {
    const double lo =
        d == face.axis ? face.center[d] / res : (face.center[d] - 0.5 * face.size_m) / res;
    sq.min_corner[d] = static_cast<int>(std::llround(lo));
    ok = std::abs(lo - sq.min_corner[d]) < 1e-6;
  }
  if (!ok) {
    return absl::InvalidArgumentError(
        absl::StrCat("planar_mesh: face ", index, " is not on the lattice of resolution ", res));
  }
  return sq;
}

}  // namespace

absl::StatusOr<FaceSurface> BuildSurface(std::span<const BoundaryFace> faces, double res) {
  FaceSurface s;
  std::vector<FaceSquare> squares;
  squares.reserve(faces.size());
  absl::flat_hash_map<LatticeKey, int> vertex_index;
  auto vertex_of = [&](const Eigen::Vector3i& p) {
    auto [it, inserted] =
        vertex_index.try_emplace(LatticeKey{p[0], p[1], p[2]}, static_cast<int>(s.lattice.size()));
    if (inserted) s.lattice.push_back(p);
    return it->second;
  };
  for (size_t f = 0; f < faces.size(); ++f) {
    absl::StatusOr<FaceSquare> sq = SquareOf(faces[f], res, f);
    if (!sq.ok()) return sq.status();
    squares.push_back(*sq);
  }
  // Square corners, counter-clockwise seen from the normal: with u = axis+1, w = axis+2,
  // e_u × e_w = e_axis.
  auto square_corners = [](const FaceSquare& sq) {
    const int u = (sq.axis + 1) % 3, w = (sq.axis + 2) % 3;
    std::array<Eigen::Vector3i, 4> c;
    for (int i = 0; i < 4; ++i) c[i] = sq.min_corner;
    c[1][u] += sq.size;
    c[2][u] += sq.size;
    c[2][w] += sq.size;
    c[3][w] += sq.size;
    if (sq.sign < 0) std::swap(c[1], c[3]);
    return c;
  };
  for (const FaceSquare& sq : squares) {
    for (const Eigen::Vector3i& c : square_corners(sq)) vertex_of(c);
  }
  // Lattice vertices on each axis-parallel line, sorted along the line: (axis d, the other two
  // coordinates, the coordinate along d, vertex), one sorted array rather than a map of small
  // vectors (a third of the memory, no allocation per line).
  using LinePoint = std::array<int, 5>;
  std::vector<LinePoint> lines;
  lines.reserve(3 * s.lattice.size());
  for (int v = 0; v < static_cast<int>(s.lattice.size()); ++v) {
    const Eigen::Vector3i& p = s.lattice[v];
    for (int d = 0; d < 3; ++d) lines.push_back({d, p[(d + 1) % 3], p[(d + 2) % 3], p[d], v});
  }
  std::sort(lines.begin(), lines.end());

  s.poly_start.reserve(faces.size() + 1);
  // Four corners per face and a few more where a face meets smaller ones: reserved with some
  // room, as doubling these two arrays made the stage's peak.
  const size_t corners_guess = 4 * faces.size() + faces.size() / 16 + 64;
  s.corner_vertex.reserve(corners_guess);
  s.corner_face.reserve(corners_guess);
  for (size_t f = 0; f < faces.size(); ++f) {
    s.poly_start.push_back(static_cast<int>(s.corner_vertex.size()));
    const auto c = square_corners(squares[f]);
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector3i& a = c[i];
      const Eigen::Vector3i& b = c[(i + 1) % 4];
      s.corner_vertex.push_back(vertex_index.at(LatticeKey{a[0], a[1], a[2]}));
      s.corner_face.push_back(static_cast<int>(f));
      int d = 0;
      while (a[d] == b[d]) ++d;
      const int lo = std::min(a[d], b[d]), hi = std::max(a[d], b[d]);
      const int k1 = a[(d + 1) % 3], k2 = a[(d + 2) % 3];
      auto first =
          std::upper_bound(lines.begin(), lines.end(), LinePoint{d, k1, k2, lo, INT32_MAX});
      auto last = std::lower_bound(lines.begin(), lines.end(), LinePoint{d, k1, k2, hi, INT32_MIN});
      const auto n_between = last - first;
      for (ptrdiff_t k = 0; k < n_between; ++k) {  // from a towards b
        s.corner_vertex.push_back((a[d] < b[d] ? first[k] : last[-1 - k])[4]);
        s.corner_face.push_back(static_cast<int>(f));
      }
    }
  }
  s.poly_start.push_back(static_cast<int>(s.corner_vertex.size()));
  std::vector<LinePoint>().swap(lines);
  absl::flat_hash_map<LatticeKey, int>().swap(vertex_index);
  const int num_corners = static_cast<int>(s.corner_vertex.size());

  // Pair directed edges with their reverses.
  struct EdgeUse {
    uint64_t key;  // undirected (lo, hi)
    bool forward;  // lo → hi
    int corner;
  };
  std::vector<EdgeUse> uses;
  uses.reserve(num_corners);
  for (int c = 0; c < num_corners; ++c) {
    const uint32_t a = s.corner_vertex[c], b = s.corner_vertex[s.Next(c)];
    const uint32_t lo = std::min(a, b), hi = std::max(a, b);
    uses.push_back({(uint64_t{lo} << 32) | hi, a < b, c});
  }
  std::sort(uses.begin(), uses.end(), [](const EdgeUse& x, const EdgeUse& y) {
    return x.key != y.key ? x.key < y.key : x.corner < y.corner;
  });
  s.twin.assign(num_corners, -1);
  auto face_center2 = [&](int f) {  // 2 × the face centre, lattice
    const FaceSquare& sq = squares[f];
    Eigen::Vector3i c = 2 * sq.min_corner;
    c[(sq.axis + 1) % 3] += sq.size;
    c[(sq.axis + 2) % 3] += sq.size;
    return c;
  };
  // The corners along one edge: paired, or why the faces are not a closed surface.
  const auto pair_run = [&](size_t i, size_t j) -> absl::Status {
    std::vector<int> fwd, bwd;
    for (size_t k = i; k < j; ++k) (uses[k].forward ? fwd : bwd).push_back(uses[k].corner);
    if (fwd.size() != bwd.size() || fwd.size() > 2) {
      const Eigen::Vector3i& p = s.lattice[s.corner_vertex[uses[i].corner]];
      return absl::InvalidArgumentError(absl::StrCat(
          "planar_mesh: the boundary faces are not a closed surface: an edge at lattice (", p[0],
          ", ", p[1], ", ", p[2], ") is used ", fwd.size(), " + ", bwd.size(), " times"));
    }
    if (fwd.size() == 1) {
      s.twin[fwd[0]] = bwd[0];
      s.twin[bwd[0]] = fwd[0];
    } else {
      // Four faces around one edge (two interior cells touching along it): pair each face with
      // the one bounding the same interior quadrant, i.e. the face lying in the direction of
      // this face's normal (that face's normal then points along this face's side).
      const int c0 = fwd[0];
      const Eigen::Vector3i& e0 = s.lattice[s.corner_vertex[c0]];
      const Eigen::Vector3i& e1 = s.lattice[s.corner_vertex[s.Next(c0)]];
      const Eigen::Vector3i m2 = e0 + e1;
      int edge_axis = 0;
      while (e0[edge_axis] == e1[edge_axis]) ++edge_axis;
      auto wing = [&](int c) {  // (axis, sign) from the edge into the face
        const Eigen::Vector3i d = face_center2(s.corner_face[c]) - m2;
        for (int a = 0; a < 3; ++a) {
          if (a != squares[s.corner_face[c]].axis && a != edge_axis && d[a] != 0) {
            return std::make_pair(a, d[a] > 0 ? 1 : -1);
          }
        }
        return std::make_pair(-1, 0);
      };
      for (int cf : fwd) {
        const FaceSquare& sq = squares[s.corner_face[cf]];
        for (int cb : bwd) {
          if (wing(cb) == std::make_pair(sq.axis, sq.sign)) {
            s.twin[cf] = cb;
            s.twin[cb] = cf;
          }
        }
      }
      for (int c : fwd) {
        if (s.twin[c] < 0)
          return absl::InvalidArgumentError(
              "planar_mesh: inconsistent face orientation at a non-manifold edge");
      }
    }
    return absl::OkStatus();
  };
  absl::Status paired;
  ForEachRun(
      uses, [](const EdgeUse& u) { return u.key; },
      [&](size_t i, size_t j) {
        paired = pair_run(i, j);
        return paired.ok();
      });
  if (!paired.ok()) return paired;
  std::vector<EdgeUse>().swap(uses);
  // Topological vertices: corners joined across twin edges.
  UnionFind<int> corners(num_corners);
  for (int c = 0; c < num_corners; ++c) {
    const int t = s.twin[c];
    if (t < c) continue;
    corners.Union(c, s.Next(t));
    corners.Union(s.Next(c), t);
  }
  s.corner_tv.assign(num_corners, -1);
  std::vector<int> root_tv(num_corners, -1);
  for (int c = 0; c < num_corners; ++c) {
    const int r = corners.Find(c);
    if (root_tv[r] < 0) {
      root_tv[r] = s.num_tv++;
      s.tv_lattice.push_back(s.corner_vertex[c]);
    }
    s.corner_tv[c] = root_tv[r];
  }
  return s;
}

}  // namespace carvemap
