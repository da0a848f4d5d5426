// OctoMap scan graphs (storage/import/octomap_graph_import.h): any bytes give a scan or an
// error naming the file; an accepted graph writes a scan.h5 that validates.
#include <cstddef>
#include <cstdint>

#include "storage/import/octomap_graph_import.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  const std::string path = fuzz::WriteInput("input.graph", data, size);
  absl::StatusOr<ImportedScan> scan = ImportOctomapGraph(path);
  if (!scan.ok()) {
    fuzz::RequireNamesFile(scan.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  fuzz::Require(scan->frame_count == scan->frames.size() && scan->path.size() == scan->frames.size(),
                "one /path row per node");
  fuzz::RequireImportWritesValidScan(
      OctomapGraphSensor(), scan->frame_count,
      [&](const FrameSink& sink) { return ImportOctomapGraph(path, {}, sink); });
  return 0;
}
