#include "services/report/job_report.h"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "services/report/report_assets.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

absl::StatusOr<std::string> ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path.string(), ": cannot open"));
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// A level file's JSON, null when the file is absent.
absl::StatusOr<nlohmann::json> ReadJsonIfThere(const fs::path& path) {
  if (!fs::exists(path)) return nlohmann::json();
  absl::StatusOr<std::string> text = ReadAll(path);
  if (!text.ok()) return text.status();
  nlohmann::json j = nlohmann::json::parse(*text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return absl::DataLossError(absl::StrCat(path.string(), ": not JSON"));
  return j;
}

absl::Status WriteText(const fs::path& path, const std::string& text) {
  return WriteFileAtomically(path.string(), [&](std::ostream& out) { out << text; });
}

}  // namespace

absl::Status WriteJobReport(const std::string& out_dir, const nlohmann::json& job,
                            const ReportLibraries& libraries) {
  const fs::path out(out_dir);
  // The libraries first: without them there is no page to write.
  const std::vector<std::pair<fs::path, const char*>> libs = {
      {fs::path(libraries.three_dir) / "three.min.js", "libjs-three"},
      {fs::path(libraries.three_dir) / "examples/js/loaders/GLTFLoader.js", "libjs-three"},
      {fs::path(libraries.three_dir) / "examples/js/controls/OrbitControls.js", "libjs-three"},
      {fs::path(libraries.leaflet_dir) / "leaflet.js", "libjs-leaflet"},
      {fs::path(libraries.leaflet_dir) / "leaflet.css", "libjs-leaflet"},
  };
  for (const auto& [path, package] : libs) {
    if (!fs::is_regular_file(path)) {
      return absl::FailedPreconditionError(absl::StrCat(
          "report: ", path.string(), " is missing (Debian's ", package, " package provides it)"));
    }
  }
  std::error_code ec;
  fs::create_directories(out / "report" / "lib", ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat((out / "report").string(), ": cannot create: ", ec.message()));
  }
  for (const auto& [path, package] : libs) {
    absl::StatusOr<std::string> text = ReadAll(path);
    if (!text.ok()) return text.status();
    if (absl::Status s = WriteText(out / "report" / "lib" / path.filename(), *text); !s.ok()) {
      return s;
    }
  }

  // The job's data: job.json as given, and per level its plan and its top-down map's place.
  nlohmann::json data = {{"job", job}, {"levels", nlohmann::json::array()}, {"model", nullptr}};
  absl::StatusOr<nlohmann::json> levels = ReadJsonIfThere(out / "levels.json");
  if (!levels.ok()) return levels.status();
  const size_t num_levels = levels->is_array() ? levels->size() : 0;
  for (size_t k = 0; k < std::max<size_t>(num_levels, 1); ++k) {
    const std::string dir = absl::StrCat("level_", k);
    absl::StatusOr<nlohmann::json> plan = ReadJsonIfThere(out / dir / "floorplan.geojson");
    if (!plan.ok()) return plan.status();
    absl::StatusOr<nlohmann::json> topdown = ReadJsonIfThere(out / dir / "topdown.json");
    if (!topdown.ok()) return topdown.status();
    if (k >= num_levels && plan->is_null() && topdown->is_null()) break;
    nlohmann::json level = {{"index", k}, {"plan", *plan}, {"topdown", nullptr}};
    if (k < num_levels) {
      for (const char* key : {"floor_z", "ceiling_z"}) {
        if ((*levels)[k].contains(key)) level[key] = (*levels)[k][key];
      }
    }
    if (topdown->is_object() && topdown->value("image", std::string()) != "") {
      level["topdown"] = {{"image", dir + "/" + (*topdown)["image"].get<std::string>()},
                          {"origin_m", (*topdown)["origin_m"]},
                          {"resolution_m", (*topdown)["resolution_m"]},
                          {"width", (*topdown)["width"]},
                          {"height", (*topdown)["height"]}};
    }
    data["levels"].push_back(std::move(level));
  }
  if (fs::is_regular_file(out / "mesh" / "model.glb")) data["model"] = "mesh/model.glb";
  if (absl::Status s =
          WriteText(out / "report" / "data.js", "window.CARVEMAP = " + data.dump() + ";\n");
      !s.ok()) {
    return s;
  }
  if (absl::Status s = WriteText(out / "report" / "report.js", kReportJs); !s.ok()) return s;
  return WriteText(out / "index.html", kReportIndexHtml);
}

}  // namespace carvemap
