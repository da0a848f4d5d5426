#include "services/floorplan/samples/scan_cloud_stream.h"

#include <utility>

namespace carvemap {

absl::StatusOr<std::unique_ptr<ScanCloudStream>> ScanCloudStream::Open(const std::string& path,
                                                                       bool validate,
                                                                       double world_yaw_rad) {
  ScanReader::OpenOptions open;
  open.world_yaw_rad = world_yaw_rad;
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(path, open);
  if (!reader.ok()) return reader.status();
  if (validate) {
    if (absl::Status s = (*reader)->Validate(); !s.ok()) return s;
  }
  if ((*reader)->timed_path().empty()) {
    return absl::InvalidArgumentError(path + ": /path is empty");
  }
  return std::unique_ptr<ScanCloudStream>(new ScanCloudStream(*std::move(reader)));
}

CloudStreamFn ScanCloudStream::Stream() {
  return [this](const CloudBatchSink& sink) -> absl::Status {
    const std::vector<SensorInfo>& sensors = reader_->sensors();
    std::unique_ptr<ScanReader::FrameStream> frames = reader_->StreamFrames();
    ScanFrame frame;
    std::vector<CloudPoint> batch;
    while (true) {
      absl::StatusOr<bool> more = frames->Next(frame);
      if (!more.ok()) return more.status();
      if (!*more) break;
      const SensorInfo& info = sensors[static_cast<size_t>(frame.sensor)];
      const Pose pose = reader_->PoseAt(frame.t);
      const Eigen::Vector3d sensor = pose * info.T_s2c;
      batch.clear();
      for (const Eigen::Vector3f& p : frame.points_sensor) {
        if (!p.allFinite()) continue;  // docs/DESIGN.md §3: a NaN row is a beam with no return
        batch.push_back({pose * (info.R_s2c * p.cast<double>() + info.T_s2c), sensor, frame.t});
      }
      points_streamed_ += batch.size();
      if (batch.empty()) continue;
      if (absl::Status s = sink(batch); !s.ok()) return s;
    }
    return absl::OkStatus();
  };
}

}  // namespace carvemap
