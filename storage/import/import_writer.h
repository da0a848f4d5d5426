// Writes an import to scan.h5 through ScanWriter, streaming its frames as the importer
// produces them.
#pragma once

#include <cstdint>
#include <string>

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

}  // namespace carvemap
