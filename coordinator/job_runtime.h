// What the coordinator knows about a running job besides the job store (docs/DESIGN.md §8):
// its folders, its plan, the live counters not worth a store write (rays), the times of its
// stages; and what is made of them: the progress a watcher sees (docs/RPC.md WatchJob) and the
// document the merge starts job.json from. Plain data and functions; the service holds one per
// running job under its mutex.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "coordinator/job_params.h"
#include "coordinator/rate_window.h"
#include "coordinator/scan_slices.h"
#include "storage/job_store.h"

namespace carvemap {

// The stages a job went through ("ingest", "carve", "merge", "merge/<stage>") and how long
// each took, in the order first entered; a stage entered again (a merge retried on another
// merge service) is listed once, with its last run's time.
class StageTimes {
 public:
  using Time = std::chrono::steady_clock::time_point;
  struct Stage {
    std::string name;
    double elapsed_s = 0;
    bool finished = false;
  };
  // Ends the running stage at `now` and starts `stage` ("" = none runs).
  void Enter(const std::string& stage, Time now);
  [[nodiscard]] const std::string& running() const { return current_; }
  // Seconds in the running stage; 0 when none runs.
  [[nodiscard]] double RunningSeconds(Time now) const;
  // Every stage so far, the running one with its time up to `now`.
  [[nodiscard]] std::vector<Stage> List(Time now) const;
  // {stage: seconds} of the finished stages and of the running one as last entered (0).
  [[nodiscard]] nlohmann::json Seconds() const;

 private:
  std::map<std::string, std::pair<Time, double>> stages_;  // name → (start, seconds)
  std::vector<std::string> order_;
  std::optional<Time> start_;
  std::string current_;
};

struct JobRuntime {
  std::string tiles_dir;
  std::string partials_dir;  // <work>/<job>/partials: every pass's slices' partial sums
  std::string output_dir;
  std::string tenant_dir, input_path;  // the scan as the job names it (JobRecord)
  JobParams params;
  // The plan (scan_slices.h): made in INGESTING, made again (the same) by a restarted
  // coordinator. Slice k of pass p is the task SliceTaskKey(k, p).
  std::vector<ScanSlice> slices;
  double slice_s = 0;
  // §2.3's turn to north (scan_north.h), decided with the plan: every lease and the merge
  // read the scan turned by it; job.json's "north" records it.
  double world_yaw_rad = 0;
  nlohmann::json north = nlohmann::json::object();
  // The pass being carved: 0 the job's; ≥ 1 a re-carve of the merge (§5.6.1), whose partial
  // sums go to pass_dir and whose chunks and regions are in regions_path.
  int pass = 0;
  int passes = 0;  // re-carves so far
  std::string pass_dir, regions_path;
  std::vector<ChunkCoord> pass_chunks;       // a re-carve's chunks
  uint64_t merge_done = 0, merge_total = 0;  // the running merge stage's counts
  int64_t rays_carved = 0;    // the slices' own rays, as completed (CompleteChunk stats)
  int64_t rays_to_carve = 0;  // the slices' own rays, planned
  // Rays as the workers' heartbeats report them, mid-slice too: the live rate.
  RateWindow carve_rate;
  // Tasks completed: the ETA once every ray is carved and the chunks' combines remain.
  RateWindow task_rate;
  // What the slices of the job's carve measured (job.json "carve"): frames, rays, returns,
  // wedges, wedge-chunk pairs, votes, partial bytes; from `slices_counted` slices (fewer
  // than all after a restart: then job.json has no counts).
  nlohmann::json carve_counts = nlohmann::json::object();
  size_t slices_counted = 0;
  StageTimes stages;
};

// A watcher's view of a running job (WatchJob's Progress, docs/RPC.md).
struct JobProgress {
  int64_t rays_done = 0, rays_total = 0;
  double rays_per_s = 0;
  double eta_s = -1;                        // the running stage's seconds left; < 0: not known
  int64_t stage_done = 0, stage_total = 0;  // a merge stage's own counts
  std::vector<StageTimes::Stage> stages;
};

// While carving (CARVING, or the merge's re-carve of the object chunks, §5.6.1): the slices'
// rays carved as the heartbeats report them (never past the plan) and their rate over the
// window, the ETA from that rate, or, once every ray is carved and combines remain, from the
// tasks' own rate; while MERGING, the stage's counts and an ETA in proportion to them.
[[nodiscard]] JobProgress ProgressOf(const JobRuntime& rt, const JobCounters& counters,
                                     JobState state, StageTimes::Time now);

// What the merge starts job.json from: the job, its parameters, rays carved, chunks and
// retries (`counters`: the store's, when it could be read), the stages' seconds, the turn to
// north, and the carve's counts when every slice reported them (also under "ingest", the key
// earlier versions wrote).
[[nodiscard]] nlohmann::json MergeJobDocument(const JobRecord& job,
                                              const std::optional<JobCounters>& counters,
                                              const JobRuntime& rt);

}  // namespace carvemap
