#include "services/levels/level_regions.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <tuple>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace carvemap {

absl::Status SortFacesByHeight(std::vector<BoundaryFace>& faces) {
  for (size_t i = 0; i < faces.size(); ++i) {
    if (!faces[i].center.allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("SortFacesByHeight: face ", i, " has a centre that is not finite"));
    }
  }
  // In place: a stable sort would need a second copy of the building's faces.
  std::sort(faces.begin(), faces.end(), [](const BoundaryFace& a, const BoundaryFace& b) {
    return std::tie(a.center.z(), a.center.x(), a.center.y(), a.axis, a.sign, a.size_m) <
           std::tie(b.center.z(), b.center.x(), b.center.y(), b.axis, b.sign, b.size_m);
  });
  return absl::OkStatus();
}

absl::StatusOr<std::vector<PlanarRegion>> LevelRegions(std::span<const BoundaryFace> faces,
                                                       const OctreeGrid& grid,
                                                       const PlanarRegionOptions& options,
                                                       size_t slab_faces, double margin_m) {
  if (slab_faces == 0) return absl::InvalidArgumentError("LevelRegions: slab_faces = 0");
  if (!std::isfinite(margin_m) || margin_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat("LevelRegions: bad margin_m = ", margin_m));
  }
  // Each face's height in finest half-cells (a face's centre lies on a cell's plane or half-way
  // up it), so that equal heights compare equal.
  const double half_cell = grid.resolution_m() / 2;
  for (size_t i = 0; i < faces.size(); ++i) {
    const double h = faces[i].center.z() / half_cell;
    if (!std::isfinite(h) || std::abs(h) > 1e15) {
      return absl::InvalidArgumentError(
          absl::StrCat("LevelRegions: face ", i, " has a height that is not finite"));
    }
    if (i > 0 && faces[i].center.z() < faces[i - 1].center.z()) {
      return absl::InvalidArgumentError(
          absl::StrCat("LevelRegions: the faces are not sorted by height (face ", i, ")"));
    }
  }
  auto height = [half_cell](const BoundaryFace& f) {
    return static_cast<int64_t>(std::llround(f.center.z() / half_cell));
  };
  const int64_t margin = static_cast<int64_t>(std::ceil(margin_m / half_cell));

  std::vector<PlanarRegion> out;
  for (size_t begin = 0; begin < faces.size();) {
    // The core: whole heights, up to slab_faces faces, at least one height.
    size_t end = begin;
    while (end < faces.size()) {
      size_t next = end;
      while (next < faces.size() && height(faces[next]) == height(faces[end])) ++next;
      if (end > begin && next - begin > slab_faces) break;
      end = next;
    }
    const int64_t core_lo = height(faces[begin]);
    const int64_t core_hi = height(faces[end - 1]);  // inclusive
    const auto first = std::partition_point(faces.begin(), faces.end(), [&](const BoundaryFace& f) {
      return height(f) < core_lo - margin;
    });
    const auto last = std::partition_point(faces.begin(), faces.end(), [&](const BoundaryFace& f) {
      return height(f) <= core_hi + margin;
    });
    absl::StatusOr<PlanarRegionSet> set =
        FitPlanarRegions(std::span<const BoundaryFace>(first, last), grid, options);
    if (!set.ok()) return set.status();
    // The core's range of centroid heights: to half-way to the next core's first height, so
    // that consecutive cores tile the heights.
    const double lo_m = begin == 0 ? -std::numeric_limits<double>::infinity()
                                   : 0.5 * double(height(faces[begin - 1]) + core_lo) * half_cell;
    const double hi_m = end == faces.size()
                            ? std::numeric_limits<double>::infinity()
                            : 0.5 * double(core_hi + height(faces[end])) * half_cell;
    for (PlanarRegion& r : set->regions) {
      if (!(r.centroid.z() >= lo_m && r.centroid.z() < hi_m)) continue;
      r.id = static_cast<int>(out.size());
      r.faces = {};
      out.push_back(std::move(r));
    }
    begin = end;
  }
  return out;
}

std::span<const BoundaryFace> LevelBandFaces(std::span<const BoundaryFace> faces,
                                             const Level& level, double margin_m) {
  const double lo = level.split_z_low - margin_m;
  const double hi = level.split_z_high + margin_m;
  const auto first = std::partition_point(
      faces.begin(), faces.end(), [lo](const BoundaryFace& f) { return f.center.z() < lo; });
  const auto last = std::partition_point(first, faces.end(),
                                         [hi](const BoundaryFace& f) { return f.center.z() < hi; });
  return {first, last};
}

}  // namespace carvemap
