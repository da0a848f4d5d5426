// The coordinator's in-process merge step (CoordinatorSpec::merge).
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "absl/strings/str_cat.h"
#include "services/merge/merge_job.h"
#include "services/rpc/coordinator_service.h"

namespace carvemap {

MergeFunction FirstOutputsMerge() {
  return [](const MergeJobRequest& req) -> absl::Status {
    MergeOptions options;
    options.tiles_dir = req.tiles_dir;
    options.output_dir = req.output_dir;
    options.scan_path = req.scan_path;
    options.resolution_m = req.resolution_m;
    options.object_resolution_m = req.object_resolution_m;
    options.recarve = req.recarve;
    nlohmann::json job = nlohmann::json::parse(req.job_json, nullptr, /*allow_exceptions=*/false);
    options.job = job.is_object() ? job : nlohmann::json::object({{"job_id", req.job_id}});
    MergeProgressCallback progress;
    if (req.progress) {
      progress = [&req](const MergeProgress& p) { return req.progress(p.stage, p.done, p.total); };
    }
    absl::StatusOr<MergeSummary> summary = RunMerge(options, progress);
    if (!summary.ok()) return summary.status();
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
