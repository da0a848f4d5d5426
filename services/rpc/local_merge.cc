// LocalMerge (services/rpc/merge_request.h): RunMerge in this process.
#include <optional>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "absl/strings/str_cat.h"
#include "services/merge/merge_job.h"
#include "services/rpc/merge_request.h"
#include "storage/confined_path.h"

namespace carvemap {

MergeFunction LocalMerge(uint64_t memory_budget_bytes) {
  return [memory_budget_bytes](const MergeJobRequest& req) -> absl::Status {
    MergeOptions options;
    static_cast<MergeParams&>(options) = req.params;
    options.tiles_dir = req.tiles_dir;
    options.output_dir = req.output_dir;
    options.recarve = req.recarve;
    options.memory_budget_bytes = memory_budget_bytes;
    // The scan through the descriptor checked here (ConfinedFile: "/proc/self/fd/N"), as the
    // ingest reads it; its errors then name the path as the tenant gave it.
    std::optional<ConfinedFile> scan;
    if (!req.scan_input.empty()) {
      absl::StatusOr<ConfinedFile> opened =
          ConfinedFile::Open(req.scan_root, req.scan_input, "input_path");
      if (!opened.ok()) return opened.status();
      scan.emplace(*std::move(opened));
      options.scan_path = scan->path();
    }
    nlohmann::json job = nlohmann::json::parse(req.job_json, nullptr, /*allow_exceptions=*/false);
    options.job = job.is_object() ? job : nlohmann::json::object({{"job_id", req.job_id}});
    MergeProgressCallback progress;
    if (req.progress) {
      progress = [&req](const MergeProgress& p) { return req.progress(p.stage, p.done, p.total); };
    }
    absl::StatusOr<MergeSummary> summary = RunMerge(options, progress);
    if (!summary.ok()) return scan ? scan->Rename(summary.status()) : summary.status();
    spdlog::info(
        "merge: job {}: {} tiles, {} leaves, {} levels, {} planar regions, dense {} / planar {} "
        "triangles -> {} in {:.1f} s",
        req.job_id, summary->num_tiles, summary->num_leaves, summary->num_levels,
        summary->num_planar_regions, summary->dense_triangles, summary->building_triangles,
        req.output_dir, summary->seconds_total);
    for (const std::string& w : summary->warnings) {
      spdlog::warn("merge: job {}: {}", req.job_id, w);
    }
    return absl::OkStatus();
  };
}

}  // namespace carvemap
