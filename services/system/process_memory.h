// This process's memory as the kernel counts it, and the most it may use: what sizes a
// Kubernetes pod's memory limit and what the merge checks its planar mesh against.
#ifndef CARVEMAP_SERVICES_SYSTEM_PROCESS_MEMORY_H_
#define CARVEMAP_SERVICES_SYSTEM_PROCESS_MEMORY_H_

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

namespace carvemap {

// What /proc/<pid>/status says of a process's memory and threads.
struct ProcessStatus {
  uint64_t resident_bytes = 0;       // VmRSS
  uint64_t peak_resident_bytes = 0;  // VmHWM: the largest VmRSS since the process started
  int64_t threads = 0;               // Threads
};

// From the text of a /proc/<pid>/status; fields stay 0 where it does not say.
ProcessStatus ParseProcessStatus(std::string_view status);

// ParseProcessStatus of /proc/self/status.
ProcessStatus ReadProcessStatus();

// Has the allocator map each buffer of `min_bytes` or more on its own (glibc's M_MMAP_THRESHOLD),
// so that a stage's large buffers go back to the system when it frees them. By default glibc
// raises that threshold to the largest buffer freed so far (up to 32 MiB); after that, buffers
// below it come from the heap, and what one stage freed stays resident under the next one's
// peak. Smaller buffers freed at a heap's top stay there up to 8 MiB (M_TRIM_THRESHOLD) for the
// next one, as glibc's own raising of the thresholds would have kept them. For a process that
// runs stages one after another (the merge). Returns false when the allocator refuses.
bool MapLargeBuffersAlone(size_t min_bytes = size_t{1} << 20);

// Gives the system back the whole free pages inside the allocator's heaps (glibc's
// malloc_trim). A stage that makes and frees millions of small blocks (the planar regions'
// groups) leaves them free but resident, scattered below blocks still in use, where the next
// stage's peak sits on top of them. Returns whether any memory was given back. Costs a walk
// over the free lists: call it between stages, not in loops.
bool ReturnFreedMemory();

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
// What the merge's MemoryBudgetBytes flag means, for the `--help` of every command that takes it.
inline constexpr char kMergeMemoryBudgetHelp[] =
    "Memory the merge may use, MiB: a building whose planar mesh would not fit fails with why "
    "before it is made. 0: 90 % of the cgroup's memory limit (a pod's limit), none without one; "
    "< 0: no budget";

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_SYSTEM_PROCESS_MEMORY_H_
