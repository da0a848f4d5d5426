// The §2.3 flags every command that reads a scan's path shares (--north, --location,
// --survey-date), and the turn they give for a scan (coordinator/scan_north.h).
#ifndef CARVEMAP_SERVICES_CLI_NORTH_FLAGS_H_
#define CARVEMAP_SERVICES_CLI_NORTH_FLAGS_H_

#include <string>

#include <CLI/CLI.hpp>

#include "absl/status/statusor.h"
#include "coordinator/scan_north.h"

namespace carvemap {

struct NorthFlags {
  std::string mode = "auto";  // "" when `optional_mode` and not given
  std::string location;       // "LAT,LON", or empty
  std::string survey_date;    // "YYYY-MM-DD", or empty (the scan's times)
};

// Adds --north, --location and --survey-date to `cmd`. With `optional_mode` --north has no
// default (flags.mode stays "" unless given).
void AddNorthFlags(CLI::App* cmd, NorthFlags& flags, bool optional_mode = false);

// The turn for `scan_path` (mode "" = auto).
absl::StatusOr<ScanNorth> NorthOfScanForFlags(const std::string& scan_path,
                                              const NorthFlags& flags);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_CLI_NORTH_FLAGS_H_
