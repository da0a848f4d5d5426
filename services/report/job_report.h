// The job report (docs/DESIGN.md §7 index.html): a self-contained page beside a job's outputs
// that shows its numbers, where the time went, each level's floor plan over its top-down map
// and the 3D model (mesh/model.glb) to orbit and click. No network: OUT/report/ holds the
// page's script, the job's data (data.js, so that the page also opens as a file) and copies of
// the viewers' libraries from Debian's libjs-three and libjs-leaflet.
//
// Files only, no logging: the merge writes it beside job.json, `carvemap report` rebuilds it.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "absl/status/status.h"

namespace carvemap {

// Where the libraries are read from (Debian's packages' folders).
struct ReportLibraries {
  std::string three_dir = "/usr/share/javascript/three";
  std::string leaflet_dir = "/usr/share/javascript/leaflet";
};

// Writes <out>/index.html, <out>/report/{report.js, data.js} and <out>/report/lib/ for the job
// document `job` (job.json's content), reading the level files the job's outputs hold
// (levels.json, level_<k>/floorplan.geojson, level_<k>/topdown.json); index.html last, each
// file through "<name>.partial" and a rename. Errors: FailedPrecondition naming a library file
// that is missing (and its Debian package); DataLoss naming a level file that is not JSON;
// the writes' errors, naming the file.
[[nodiscard]] absl::Status WriteJobReport(const std::string& out_dir, const nlohmann::json& job,
                                          const ReportLibraries& libraries = {});

}  // namespace carvemap
