#include "coordinator/job_plan.h"

#include <filesystem>
#include <optional>
#include <set>

#include "absl/strings/str_cat.h"
#include "storage/partial_sums.h"
#include "storage/scan_reader.h"

namespace carvemap {

absl::StatusOr<JobPlan> PlanJob(const std::string& scan_path, const JobParams& params) {
  ScanReader::OpenOptions open;
  open.path_rows = ScanReader::PathRows::kNone;
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(scan_path, open);
  if (!reader.ok()) return reader.status();
  absl::StatusOr<ScanSlicePlan> slices = PlanScanSlices(**reader, SlicePlanOptions{});
  if (!slices.ok()) return slices.status();
  std::optional<NorthPlace> place;
  if (!params.location.empty()) {
    // Checked at submit; a place that no longer parses turns to magnetic north.
    absl::StatusOr<NorthPlace> p = ParseNorthPlace(params.location, params.survey_date, "location");
    if (p.ok()) place = *p;
  }
  absl::StatusOr<ScanNorth> north = NorthOfScan(**reader, params.north, place);
  if (!north.ok()) return north.status();
  return JobPlan{*std::move(slices), *std::move(north)};
}

std::vector<ChunkRecord> SliceTasks(const std::string& job_id, std::span<const ScanSlice> slices,
                                    int pass) {
  std::vector<ChunkRecord> records;
  records.reserve(slices.size());
  for (const ScanSlice& s : slices) {
    ChunkRecord r;
    r.job_id = job_id;
    r.key = SliceTaskKey(s.index, pass);
    r.wedge_count = int64_t(s.own_rays);
    records.push_back(std::move(r));
  }
  return records;
}

std::string SlicePartialPath(const std::string& dir, uint32_t index) {
  return (std::filesystem::path(dir) / absl::StrCat("slice_", index, ".part")).string();
}

absl::StatusOr<std::vector<ChunkCoord>> ChunksOfPartials(std::span<const std::string> paths) {
  std::set<ChunkCoord> chunks;
  for (const std::string& p : paths) {
    absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(p);
    if (!index.ok()) return index.status();
    for (const PartialSection& s : index->sections) {
      chunks.insert({s.chunk.x(), s.chunk.y(), s.chunk.z()});
    }
  }
  return std::vector<ChunkCoord>(chunks.begin(), chunks.end());
}

}  // namespace carvemap
