#include "services/building/building.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace carvemap {

Eigen::Vector2i NavGrid::CellOf(const Eigen::Vector2d& p) const {
  return {static_cast<int>(std::floor((p.x() - origin.x()) / resolution_m)),
          static_cast<int>(std::floor((p.y() - origin.y()) / resolution_m))};
}

Eigen::Vector2d NavGrid::CellCenter(int ix, int iy) const {
  return origin + resolution_m * Eigen::Vector2d(ix + 0.5, iy + 0.5);
}

Eigen::AlignedBox3d ObjectTruth::Aabb() const {
  Eigen::AlignedBox3d box;  // empty
  for (const Prism& part : parts) {
    for (const Eigen::Vector2d& p : part.footprint) {
      box.extend(Eigen::Vector3d(p.x(), p.y(), part.z0));
      box.extend(Eigen::Vector3d(p.x(), p.y(), part.z1));
    }
  }
  return box;
}

TriangleMesh PrismMesh(const Prism& prism) {
  // Vertices 0..n-1 on the bottom cap, n..2n-1 on the top. The footprint is CCW seen from
  // above, so (b_i, b_j, t_j) has normal (dy, -dx, 0)·h: the edge's right side, i.e. outward.
  TriangleMesh mesh;
  const int n = static_cast<int>(prism.footprint.size());
  if (n < 3) return mesh;
  for (double z : {prism.z0, prism.z1}) {
    for (const Eigen::Vector2d& p : prism.footprint) {
      mesh.vertices.emplace_back(float(p.x()), float(p.y()), float(z));
    }
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    mesh.triangles.emplace_back(i, j, n + j);
    mesh.triangles.emplace_back(i, n + j, n + i);
  }
  for (int k = 1; k + 1 < n; ++k) {
    mesh.triangles.emplace_back(n, n + k, n + k + 1);  // top: CCW from above, normal +z
    mesh.triangles.emplace_back(0, k + 1, k);          // bottom: reversed, normal −z
  }
  return mesh;
}

TriangleMesh StructureMesh(const Building& building) {
  TriangleMesh mesh;
  for (const Prism& p : building.structure) mesh.Append(PrismMesh(p));
  return mesh;
}

TriangleMesh ObjectsMesh(const Building& building, std::vector<int>* object_of_triangle) {
  TriangleMesh mesh;
  if (object_of_triangle) object_of_triangle->clear();
  for (const ObjectTruth& object : building.objects) {
    for (const Prism& part : object.parts) {
      const TriangleMesh m = PrismMesh(part);
      mesh.Append(m);
      if (object_of_triangle) {
        object_of_triangle->insert(object_of_triangle->end(), m.triangles.size(), object.id);
      }
    }
  }
  return mesh;
}

double SignedArea(const std::vector<Eigen::Vector2d>& ring) {
  double a = 0;
  for (size_t i = 0; i < ring.size(); ++i) {
    const Eigen::Vector2d& p = ring[i];
    const Eigen::Vector2d& q = ring[(i + 1) % ring.size()];
    a += p.x() * q.y() - q.x() * p.y();
  }
  return 0.5 * a;
}

bool RingContains(const std::vector<Eigen::Vector2d>& ring, const Eigen::Vector2d& p) {
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

bool RoomContains(const RoomTruth& room, const Eigen::Vector2d& p) {
  if (!RingContains(room.polygon, p)) return false;
  for (const auto& hole : room.holes) {
    if (RingContains(hole, p)) return false;
  }
  return true;
}

double RoomArea(const RoomTruth& room) {
  double a = SignedArea(room.polygon);
  for (const auto& hole : room.holes) a -= std::abs(SignedArea(hole));
  return a;
}

namespace {

void MarkFootprint(const Prism& prism, const NavGrid& frame, std::vector<uint8_t>& blocked) {
  const auto mark = [&](const Eigen::Vector2d& p) {
    const Eigen::Vector2i c = frame.CellOf(p);
    if (c.x() >= 0 && c.y() >= 0 && c.x() < frame.width && c.y() < frame.height) {
      blocked[size_t(c.y()) * frame.width + c.x()] = 1;
    }
  };
  // Cell centres inside the footprint, plus every cell its edges pass through (sampled at a
  // quarter cell), so thin parts such as chair legs still block.
  Eigen::AlignedBox2d box;
  for (const auto& p : prism.footprint) box.extend(p);
  const Eigen::Vector2i lo = frame.CellOf(box.min()), hi = frame.CellOf(box.max());
  for (int iy = std::max(lo.y(), 0); iy <= std::min(hi.y(), frame.height - 1); ++iy) {
    for (int ix = std::max(lo.x(), 0); ix <= std::min(hi.x(), frame.width - 1); ++ix) {
      if (RingContains(prism.footprint, frame.CellCenter(ix, iy))) {
        blocked[size_t(iy) * frame.width + ix] = 1;
      }
    }
  }
  const size_t n = prism.footprint.size();
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d a = prism.footprint[i], b = prism.footprint[(i + 1) % n];
    const int steps = 1 + static_cast<int>((b - a).norm() / (0.25 * frame.resolution_m));
    for (int s = 0; s <= steps; ++s) mark(a + (b - a) * (double(s) / steps));
  }
}

// 1D squared distance transform of f (Felzenszwalb & Huttenlocher 2012). Entries >= kInf are
// "no site" and take no part in the lower envelope (avoids inf − inf).
constexpr double kInf = 1e18;
void Edt1d(const std::vector<double>& f, std::vector<double>& d, std::vector<int>& v,
           std::vector<double>& z) {
  const int n = static_cast<int>(f.size());
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] >= kInf) continue;
    double s = -std::numeric_limits<double>::infinity();
    while (k >= 0) {
      s = ((f[q] + double(q) * q) - (f[v[k]] + double(v[k]) * v[k])) / (2.0 * q - 2.0 * v[k]);
      if (s <= z[k]) {
        --k;
      } else {
        break;
      }
    }
    ++k;
    v[k] = q;
    z[k] = k == 0 ? -std::numeric_limits<double>::infinity() : s;
    z[k + 1] = std::numeric_limits<double>::infinity();
  }
  if (k < 0) {
    std::fill(d.begin(), d.end(), kInf);
    return;
  }
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (z[k + 1] < q) ++k;
    d[q] = double(q - v[k]) * (q - v[k]) + f[v[k]];
  }
}

}  // namespace

std::vector<uint8_t> BlockedCells(const NavGrid& frame, const Building& building, double z_lo,
                                  double z_hi) {
  std::vector<uint8_t> blocked(size_t(frame.width) * frame.height, 0);
  const auto overlaps = [&](const Prism& p) { return p.z1 > z_lo && p.z0 < z_hi; };
  for (const Prism& p : building.structure) {
    if (overlaps(p)) MarkFootprint(p, frame, blocked);
  }
  for (const ObjectTruth& o : building.objects) {
    for (const Prism& p : o.parts) {
      if (overlaps(p)) MarkFootprint(p, frame, blocked);
    }
  }
  return blocked;
}

std::vector<float> DistanceToBlocked(const std::vector<uint8_t>& blocked, int width, int height) {
  const int n = std::max(width, height);
  std::vector<double> f(n), d(n), z(n + 1);
  std::vector<int> v(n);
  std::vector<double> grid(size_t(width) * height);
  for (size_t i = 0; i < grid.size(); ++i) grid[i] = blocked[i] ? 0.0 : kInf;
  // Columns, then rows.
  f.resize(height), d.resize(height);
  for (int x = 0; x < width; ++x) {
    for (int y = 0; y < height; ++y) f[y] = grid[size_t(y) * width + x];
    Edt1d(f, d, v, z);
    for (int y = 0; y < height; ++y) grid[size_t(y) * width + x] = d[y];
  }
  f.resize(width), d.resize(width);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) f[x] = grid[size_t(y) * width + x];
    Edt1d(f, d, v, z);
    for (int x = 0; x < width; ++x) grid[size_t(y) * width + x] = d[x];
  }
  std::vector<float> out(grid.size());
  for (size_t i = 0; i < grid.size(); ++i) {
    out[i] = grid[i] >= kInf * 0.5 ? 1e9f : static_cast<float>(std::sqrt(grid[i]));
  }
  return out;
}

}  // namespace carvemap
