// How many CPUs this process may really use: the CPUs it may run on (its affinity mask, what a
// cpuset or `taskset` gives) capped by its cgroup's CPU quota (what a Kubernetes CPU limit
// sets). std::thread::hardware_concurrency() counts the machine's CPUs and sees neither, so a
// pod limited to 2 CPUs on a 64-core node would start 64 threads and be throttled.
#ifndef CARVEMAP_SERVICES_SYSTEM_USABLE_CPUS_H_
#define CARVEMAP_SERVICES_SYSTEM_USABLE_CPUS_H_

#include <optional>
#include <string_view>

namespace carvemap {

// The CPUs a cgroup v2 `cpu.max` text allows ("max 100000": no limit, nullopt; "150000 100000":
// 1.5). nullopt for text that does not parse.
std::optional<double> CpusOfCpuMax(std::string_view text);

// The same from cgroup v1's cpu.cfs_quota_us and cpu.cfs_period_us (quota -1: no limit).
std::optional<double> CpusOfCfsQuota(std::string_view quota_text, std::string_view period_text);

// max(1, min(affinity CPUs, ceil(quota CPUs))), the quota read from the process's cgroup (v2:
// its own and every parent's cpu.max; v1: the cpu controller's quota) where there is one.
int UsableCpus();

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_SYSTEM_USABLE_CPUS_H_
