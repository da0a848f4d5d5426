// Writes an import to scan.h5 through ScanWriter, streaming its frames as the importer
// produces them.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "absl/functional/function_ref.h"
#include "absl/status/statusor.h"
#include "storage/import/scan_import.h"

namespace carvemap {

struct ImportSummary {
  uint64_t frames = 0, points = 0, poses = 0;
  double t_begin = 0, t_end = 0;  // span of /path, s
};

// Creates `out_path`, declares `sensor`, then runs `import` with a sink that appends each
// frame to the file; then writes the returned path (and any frames the importer kept in its
// result) and closes. On error the partial file is removed (ScanWriter). `sensor` must be the
// sensor the importer reports (XxxSensor(options)).
absl::StatusOr<ImportSummary> WriteImport(
    const std::string& out_path, const SensorInfo& sensor,
    absl::FunctionRef<absl::StatusOr<ImportedScan>(const FrameSink&)> import);

// Receives the frames of an importer with several sensors: `sensor` indexes the sensors
// declared to WriteImportSensors; each sensor's frames come in ascending time.
using SensorFrameSink =
    std::function<absl::Status(int sensor, double t, std::span<const Eigen::Vector3f>)>;

// As WriteImport, for several sensors: declares `sensors` in order, then runs `import`, which
// sends every frame to the sink and returns /path.
absl::StatusOr<ImportSummary> WriteImportSensors(
    const std::string& out_path, std::span<const SensorInfo> sensors,
    absl::FunctionRef<absl::StatusOr<std::vector<PathRecord>>(const SensorFrameSink&)> import);

}  // namespace carvemap
