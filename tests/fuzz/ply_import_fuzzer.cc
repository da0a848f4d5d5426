// PLY point clouds with sensor origins (storage/import/ply_import.h): any bytes give a scan or
// an error naming the file; an accepted file writes a scan.h5 that validates.
#include <cstddef>
#include <cstdint>

#include "storage/import/ply_import.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("input.ply", data, size);
  absl::StatusOr<ImportedScan> scan = ImportPly(path);
  if (!scan.ok()) {
    fuzz::RequireNamesFile(scan.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  fuzz::Require(scan->frame_count == scan->frames.size() && scan->path.size() == scan->frames.size(),
                "one /path row per frame");
  fuzz::RequireImportWritesValidScan(PlySensor(), scan->frame_count, [&](const FrameSink& sink) {
    return ImportPly(path, {}, sink);
  });
  return 0;
}
