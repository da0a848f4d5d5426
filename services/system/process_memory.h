// This process's memory as the kernel counts it, and the most it may use: what sizes a
// Kubernetes pod's memory limit and what the merge checks its planar mesh against.
#ifndef CARVEMAP_SERVICES_SYSTEM_PROCESS_MEMORY_H_
#define CARVEMAP_SERVICES_SYSTEM_PROCESS_MEMORY_H_

#include <cstdint>
#include <optional>
#include <string_view>

namespace carvemap {

struct ProcessMemory {
  uint64_t resident_bytes = 0;       // VmRSS
  uint64_t peak_resident_bytes = 0;  // VmHWM: the largest VmRSS since the process started
};

// From the text of a /proc/<pid>/status; fields stay 0 where it does not say.
ProcessMemory ParseProcessMemory(std::string_view status);

// ParseProcessMemory of /proc/self/status.
ProcessMemory ReadProcessMemory();

// The bytes a cgroup v2 `memory.max` (or v1 `memory.limit_in_bytes`) text allows: nullopt for
// "max", for v1's "no limit" (a value of 2^62 or more) and for text that does not parse.
std::optional<uint64_t> BytesOfMemoryMax(std::string_view text);

// The smallest memory limit of the process's cgroup and its parents (v2), or of the memory
// controller (v1); nullopt when none is set.
std::optional<uint64_t> CgroupMemoryLimit();

// A memory budget in MiB as a user gives it: > 0 that many MiB; 0 = 90 % of
// CgroupMemoryLimit() (the rest for the allocator's slack and what no estimate counts), or no
// budget (0 bytes) when the process has no limit; < 0 = no budget.
uint64_t MemoryBudgetBytes(double mib);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_SYSTEM_PROCESS_MEMORY_H_
