#include "services/levels/level_regions.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace carvemap {

absl::StatusOr<std::vector<PlanarRegion>> LevelRegions(std::span<const BoundaryFace> faces,
                                                       const OctreeGrid& grid,
                                                       const PlanarRegionOptions& options,
                                                       size_t slab_faces, double margin_m) {
  if (slab_faces == 0) return absl::InvalidArgumentError("LevelRegions: slab_faces = 0");
  if (!std::isfinite(margin_m) || margin_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat("LevelRegions: bad margin_m = ", margin_m));
  }
  // The faces by height: each face's centre in finest half-cells (a face's centre lies on a
  // cell's plane or half-way up it), so that equal heights compare equal.
  const double half_cell = grid.resolution_m() / 2;
  std::vector<std::pair<int64_t, uint32_t>> by_height;
  by_height.reserve(faces.size());
  for (size_t i = 0; i < faces.size(); ++i) {
    const double h = faces[i].center.z() / half_cell;
    if (!std::isfinite(h) || std::abs(h) > 1e15) {
      return absl::InvalidArgumentError(
          absl::StrCat("LevelRegions: face ", i, " has a height that is not finite"));
    }
    by_height.emplace_back(std::llround(h), static_cast<uint32_t>(i));
  }
  std::sort(by_height.begin(), by_height.end());
  const int64_t margin = static_cast<int64_t>(std::ceil(margin_m / half_cell));

  std::vector<PlanarRegion> out;
  std::vector<BoundaryFace> slab;
  for (size_t begin = 0; begin < by_height.size();) {
    // The core: whole heights, up to slab_faces faces, at least one height.
    size_t end = begin;
    while (end < by_height.size()) {
      size_t next = end;
      while (next < by_height.size() && by_height[next].first == by_height[end].first) ++next;
      if (end > begin && next - begin > slab_faces) break;
      end = next;
    }
    const int64_t core_lo = by_height[begin].first;
    const int64_t core_hi = by_height[end - 1].first;  // inclusive
    const auto first = std::lower_bound(by_height.begin(), by_height.end(),
                                        std::pair<int64_t, uint32_t>{core_lo - margin, 0});
    const auto last = std::upper_bound(
        by_height.begin(), by_height.end(),
        std::pair<int64_t, uint32_t>{core_hi + margin, std::numeric_limits<uint32_t>::max()});
    slab.clear();
    for (auto it = first; it != last; ++it) slab.push_back(faces[it->second]);
    absl::StatusOr<PlanarRegionSet> set = FitPlanarRegions(slab, grid, options);
    if (!set.ok()) return set.status();
    // The core's range of centroid heights: to half-way to the next core's first height, so
    // that consecutive cores tile the heights.
    const double lo_m = begin == 0 ? -std::numeric_limits<double>::infinity()
                                   : 0.5 * double(by_height[begin - 1].first + core_lo) * half_cell;
    const double hi_m = end == by_height.size()
                            ? std::numeric_limits<double>::infinity()
                            : 0.5 * double(core_hi + by_height[end].first) * half_cell;
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

std::vector<BoundaryFace> LevelBandFaces(std::span<const BoundaryFace> faces, const Level& level,
                                         double margin_m) {
  const double lo = level.split_z_low - margin_m;
  const double hi = level.split_z_high + margin_m;
  std::vector<BoundaryFace> out;
  size_t n = 0;
  for (const BoundaryFace& f : faces) n += f.center.z() >= lo && f.center.z() < hi;
  out.reserve(n);
  for (const BoundaryFace& f : faces) {
    if (f.center.z() >= lo && f.center.z() < hi) out.push_back(f);
  }
  return out;
}

}  // namespace carvemap
