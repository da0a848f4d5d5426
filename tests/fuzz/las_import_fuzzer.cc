// LAS with a trajectory (storage/import/las_import.h, las_reader.h): any bytes give a scan or
// an error naming the file; an accepted file writes a scan.h5 that validates. The trajectory is
// fixed, at the seeds' scanner, and spans every time a double can hold, so the fuzzer reaches
// the points' checks.
#include <cstddef>
#include <cstdint>
#include <fstream>
#include <string>

#include "storage/import/las_import.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace carvemap;
  static const std::string trajectory = [] {
    const std::string t = (fuzz::ScratchDir() / "trajectory.txt").string();
    // Where the seeds' scanner is (tests/data/las/), standing still.
    std::ofstream(t) << "-1e300 500002 4100004 101.8 0 0 0 1\n"
                        "1e300 500002 4100004 101.8 0 0 0 1\n";
    return t;
  }();
  const std::string path = fuzz::WriteInput("input.las", data, size);
  LasImportOptions options;
  options.trajectory = trajectory;
  absl::StatusOr<LasImport> las = LasImport::Open(path, options);
  if (!las.ok()) {
    fuzz::RequireNamesFile(las.status(), path);
    return 0;
  }
  LasReport report;
  absl::StatusOr<ImportedScan> scan = las->Run(nullptr, &report);
  if (!scan.ok()) {
    fuzz::RequireNamesFile(scan.status(), path);
    return 0;
  }
  fuzz::Trace(absl::OkStatus());
  fuzz::Require(scan->frame_count == scan->frames.size() && scan->frame_count > 0,
                "frames kept in the result");
  fuzz::Require(scan->path.size() == scan->frames.size(), "one /path row per frame");
  fuzz::Require(scan->point_count == report.points, "every point in a frame");
  fuzz::RequireImportWritesValidScan(las->sensor(), scan->frame_count,
                                     [&](const FrameSink& sink) { return las->Run(sink); });
  return 0;
}
