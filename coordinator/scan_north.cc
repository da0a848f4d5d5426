#include "coordinator/scan_north.h"

#include <cmath>
#include <memory>
#include <numbers>
#include <sstream>
#include <vector>

#include "absl/strings/str_cat.h"
#include "services/geomag/magnetic_declination.h"

namespace carvemap {
namespace {

double Degrees(double rad) {
  // Rounded to 1e-4°: the record is for people; the turn itself stays exact.
  return std::round(rad * 180 / std::numbers::pi * 1e4) / 1e4;
}

}  // namespace

absl::StatusOr<ScanNorth> NorthOfScan(ScanReader& reader, NorthMode mode,
                                      const std::optional<NorthPlace>& place) {
  ScanNorth north;
  north.mode = mode;
  north.place = place;
  if (mode != NorthMode::kNone) {
    absl::StatusOr<std::vector<Eigen::Vector3d>> fields = reader.MagnetometerInWorld();
    if (!fields.ok()) return fields.status();
    north.has_readings = !fields->empty();
    if (north.has_readings) north.estimate = EstimateNorth(*fields);
  }
  double declination_rad = 0;
  if (place && mode != NorthMode::kNone) {
    absl::StatusOr<double> year;
    if (!place->survey_date.empty()) {
      year = DecimalYear(place->survey_date);
    } else {
      absl::StatusOr<std::pair<double, double>> span = reader.PathTimeSpan();
      if (!span.ok()) return span.status();
      // Before 2001 as Unix seconds: times from the start of the walk, not dates.
      if (!(span->first >= 1e9)) {
        return absl::InvalidArgumentError(absl::StrCat(
            reader.file(), ": the path's times start at ", span->first,
            " s, not a date (Unix seconds): give the survey date (YYYY-MM-DD) for true north"));
      }
      year = 1970 + span->first / (365.2425 * 86400);
    }
    if (!year.ok()) return year.status();
    north.survey_year = *year;
    absl::StatusOr<double> d =
        MagneticDeclinationDeg(BuiltInWmm(), place->lat_deg, place->lon_deg, 0, *year);
    if (!d.ok()) {
      return absl::Status(d.status().code(),
                          absl::StrCat(reader.file(), ": true north: ", d.status().message()));
    }
    north.declination_deg = *d;
    declination_rad = *d * std::numbers::pi / 180;
  }
  absl::StatusOr<NorthDecision> decision =
      DecideNorth(mode, north.has_readings, north.estimate, declination_rad);
  if (!decision.ok()) {
    return absl::Status(decision.status().code(),
                        absl::StrCat(reader.file(), ": ", decision.status().message()));
  }
  north.decision = *decision;
  return north;
}

absl::StatusOr<ScanNorth> NorthOfScanFile(const std::string& scan_path, NorthMode mode,
                                          const std::optional<NorthPlace>& place) {
  ScanReader::OpenOptions open;
  open.path_rows = ScanReader::PathRows::kNone;
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(scan_path, open);
  if (!reader.ok()) return reader.status();
  return NorthOfScan(**reader, mode, place);
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
  if (north.place && north.mode != NorthMode::kNone) {
    j["reference"] = "true north";
    j["place"] = {{"lat_deg", north.place->lat_deg},
                  {"lon_deg", north.place->lon_deg},
                  {"survey_year", std::round(north.survey_year * 1e4) / 1e4},
                  {"declination_deg", std::round(north.declination_deg * 1e4) / 1e4},
                  {"model", BuiltInWmm().name}};
  } else {
    j["reference"] = "magnetic north";
  }
  if (!north.decision.note.empty()) j["note"] = north.decision.note;
  return j;
}

}  // namespace carvemap
