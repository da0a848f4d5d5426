#include "services/mesh/level_cut.h"

#include <cmath>
#include <cstdint>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace carvemap {

absl::StatusOr<CutPlane> FindCutPlane(const OctreeGrid& grid, double z,
                                      const Eigen::Vector2d& xy_min, const Eigen::Vector2d& xy_max,
                                      const InteriorAtFn& interior_at) {
  CutPlane plane;
  if (!std::isfinite(z)) {
    plane.z = z;
    return plane;
  }
  const double res = grid.resolution_m();
  plane.z = std::round(z / res) * res;
  const int64_t i0 = std::llround(std::floor(xy_min.x() / res));
  const int64_t i1 = std::llround(std::ceil(xy_max.x() / res));
  const int64_t j0 = std::llround(std::floor(xy_min.y() / res));
  const int64_t j1 = std::llround(std::ceil(xy_max.y() / res));
  if (i1 > i0 && j1 > j0 && double(i1 - i0) * double(j1 - j0) > double(int64_t{1} << 28)) {
    return absl::InvalidArgumentError("level cut: the faces' extent has more than 2^28 columns");
  }
  for (int64_t i = i0; i < i1; ++i) {
    for (int64_t j = j0; j < j1; ++j) {
      const double x = (double(i) + 0.5) * res, y = (double(j) + 0.5) * res;
      absl::StatusOr<bool> below = interior_at(Eigen::Vector3d(x, y, plane.z - res / 2));
      if (!below.ok()) return below.status();
      if (!*below) continue;
      absl::StatusOr<bool> above = interior_at(Eigen::Vector3d(x, y, plane.z + res / 2));
      if (!above.ok()) return above.status();
      if (*above) plane.crossings.emplace_back(x, y);
    }
  }
  return plane;
}

absl::StatusOr<LevelPart> CutLevelPart(std::span<const BoundaryFace> faces, const OctreeGrid& grid,
                                       const CutPlane& low, const CutPlane& high) {
  const double res = grid.resolution_m();
  const double lo = low.z, hi = high.z;
  if (!(lo < hi)) {
    return absl::InvalidArgumentError(
        absl::StrCat("level cut: the part from ", lo, " to ", hi, " m is empty"));
  }
  const double eps = 1e-6 * res;
  auto straddles = [&](double z0, double z1, double s) {
    return std::isfinite(s) && z0 < s - eps && z1 > s + eps;
  };
  auto in_part = [lo, hi](double z) { return z >= lo && z < hi; };
  LevelPart part;
  for (size_t i = 0; i < faces.size(); ++i) {
    const BoundaryFace& f = faces[i];
    if (f.axis != 2) {
      const double half = f.size_m / 2;
      const double z0 = f.center.z() - half, z1 = f.center.z() + half;
      if (straddles(z0, z1, lo) || straddles(z0, z1, hi)) {
        // Cut into finest squares, each on the side of the plane its cells are on.
        const double cells = f.size_m / res;
        const int64_t n = std::llround(cells);
        if (n < 1 || std::abs(cells - double(n)) > 1e-6) {
          return absl::InvalidArgumentError(absl::StrCat("level cut: face ", i, " is ", f.size_m,
                                                         " m, not a whole number of ", res,
                                                         " m cells"));
        }
        const int u = 1 - f.axis;  // the face's horizontal direction
        for (int64_t a = 0; a < n; ++a) {
          for (int64_t b = 0; b < n; ++b) {
            BoundaryFace piece = f;
            piece.size_m = res;
            piece.center[u] = f.center[u] - half + (double(a) + 0.5) * res;
            piece.center.z() = z0 + (double(b) + 0.5) * res;
            if (in_part(piece.center.z())) part.faces.push_back(piece);
          }
        }
        continue;
      }
      if (in_part(f.center.z())) part.faces.push_back(f);
      continue;
    }
    // A horizontal face belongs to the part that holds the finest cell on its interior side.
    if (in_part(f.center.z() + f.sign * res / 2)) part.faces.push_back(f);
  }

  // Caps where free space crosses a plane.
  for (const auto& [plane, sign] : {std::pair<const CutPlane*, int>{&low, 1}, {&high, -1}}) {
    for (const Eigen::Vector2d& xy : plane->crossings) {
      BoundaryFace cap;
      cap.axis = 2;
      cap.sign = static_cast<int8_t>(sign);
      cap.size_m = res;
      cap.center = Eigen::Vector3d(xy.x(), xy.y(), plane->z);
      cap.isosurface_m = plane->z + sign * res / 4;
      part.faces.push_back(cap);
      ++part.caps;
    }
  }
  return part;
}

}  // namespace carvemap
