// Reads scan.h5 (carvemap-scan v1, docs/DESIGN.md §3). Open() checks the structure (format,
// version, datasets, attributes, dtypes); Validate() also checks every row. Frames stream in time
// order across sensors with bounded memory: /points is read in blocks, never whole.
//
// Thread safety: Debian's libhdf5 is built without thread-safety, so even one reader per thread
// is unsafe: serialize every HDF5 call in the process (all ScanReader/ScanWriter use included).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "geometry/pose.h"
#include "storage/scan_types.h"

namespace carvemap {

class ScanReader {
 public:
  // Rows [begin, end) of one sensor's frames.
  struct RowRange {
    uint64_t begin = 0, end = 0;
  };
  // How much of the path (/path, /path_cov, /magnetometer) Open holds. The whole path is
  // ~190 bytes per pose in memory (270 MB for a two-hour walk logged at 200 Hz): a process that
  // needs only part of it, or none, should not grow with the survey.
  enum class PathRows {
    kAll,     // every pose, covariance and magnetometer reading
    kFrames,  // the poses and covariances around the frames of `frame_rows`; no magnetometer
    kNone,    // none (path() and timed_path() empty; Validate() still reads and checks it all)
  };
  struct OpenOptions {
    PathRows path_rows = PathRows::kAll;
    // kFrames: one range per sensor (as StreamFrames takes). The poses read run from the last
    // at or before the earliest of those frames to the first at or after the latest, one more
    // either way: PoseAt, the covariance and the angular velocity at any of those frames'
    // times (each reads the two poses around it) come out as from the whole path.
    std::vector<RowRange> frame_rows;
    // The turn about the vertical through the scan frame's origin (x = y = 0) applied to every
    // pose, covariance and position the reader returns, radians counter-clockwise seen from
    // above: the §2.3 north alignment (geometry/north_alignment.h). 0 = the file's
    // frame, untouched bit for bit.
    double world_yaw_rad = 0;
  };
  // Errors name the file and the dataset, e.g.
  // "scan.h5: /sensors/h0/frames: missing field 'count'".
  static absl::StatusOr<std::unique_ptr<ScanReader>> Open(const std::string& path,
                                                          const OpenOptions& options);
  static absl::StatusOr<std::unique_ptr<ScanReader>> Open(const std::string& path);  // kAll
  ~ScanReader();
  ScanReader(const ScanReader&) = delete;
  ScanReader& operator=(const ScanReader&) = delete;

  // Every check of docs/DESIGN.md §3 on every row: finite poses, ascending time, unit quaternions,
  // covariances, frame ranges inside /points, grid frame sizes, frames within the path's time
  // span, point rows finite or all-NaN. The first error names file, dataset and row.
  absl::Status Validate();

  [[nodiscard]] const std::string& file() const;
  // The poses Open read (OpenOptions::path_rows): the whole path by default.
  [[nodiscard]] const std::vector<PathRecord>& path() const;
  [[nodiscard]] const std::vector<TimedPose>& timed_path() const;
  [[nodiscard]] const std::optional<std::vector<PathCovariance>>& path_covariance() const;
  [[nodiscard]] const std::optional<std::vector<MagnetometerRecord>>& magnetometer() const;
  [[nodiscard]] const std::vector<SensorInfo>& sensors() const;
  [[nodiscard]] uint64_t frame_count(int sensor) const;
  [[nodiscard]] uint64_t point_count(int sensor) const;

  // Pose of the system at time t (linear position, SLERP orientation, §2.4); clamped to the
  // ends of the path.
  [[nodiscard]] Pose PoseAt(double t) const;

  // Streams frames of all sensors merged by time (ties by sensor index, then row). Memory is
  // bounded by a per-sensor block of frame rows and points, whatever the file's size.
  class FrameStream {
   public:
    virtual ~FrameStream() = default;
    // Fills `frame` with the next frame; returns false at the end. Errors (e.g. a read failure
    // in a truncated file) name file, dataset and row.
    virtual absl::StatusOr<bool> Next(ScanFrame& frame) = 0;
  };
  // Bytes: the block budget per sensor for frame rows and points (a frame larger than the
  // budget is still read whole). REQUIRES: the reader outlives the stream.
  [[nodiscard]] std::unique_ptr<FrameStream> StreamFrames(size_t block_bytes = 4 << 20);
  // The same over rows [begin, end) of each sensor (one range per sensor, in sensor order; an
  // empty range streams nothing of that sensor): a time slice of the scan (scan_slices.h).
  // InvalidArgument for a wrong count of ranges or a range past a sensor's frames.
  [[nodiscard]] absl::StatusOr<std::unique_ptr<FrameStream>> StreamFrames(
      std::span<const RowRange> rows, size_t block_bytes = 4 << 20);
  // Every pose's position (/path x, y, z), read in blocks whatever Open kept of the path: 24
  // bytes per pose where the whole path is ~190.
  absl::StatusOr<std::vector<Eigen::Vector3d>> PathPositions();
  // How far the path's positions may be off horizontally, m: the root mean square over the
  // poses of √((xx + yy) / 2) of /path_cov, read in blocks whatever Open kept; nullopt when the
  // scan has no /path_cov.
  absl::StatusOr<std::optional<double>> HorizontalPositionSigma();
  // The magnetometer readings taken into the world frame through the pose at their times
  // (§2.3: R(t)·m, readings in the system frame), world_yaw_rad applied; the path read in
  // blocks whatever Open kept. Readings outside the path's time span are left out. Empty
  // without /magnetometer.
  absl::StatusOr<std::vector<Eigen::Vector3d>> MagnetometerInWorld();
  // The times of the first and last poses of /path (two rows read, whatever Open kept).
  // INVALID_ARGUMENT for an empty path.
  absl::StatusOr<std::pair<double, double>> PathTimeSpan();
  // A sensor's /frames rows (time, first point, count), read in blocks: 24 bytes per frame.
  absl::StatusOr<std::vector<FrameRecord>> FrameRecords(int sensor);

  // Reads one frame's rows of a sensor directly (random access).
  absl::StatusOr<ScanFrame> ReadFrame(int sensor, uint64_t row);

 private:
  struct Impl;
  explicit ScanReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace carvemap
