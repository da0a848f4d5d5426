// A job's way through its states (docs/RPC.md "Job states"): QUEUED → INGESTING → CARVING →
// MERGING → SUCCEEDED, or FAILED with the failing stage's reason, and where a restarted
// coordinator picks a job up (docs/JOB_STORE.md). Plain code over the job store and an
// injected clock; the stages' own work is JobStages', which the coordinator's service
// implements around its lease table and merge client.
#pragma once

#include <string>

#include "absl/status/status.h"
#include "coordinator/lease_table.h"  // LeaseTable::Clock
#include "storage/job_store.h"

namespace carvemap {

// What the runner asks of the coordinator around it.
class JobStages {
 public:
  virtual ~JobStages() = default;
  // INGESTING: check the scan, plan its slices and store them as the job's first tasks.
  // Cancelled when the job ended meanwhile (a cancel) or the coordinator stops.
  virtual absl::Status Ingest(const JobRecord& job) = 0;
  // CARVING: until every task of the job's carve is done. Cancelled as Ingest.
  virtual absl::Status Carve(const JobRecord& job) = 0;
  // MERGING: the outputs. Cancelled as Ingest.
  virtual absl::Status Merge(const JobRecord& job) = 0;
  // The job's running stage, for its timings: "ingest", "carve", "merge".
  virtual void EnterStage(const std::string& job_id, const std::string& stage) = 0;
  // A stage's error as the job's tenant may read it (coordinator/job_folders.h TenantView).
  virtual std::string TenantView(const std::string& job_id, const std::string& text) = 0;
  // The store moved the job from `from` to `to` (`reason`: the raw error of a FAILED).
  virtual void Moved(const std::string& job_id, JobState from, JobState to,
                     const std::string& reason) = 0;
  // A transition the store refused (the job was cancelled meanwhile, or the store failed).
  virtual void NotMoved(const std::string& job_id, JobState to, const absl::Status& why) = 0;
  // The job ended here (not called when the coordinator stops: the next one resumes it).
  virtual void CleanUp(const std::string& job_id, bool succeeded) = 0;
  // The coordinator is stopping: a stage that fails now leaves the job as it is stored.
  virtual bool Stopping() = 0;
};

// Runs job `job_id` from the state it is stored in until it is terminal, or until a stage
// gives up because the coordinator stops. A restart finds: QUEUED or INGESTING without tasks
// → ingest again; INGESTING with tasks stored → carve; CARVING → carve (the tasks done stay
// done); MERGING → merge again. A stage's error fails the job ("<stage>: <error>", in the
// tenant's view) unless it is Cancelled (the job ended meanwhile). An empty scan (no tasks)
// goes from INGESTING to MERGING. Returns the state the job was left in, or the store's error
// when the job cannot be read.
absl::StatusOr<JobState> RunJob(const std::string& job_id, JobStore& store, JobStages& stages,
                                LeaseTable::Clock& clock);

}  // namespace carvemap
