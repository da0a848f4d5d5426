// CARMEN laser logs (storage/import/carmen_import.h): any bytes give a scan or an error naming
// the file; an accepted log writes a scan.h5 that validates. zlib reads non-gzip bytes as they
// are, so the text parser is reached directly; the gzip seed reaches the decompression.
#include <cstddef>
#include <cstdint>

#include "storage/import/carmen_import.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("input.log", data, size);
  CarmenReport report;
  absl::StatusOr<ImportedScan> scan = ImportCarmen(path, {}, nullptr, &report);
  if (!scan.ok()) {
    fuzz::RequireNamesFile(scan.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  fuzz::Require(scan->frame_count == scan->frames.size() && scan->frame_count > 0,
                "frames kept in the result");
  fuzz::Require(report.pose_message == "ODOM" || scan->path.size() == scan->frames.size(),
                "one /path row per posed frame");
  fuzz::RequireImportWritesValidScan(CarmenSensor(), scan->frame_count, [&](const FrameSink& sink) {
    return ImportCarmen(path, {}, sink);
  });
  return 0;
}
