// Boundary faces sorted by height, and the index of their heights: what lets the merge read the
// faces of a slab of heights or of one level (the levels' regions, a level's wall samples, a
// level's part of the building mesh) without holding every face of the building. The merge
// keeps the sorted faces in a scratch file (services/merge/face_store.h) and reads ranges of
// them; tests hold them in memory.
//
// Plain functions over plain data: no files, no logging.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"

namespace carvemap {

// The order faces are sorted in: centre height, then x, y, axis, sign and size. A total order,
// so that the sorted faces do not depend on the order the chunks were collected in.
[[nodiscard]] bool FaceHeightLess(const BoundaryFace& a, const BoundaryFace& b);

// Sorts `faces` in place by FaceHeightLess. Errors: InvalidArgument for a face whose centre is
// not finite (the faces are then left unsorted).
[[nodiscard]] absl::Status SortFacesByHeight(std::vector<BoundaryFace>& faces);

// The heights of faces sorted by height: each distinct centre height in finest half-cells (a
// face's centre lies on a cell's plane or half-way up it, so equal heights compare equal), with
// the index of its first face.
struct FaceHeights {
  double half_cell_m = 0;
  std::vector<int64_t> keys;     // ascending
  std::vector<uint64_t> starts;  // starts[i]: the first face at keys[i]; then the face count

  [[nodiscard]] uint64_t size() const { return starts.empty() ? 0 : starts.back(); }
  // The key of height `z`.
  [[nodiscard]] int64_t KeyOf(double z) const;
  // The index range [begin, end) of the faces whose centre height lies in [z_low, z_high)
  // (either may be ±infinity).
  [[nodiscard]] std::pair<uint64_t, uint64_t> Range(double z_low, double z_high) const;
  // Appends a face at height `z`, not below the last. Errors: InvalidArgument for a height that
  // is not finite or is below the last.
  [[nodiscard]] absl::Status Append(double z);
};

// FaceHeights of `faces`, which must be sorted by height. Errors: those of Append.
[[nodiscard]] absl::StatusOr<FaceHeights> HeightsOf(std::span<const BoundaryFace> faces,
                                                    const OctreeGrid& grid);

// Reads the sorted faces [begin, end).
using ReadFacesFn =
    std::function<absl::StatusOr<std::vector<BoundaryFace>>(uint64_t begin, uint64_t end)>;

// A ReadFacesFn over faces held in memory (copies the range; `faces` must outlive it).
[[nodiscard]] ReadFacesFn ReadFromSpan(std::span<const BoundaryFace> faces);

}  // namespace carvemap
