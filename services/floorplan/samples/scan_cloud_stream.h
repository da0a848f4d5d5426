// A scan.h5 (docs/DESIGN.md §3) as the point cloud of §3.1.1 (pointcloud_wall_samples.h): every
// return of every sensor in the world frame, from the system pose at its frame's time (linear
// position, SLERP orientation, §2.4: ScanReader::PoseAt, the interpolation the coordinator's
// ingest uses) composed with the sensor's extrinsics (R_s2c, T_s2c). Frames stream from the
// file (ScanReader::StreamFrames): memory stays bounded by the reader's blocks, whatever the
// scan's size, and each call of the stream reads the file again.
//
// Not thread-safe (HDF5, scan_reader.h): one stream at a time in the process.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "geometry/pose.h"
#include "services/floorplan/samples/pointcloud_wall_samples.h"
#include "storage/scan_reader.h"

namespace carvemap {

class ScanCloudStream {
 public:
  // Opens the scan; with `validate`, checks every row first (ScanReader::Validate, one extra
  // read of the file). Errors name the file (and dataset and row). `world_yaw_rad`: the §2.3
  // turn to north (ScanReader::OpenOptions).
  static absl::StatusOr<std::unique_ptr<ScanCloudStream>> Open(const std::string& path,
                                                               bool validate = true,
                                                               double world_yaw_rad = 0);

  // The recorded system path (/path), time order.
  [[nodiscard]] const std::vector<TimedPose>& path() const { return reader_->timed_path(); }
  // Streams every return once per call, one batch per frame, frames in time order; NaN rows (no
  // return) are skipped. REQUIRES: this object outlives the function.
  [[nodiscard]] CloudStreamFn Stream();
  // Returns streamed so far, over all calls.
  [[nodiscard]] uint64_t points_streamed() const { return points_streamed_; }

 private:
  explicit ScanCloudStream(std::unique_ptr<ScanReader> reader) : reader_(std::move(reader)) {}
  std::unique_ptr<ScanReader> reader_;
  uint64_t points_streamed_ = 0;
};

}  // namespace carvemap
