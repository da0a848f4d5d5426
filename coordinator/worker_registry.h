// The workers a coordinator knows (docs/RPC.md RegisterWorker, Heartbeat): the ids it hands
// out, when each was last heard from, and the job of each one's latest lease (whose work its
// heartbeats report). Plain data; the caller passes the time (its clock, or a test's) and
// holds the lock.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace carvemap {

class WorkerRegistry {
 public:
  // `instance` tells this coordinator's worker ids from a previous one's (a worker still
  // holding an old id after a restart is told to register again, not mistaken for another).
  explicit WorkerRegistry(std::string instance) : instance_(std::move(instance)) {}

  // A new worker, heard from at now_ms: "w-<instance>-<n>", n counting from 1.
  std::string Register(int64_t now_ms);
  // Heard from at now_ms. False for an id it does not know (never registered, or lost).
  bool Touch(const std::string& id, int64_t now_ms);
  [[nodiscard]] bool Known(const std::string& id) const { return last_seen_.count(id) > 0; }
  [[nodiscard]] size_t size() const { return last_seen_.size(); }
  [[nodiscard]] std::vector<std::string> Ids() const;  // in id order

  // The job of the worker's latest lease; "" when none (or the worker is unknown).
  void SetJob(const std::string& id, std::string job_id);
  [[nodiscard]] std::string JobOf(const std::string& id) const;

  // A sweep that ran `late_ms` late (waiting for the lock or for a core) could not hear
  // heartbeats either: every worker is credited that time, up to now_ms, so that the
  // coordinator's own delay does not count against it.
  void CreditLateness(int64_t late_ms, int64_t now_ms);
  // Forgets the workers silent for more than timeout_ms at now_ms and returns them with how
  // long each was silent (ms), in id order.
  std::vector<std::pair<std::string, int64_t>> RemoveSilent(int64_t now_ms, int64_t timeout_ms);

 private:
  std::string instance_;
  int64_t next_ = 1;
  std::map<std::string, int64_t> last_seen_;  // id → ms
  std::map<std::string, std::string> job_of_;
};

}  // namespace carvemap
