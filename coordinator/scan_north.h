// §2.3 on a scan file: its magnetometer readings taken into the world frame through the path
// (read in blocks: memory does not grow with the walk), the fit of north_alignment.h, the
// job's decision for its --north mode, and the record job.json keeps of it. The coordinator
// runs it once per job at ingest and hands the turn to every lease and to the merge; `carvemap
// carve` and `merge` run it on their own.
#ifndef CARVEMAP_COORDINATOR_SCAN_NORTH_H_
#define CARVEMAP_COORDINATOR_SCAN_NORTH_H_

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "geometry/north_alignment.h"
#include "storage/scan_reader.h"

namespace carvemap {

struct ScanNorth {
  NorthMode mode = NorthMode::kAuto;
  bool has_readings = false;
  NorthEstimate estimate;   // not fitted with kNone
  std::optional<NorthPlace> place;
  double survey_year = 0;      // with a place: the decimal year the declination is for
  double declination_deg = 0;  // with a place: magnetic north's bearing east of true north
  NorthDecision decision;   // decision.yaw_rad: ScanReader::OpenOptions::world_yaw_rad
};

// `reader` opened with world_yaw_rad 0 (any PathRows). With `place`, the turn is to true
// north. Errors: the reader's (naming the file); DecideNorth's FAILED_PRECONDITION for
// kMagnetic without a confident fit; with a place, INVALID_ARGUMENT when the survey's date is
// unknown (relative times and no date) and OUT_OF_RANGE outside the model's years.
absl::StatusOr<ScanNorth> NorthOfScan(ScanReader& reader, NorthMode mode,
                                      const std::optional<NorthPlace>& place = std::nullopt);

// The same on a scan file, read for it alone (the frame tables and the path in blocks, not
// held); the CLI's `carve`, `merge` and `floorplan --scan`. Not thread-safe with other HDF5
// calls (storage/hdf5_lock.h).
absl::StatusOr<ScanNorth> NorthOfScanFile(const std::string& scan_path, NorthMode mode,
                                          const std::optional<NorthPlace>& place = std::nullopt);

// job.json's "north": the mode, whether and by how much the outputs were turned (degrees,
// counter-clockwise from above, about the vertical through the scan frame's origin), the
// fit's readings, inliers, spread and standard error, and the note when not turned.
nlohmann::json NorthJson(const ScanNorth& north);

}  // namespace carvemap

#endif  // CARVEMAP_COORDINATOR_SCAN_NORTH_H_
