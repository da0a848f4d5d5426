// The coordinator's in-process merge step (CoordinatorSpec::merge).
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "absl/strings/str_cat.h"
#include "services/merge/first_outputs.h"
#include "services/rpc/coordinator_service.h"

namespace carvemap {

MergeFunction FirstOutputsMerge() {
  return [](const MergeJobRequest& req) -> absl::Status {
    MergeOptions options;
    options.tiles_dir = req.tiles_dir;
    options.output_dir = req.output_dir;
    options.resolution_m = req.resolution_m;
    nlohmann::json job = nlohmann::json::parse(req.job_json, nullptr, /*allow_exceptions=*/false);
    options.job = job.is_object() ? job : nlohmann::json::object({{"job_id", req.job_id}});
    absl::StatusOr<MergeSummary> summary = MergeFirstOutputs(options);
    if (!summary.ok()) return summary.status();
    spdlog::info("merge: job {}: {} tiles, {} leaves -> {} in {:.1f} s", req.job_id,
                 summary->num_tiles, summary->num_leaves, req.output_dir, summary->seconds_total);
    return absl::OkStatus();
  };
}

}  // namespace carvemap
