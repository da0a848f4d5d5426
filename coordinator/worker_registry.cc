#include "coordinator/worker_registry.h"

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace carvemap {

std::string WorkerRegistry::Register(int64_t now_ms) {
  std::string id = absl::StrCat("w-", instance_, "-", next_++);
  last_seen_[id] = now_ms;
  return id;
}

bool WorkerRegistry::Touch(const std::string& id, int64_t now_ms) {
  auto it = last_seen_.find(id);
  if (it == last_seen_.end()) return false;
  it->second = now_ms;
  return true;
}

std::vector<std::string> WorkerRegistry::Ids() const {
  std::vector<std::string> ids;
  ids.reserve(last_seen_.size());
  for (const auto& [id, seen] : last_seen_) ids.push_back(id);
  return ids;
}

void WorkerRegistry::SetJob(const std::string& id, std::string job_id) {
  if (Known(id)) job_of_[id] = std::move(job_id);
}

std::string WorkerRegistry::JobOf(const std::string& id) const {
  auto it = job_of_.find(id);
  return it == job_of_.end() ? std::string() : it->second;
}

void WorkerRegistry::CreditLateness(int64_t late_ms, int64_t now_ms) {
  if (late_ms <= 0) return;
  for (auto& [id, seen] : last_seen_) seen = std::min(now_ms, seen + late_ms);
}

std::vector<std::pair<std::string, int64_t>> WorkerRegistry::RemoveSilent(int64_t now_ms,
                                                                          int64_t timeout_ms) {
  std::vector<std::pair<std::string, int64_t>> lost;
  for (auto it = last_seen_.begin(); it != last_seen_.end();) {
    if (now_ms - it->second <= timeout_ms) {
      ++it;
      continue;
    }
    lost.emplace_back(it->first, now_ms - it->second);
    job_of_.erase(it->first);
    it = last_seen_.erase(it);
  }
  return lost;
}

}  // namespace carvemap
