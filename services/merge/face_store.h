// The merge's boundary faces kept sorted by height in a scratch file, and read back a range at
// a time (services/mesh/sorted_faces.h): the levels' slabs, a level's band for its floor plan,
// a level's part of the building mesh. Memory follows the largest range read, not the
// building: the faces of office4 at 10 Hz are 340 MB, a level's a quarter of that.
//
// The faces come in any order (chunk by chunk). Each is appended to the bucket of its height
// (kFaceBucketM of heights per bucket, a file beside the store's); Finish reads each bucket in
// turn, sorts it (FaceHeightLess) and appends it to the store's file, so the sort holds one
// bucket, not every face. The buckets' heights do not overlap, so the file is sorted whole.
// Records are 48 bytes, the same as the struct in memory.
//
// Scratch, not an output: written in the merge's output folder (its hidden scratch folder) and
// removed by the destructor; no fsync. Not thread-safe.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/octree_keys.h"
#include "services/mesh/boundary_faces.h"
#include "services/mesh/sorted_faces.h"

namespace carvemap {

// Heights per bucket, m: a storey's floor or ceiling lands in one bucket, and a building of
// 100 m has 100 bucket files.
inline constexpr double kFaceBucketM = 1.0;

class FaceStore {
 public:
  // A store whose file is `path` (its buckets "<path>.<k>"), for faces on `grid`'s lattice.
  // The folder must exist. Errors: Unavailable when `path` cannot be created.
  [[nodiscard]] static absl::StatusOr<std::unique_ptr<FaceStore>> Create(std::string path,
                                                                         const OctreeGrid& grid);
  ~FaceStore();
  FaceStore(const FaceStore&) = delete;
  FaceStore& operator=(const FaceStore&) = delete;

  // Adds faces, before Finish. Errors: InvalidArgument for a face whose centre is not finite;
  // DataLoss when a bucket cannot be written (the file and the reason named).
  [[nodiscard]] absl::Status Add(std::span<const BoundaryFace> faces);
  // Sorts the faces into the file. Errors: those of reading and writing the files, named.
  [[nodiscard]] absl::Status Finish();

  // After Finish: the faces' heights, their count, the largest face's side, the faces' extent
  // across (each face's centre ± half its side, whatever its axis) and their total area.
  [[nodiscard]] const FaceHeights& heights() const { return heights_; }
  [[nodiscard]] uint64_t size() const { return heights_.size(); }
  [[nodiscard]] double max_size_m() const { return max_size_m_; }
  [[nodiscard]] const Eigen::Vector2d& xy_min() const { return xy_min_; }
  [[nodiscard]] const Eigen::Vector2d& xy_max() const { return xy_max_; }
  [[nodiscard]] double area_m2() const { return area_m2_; }

  // The sorted faces [begin, end). Errors: OutOfRange for a range past the end or before
  // Finish; DataLoss naming the file when it cannot be read whole.
  [[nodiscard]] absl::StatusOr<std::vector<BoundaryFace>> Read(uint64_t begin, uint64_t end) const;
  // Read as a ReadFacesFn (the store must outlive it).
  [[nodiscard]] ReadFacesFn Reader() const;

 private:
  struct Bucket {
    std::string path;
    std::vector<char> pending;  // records not yet appended to the bucket's file
    uint64_t on_disk = 0;       // records in the file
  };
  FaceStore(std::string path, const OctreeGrid& grid);
  absl::Status Flush(Bucket& bucket);

  std::string path_;
  std::map<int64_t, Bucket> buckets_;  // by floor(height / kFaceBucketM)
  bool finished_ = false;
  FaceHeights heights_;
  double max_size_m_ = 0;
  double area_m2_ = 0;
  Eigen::Vector2d xy_min_, xy_max_;
};

}  // namespace carvemap
