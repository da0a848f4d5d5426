#include "coordinator/scan_north.h"

#include <cmath>
#include <numbers>
#include <memory>
#include <vector>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

double Degrees(double rad) {
  // Rounded to 1e-4°: the record is for people; the turn itself stays exact.
  return std::round(rad * 180 / std::numbers::pi * 1e4) / 1e4;
}

}  // namespace

absl::StatusOr<ScanNorth> NorthOfScan(ScanReader& reader, NorthMode mode) {
  ScanNorth north;
  north.mode = mode;
  if (mode != NorthMode::kNone) {
    absl::StatusOr<std::vector<Eigen::Vector3d>> fields = reader.MagnetometerInWorld();
    if (!fields.ok()) return fields.status();
    north.has_readings = !fields->empty();
    if (north.has_readings) north.estimate = EstimateNorth(*fields);
  }
  absl::StatusOr<NorthDecision> decision =
      DecideNorth(mode, north.has_readings, north.estimate);
  if (!decision.ok()) {
    return absl::Status(decision.status().code(),
                        absl::StrCat(reader.file(), ": ", decision.status().message()));
  }
  north.decision = *decision;
  return north;
}

absl::StatusOr<ScanNorth> NorthOfScanFile(const std::string& scan_path, NorthMode mode) {
  ScanReader::OpenOptions open;
  open.path_rows = ScanReader::PathRows::kNone;
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(scan_path, open);
  if (!reader.ok()) return reader.status();
  return NorthOfScan(**reader, mode);
}

nlohmann::json NorthJson(const ScanNorth& north) {
  nlohmann::json j = {{"mode", NorthModeName(north.mode)},
                      {"turned", north.decision.turned},
                      {"yaw_deg", Degrees(north.decision.yaw_rad)},
                      {"about", "the vertical through the scan frame's origin (x = y = 0)"}};
  if (north.has_readings) {
    const NorthEstimate& e = north.estimate;
    j["fit"] = {{"yaw_deg", Degrees(e.yaw_rad)},
                {"readings", e.readings},
                {"usable", e.usable},
                {"kept", e.kept},
                {"spread_deg", Degrees(e.spread_rad)},
                {"standard_error_deg", Degrees(e.standard_error_rad)},
                {"confident", e.confident}};
  }
  if (!north.decision.note.empty()) j["note"] = north.decision.note;
  return j;
}

}  // namespace carvemap
