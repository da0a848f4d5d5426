// Test support: distances from points to a truth triangle soup (the simulator's gt/*.ply), for
// the tests that compare carved meshes with the truth.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "storage/ply_io.h"

namespace carvemap::testing {

// A mesh's triangles as vertex triples (the form TruthDistance takes).
inline std::vector<std::array<Eigen::Vector3d, 3>> MeshTriangles(const TriangleMesh& mesh) {
  std::vector<std::array<Eigen::Vector3d, 3>> out;
  out.reserve(mesh.triangles.size());
  const auto& v = mesh.vertices;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    out.push_back({v[t[0]].cast<double>(), v[t[1]].cast<double>(), v[t[2]].cast<double>()});
  }
  return out;
}

// The triangles of a PLY (the simulator's truth meshes) as vertex triples.
inline std::vector<std::array<Eigen::Vector3d, 3>> ReadPlyTriangles(const std::string& path) {
  absl::StatusOr<PlyMesh> ply = ReadPly(path);
  if (!ply.ok()) return {};  // callers check for an empty result
  return MeshTriangles(ply->mesh);
}

// Points on the vertical triangles (walls: |n_z| ≤ 0.1) of a truth soup, about `spacing_m`
// apart: each triangle split into k² sub-triangles, one point at each one's centroid. What the
// wall-cover measures (object_segmentation_test, planar_mesh_bench) sample.
inline std::vector<Eigen::Vector3d> WallPoints(
    const std::vector<std::array<Eigen::Vector3d, 3>>& tris, double spacing_m) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& t : tris) {
    const Eigen::Vector3d n = (t[1] - t[0]).cross(t[2] - t[0]);
    const double area2 = n.norm();
    if (area2 < 1e-9 || std::abs(n.z()) > 0.1 * area2) continue;  // walls only
    const int k = std::max(1, static_cast<int>(std::sqrt(area2 / 2) / spacing_m));
    for (int i = 0; i < k; ++i) {
      for (int j = 0; i + j < k; ++j) {
        out.push_back(t[0] + (i + 1.0 / 3) / k * (t[1] - t[0]) +
                      (j + 1.0 / 3) / k * (t[2] - t[0]));
      }
    }
  }
  return out;
}

inline double PointTriangleDistance(const Eigen::Vector3d& p, const std::array<Eigen::Vector3d, 3>& t) {
  const Eigen::Vector3d& a = t[0];
  const Eigen::Vector3d ab = t[1] - a, ac = t[2] - a, ap = p - a;
  const Eigen::Vector3d n = ab.cross(ac);
  const double nn = n.squaredNorm();
  auto seg = [](const Eigen::Vector3d& p, const Eigen::Vector3d& s0, const Eigen::Vector3d& s1) {
    const Eigen::Vector3d d = s1 - s0;
    const double l = d.squaredNorm();
    const double u = l > 0 ? std::clamp((p - s0).dot(d) / l, 0.0, 1.0) : 0.0;
    return (s0 + u * d - p).norm();
  };
  if (nn > 1e-18) {
    // Barycentric coordinates of the projection.
    const double w1 = ap.cross(ac).dot(n) / nn, w2 = ab.cross(ap).dot(n) / nn;
    if (w1 >= 0 && w2 >= 0 && w1 + w2 <= 1) return std::abs(ap.dot(n)) / std::sqrt(nn);
  }
  return std::min({seg(p, t[0], t[1]), seg(p, t[1], t[2]), seg(p, t[2], t[0])});
}

// Distance from points to a triangle soup, through a uniform grid of triangle bounding boxes;
// distances beyond `cap_m` are reported as cap_m.
class TruthDistance {
 public:
  TruthDistance(std::vector<std::array<Eigen::Vector3d, 3>> tris, double cell_m, double cap_m)
      : tris_(std::move(tris)), cell_(cell_m), cap_(cap_m) {
    for (size_t i = 0; i < tris_.size(); ++i) {
      Eigen::Vector3d lo = tris_[i][0].cwiseMin(tris_[i][1]).cwiseMin(tris_[i][2]);
      Eigen::Vector3d hi = tris_[i][0].cwiseMax(tris_[i][1]).cwiseMax(tris_[i][2]);
      const Eigen::Vector3i a = Cell(lo.array() - cap_), b = Cell(hi.array() + cap_);
      for (int z = a.z(); z <= b.z(); ++z)
        for (int y = a.y(); y <= b.y(); ++y)
          for (int x = a.x(); x <= b.x(); ++x) grid_[Key(Eigen::Vector3i(x, y, z))].push_back(i);
    }
  }
  double operator()(const Eigen::Vector3d& p) const {
    auto it = grid_.find(Key(Cell(p)));
    double best = cap_;
    if (it == grid_.end()) return best;
    for (size_t i : it->second) best = std::min(best, PointTriangleDistance(p, tris_[i]));
    return best;
  }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& p) const {
    return (p / cell_).array().floor().cast<int>();
  }
  static uint64_t Key(const Eigen::Vector3i& c) {
    return (uint64_t(uint32_t(c.x() + (1 << 20))) << 42) |
           (uint64_t(uint32_t(c.y() + (1 << 20))) << 21) | uint64_t(uint32_t(c.z() + (1 << 20)));
  }
  std::vector<std::array<Eigen::Vector3d, 3>> tris_;
  double cell_, cap_;
  std::unordered_map<uint64_t, std::vector<size_t>> grid_;
};

}  // namespace carvemap::testing
