#include "services/cli/north_flags.h"

#include <optional>

namespace carvemap {

void AddNorthFlags(CLI::App* cmd, NorthFlags& flags, bool optional_mode) {
  std::string help =
      "§2.3: turn the outputs about the vertical to north (+y) from the scan's /magnetometer: "
      "auto (when the fit is confident and the turn is at least 1°; job.json's \"north\" says "
      "why not), magnetic (always; an error without a confident fit) or none";
  if (optional_mode) {
    help += ". Default: submit auto; merge what `carve` recorded in TILES/../north.json, else auto";
  }
  CLI::Option* north = cmd->add_option("--north", flags.mode, help);
  north->check(CLI::IsMember({"auto", "magnetic", "none"}));
  if (!optional_mode) north->capture_default_str();
  cmd->add_option("--location", flags.location,
                  "LAT,LON of the survey in degrees: turn to true north instead, by the World "
                  "Magnetic Model's declination there (WMM2025, built in)");
  cmd->add_option("--survey-date", flags.survey_date,
                  "YYYY-MM-DD of the survey, for --location (default: from the scan's times, "
                  "when they are dates)")
      ->needs("--location");
}

absl::StatusOr<ScanNorth> NorthOfScanForFlags(const std::string& scan_path,
                                              const NorthFlags& flags) {
  absl::StatusOr<NorthMode> mode = ParseNorthMode(flags.mode);
  if (!mode.ok()) return mode.status();
  std::optional<NorthPlace> place;
  if (!flags.location.empty()) {
    absl::StatusOr<NorthPlace> parsed =
        ParseNorthPlace(flags.location, flags.survey_date, "--location");
    if (!parsed.ok()) return parsed.status();
    place = *parsed;
  }
  return NorthOfScanFile(scan_path, *mode, place);
}

}  // namespace carvemap
