#include "storage/import/import_writer.h"

#include <span>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "storage/scan_writer.h"

namespace carvemap {

absl::StatusOr<ImportSummary> WriteImport(
    const std::string& out_path, const SensorInfo& sensor,
    absl::FunctionRef<absl::StatusOr<ImportedScan>(const FrameSink&)> import) {
  // The one sensor's import as an import of several: its frames go to sensor 0.
  return WriteImportSensors(
      out_path, {&sensor, 1},
      [&](const SensorFrameSink& sensors_sink) -> absl::StatusOr<std::vector<PathRecord>> {
        const FrameSink sink = [&](double t, std::span<const Eigen::Vector3f> points) {
          return sensors_sink(0, t, points);
        };
        auto scan = import(sink);
        if (!scan.ok()) return scan.status();
        if (scan->sensor.name != sensor.name || scan->sensor.kind != sensor.kind ||
            scan->sensor.rows != sensor.rows || scan->sensor.cols != sensor.cols) {
          return absl::InternalError(
              absl::StrCat(out_path, ": importer's sensor differs from the one declared"));
        }
        for (const ImportedFrame& f : scan->frames) {
          if (absl::Status s = sink(f.t, f.points_sensor); !s.ok()) return s;
        }
        return std::move(scan->path);
      });
}

absl::StatusOr<ImportSummary> WriteImportSensors(
    const std::string& out_path, std::span<const SensorInfo> sensors,
    absl::FunctionRef<absl::StatusOr<std::vector<PathRecord>>(const SensorFrameSink&)> import) {
  auto writer = ScanWriter::Create(out_path);
  if (!writer.ok()) return writer.status();
  ScanWriter& w = **writer;
  std::vector<int> index;
  for (const SensorInfo& sensor : sensors) {
    auto i = w.AddSensor(sensor);
    if (!i.ok()) return i.status();
    index.push_back(*i);
  }
  ImportSummary summary;
  const SensorFrameSink sink = [&](int sensor, double t,
                                   std::span<const Eigen::Vector3f> points) -> absl::Status {
    if (sensor < 0 || static_cast<size_t>(sensor) >= index.size()) {
      return absl::InternalError(absl::StrCat(out_path, ": a frame of undeclared sensor ", sensor));
    }
    ++summary.frames;
    summary.points += points.size();
    return w.AppendFrame(index[static_cast<size_t>(sensor)], t, points);
  };
  auto path = import(sink);
  if (!path.ok()) return path.status();
  if (absl::Status s = w.AppendPath(*path); !s.ok()) return s;
  if (absl::Status s = w.Close(); !s.ok()) return s;
  summary.poses = path->size();
  if (!path->empty()) {
    summary.t_begin = path->front().t;
    summary.t_end = path->back().t;
  }
  return summary;
}

}  // namespace carvemap
