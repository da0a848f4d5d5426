#include "services/mesh/sorted_faces.h"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "absl/strings/str_cat.h"

namespace carvemap {

bool FaceHeightLess(const BoundaryFace& a, const BoundaryFace& b) {
  return std::tie(a.center.z(), a.center.x(), a.center.y(), a.axis, a.sign, a.size_m) <
         std::tie(b.center.z(), b.center.x(), b.center.y(), b.axis, b.sign, b.size_m);
}

absl::Status SortFacesByHeight(std::vector<BoundaryFace>& faces) {
  for (size_t i = 0; i < faces.size(); ++i) {
    if (!faces[i].center.allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("SortFacesByHeight: face ", i, " has a centre that is not finite"));
    }
  }
  // In place: a stable sort would need a second copy of the building's faces.
  std::sort(faces.begin(), faces.end(), FaceHeightLess);
  return absl::OkStatus();
}

int64_t FaceHeights::KeyOf(double z) const { return std::llround(z / half_cell_m); }

std::pair<uint64_t, uint64_t> FaceHeights::Range(double z_low, double z_high) const {
  auto first_at_or_above = [&](double z) {
    const size_t i = std::partition_point(keys.begin(), keys.end(),
                                          [&](int64_t k) { return double(k) * half_cell_m < z; }) -
                     keys.begin();
    return starts.empty() ? uint64_t{0} : starts[i];
  };
  const uint64_t begin = first_at_or_above(z_low);
  return {begin, std::max(begin, first_at_or_above(z_high))};
}

absl::Status FaceHeights::Append(double z) {
  const double h = z / half_cell_m;
  if (!std::isfinite(h) || std::abs(h) > 1e15) {
    return absl::InvalidArgumentError(
        absl::StrCat("face ", size(), " has a height that is not finite (", z, " m)"));
  }
  const int64_t key = KeyOf(z);
  if (starts.empty()) starts.push_back(0);
  if (!keys.empty() && key < keys.back()) {
    return absl::InvalidArgumentError(absl::StrCat("the faces are not sorted by height (face ",
                                                   size(), " at ", z, " m is below the last)"));
  }
  if (keys.empty() || key != keys.back()) {
    keys.push_back(key);
    starts.push_back(starts.back());
  }
  ++starts.back();
  return absl::OkStatus();
}

absl::StatusOr<FaceHeights> HeightsOf(std::span<const BoundaryFace> faces, const OctreeGrid& grid) {
  FaceHeights heights;
  heights.half_cell_m = grid.resolution_m() / 2;
  for (const BoundaryFace& f : faces) {
    if (absl::Status s = heights.Append(f.center.z()); !s.ok()) return s;
  }
  return heights;
}

ReadFacesFn ReadFromSpan(std::span<const BoundaryFace> faces) {
  return [faces](uint64_t begin, uint64_t end) -> absl::StatusOr<std::vector<BoundaryFace>> {
    if (begin > end || end > faces.size()) {
      return absl::OutOfRangeError(
          absl::StrCat("faces [", begin, ", ", end, ") of ", faces.size()));
    }
    return std::vector<BoundaryFace>(faces.begin() + begin, faces.begin() + end);
  };
}

}  // namespace carvemap
