#include "services/levels/level_regions.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace carvemap {

absl::StatusOr<std::vector<PlanarRegion>> LevelRegions(const FaceHeights& heights,
                                                       const ReadFacesFn& read,
                                                       const OctreeGrid& grid,
                                                       const PlanarRegionOptions& options,
                                                       size_t slab_faces, double margin_m) {
  if (slab_faces == 0) return absl::InvalidArgumentError("LevelRegions: slab_faces = 0");
  if (!std::isfinite(margin_m) || margin_m < 0) {
    return absl::InvalidArgumentError(absl::StrCat("LevelRegions: bad margin_m = ", margin_m));
  }
  const std::vector<int64_t>& keys = heights.keys;
  const std::vector<uint64_t>& starts = heights.starts;
  const double half_cell = heights.half_cell_m;
  const int64_t margin = static_cast<int64_t>(std::ceil(margin_m / half_cell));

  std::vector<PlanarRegion> out;
  // Over the distinct heights: a core is keys [begin, end).
  for (size_t begin = 0; begin < keys.size();) {
    // Whole heights, up to slab_faces faces, at least one height.
    size_t end = begin + 1;
    while (end < keys.size() && starts[end + 1] - starts[begin] <= slab_faces) ++end;
    const int64_t core_lo = keys[begin];
    const int64_t core_hi = keys[end - 1];  // inclusive
    const size_t first =
        std::lower_bound(keys.begin(), keys.end(), core_lo - margin) - keys.begin();
    const size_t last = std::upper_bound(keys.begin(), keys.end(), core_hi + margin) - keys.begin();
    absl::StatusOr<std::vector<BoundaryFace>> slab = read(starts[first], starts[last]);
    if (!slab.ok()) return slab.status();
    absl::StatusOr<PlanarRegionSet> set = FitPlanarRegions(*slab, grid, options);
    if (!set.ok()) return set.status();
    *slab = {};
    // The core's range of centroid heights: to half-way to the next core's first height, so
    // that consecutive cores tile the heights.
    const double lo_m = begin == 0 ? -std::numeric_limits<double>::infinity()
                                   : 0.5 * double(keys[begin - 1] + core_lo) * half_cell;
    const double hi_m = end == keys.size() ? std::numeric_limits<double>::infinity()
                                           : 0.5 * double(core_hi + keys[end]) * half_cell;
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

absl::StatusOr<std::vector<PlanarRegion>> LevelRegions(std::span<const BoundaryFace> faces,
                                                       const OctreeGrid& grid,
                                                       const PlanarRegionOptions& options,
                                                       size_t slab_faces, double margin_m) {
  absl::StatusOr<FaceHeights> heights = HeightsOf(faces, grid);
  if (!heights.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("LevelRegions: ", heights.status().message()));
  }
  return LevelRegions(*heights, ReadFromSpan(faces), grid, options, slab_faces, margin_m);
}

std::pair<uint64_t, uint64_t> LevelBand(const FaceHeights& heights, const Level& level,
                                        double margin_m) {
  return heights.Range(level.split_z_low - margin_m, level.split_z_high + margin_m);
}

}  // namespace carvemap
