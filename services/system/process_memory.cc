#include "services/system/process_memory.h"

#include <malloc.h>

#include <algorithm>
#include <cstdio>
#include <string>

#include "services/system/cgroup_files.h"

namespace carvemap {

ProcessStatus ParseProcessStatus(std::string_view status) {
  ProcessStatus m;
  for (size_t start = 0; start < status.size();) {
    const size_t end = std::min(status.find('\n', start), status.size());
    const std::string line(status.substr(start, end - start));
    start = end + 1;
    unsigned long long kib = 0;
    if (std::sscanf(line.c_str(), "VmRSS: %llu kB", &kib) == 1) m.resident_bytes = kib << 10;
    if (std::sscanf(line.c_str(), "VmHWM: %llu kB", &kib) == 1) m.peak_resident_bytes = kib << 10;
    long long threads = 0;
    if (std::sscanf(line.c_str(), "Threads: %lld", &threads) == 1) m.threads = threads;
  }
  return m;
}

ProcessStatus ReadProcessStatus() {
  return ParseProcessStatus(ReadSmallFile("/proc/self/status").value_or(""));
}

bool MapLargeBuffersAlone(size_t min_bytes) {
  // Setting the threshold also turns glibc's raising of it off, and with it the raising of the
  // trim threshold, which then stays at 128 KiB: each free that left more than that at the top
  // of a heap gave those pages back, and the next chunk's buffer of the same size faulted them
  // in again (half the merge's page faults; docs/BENCHMARKS.md "The merge's page faults"). What
  // a stage frees below the heaps' tops goes back at ReturnFreedMemory between stages.
  constexpr int kKeptAtHeapTop = 8 << 20;
  return mallopt(M_MMAP_THRESHOLD, static_cast<int>(min_bytes)) == 1 &&
         mallopt(M_TRIM_THRESHOLD, kKeptAtHeapTop) == 1;
}

bool ReturnFreedMemory() { return malloc_trim(0) == 1; }

std::optional<uint64_t> BytesOfMemoryMax(std::string_view text) {
  const std::string s(text);
  unsigned long long bytes = 0;
  int end = 0;
  if (std::sscanf(s.c_str(), " %llu%n", &bytes, &end) != 1) return std::nullopt;  // "max"
  if (s.find_first_not_of(" \t\n", end) != std::string::npos) return std::nullopt;
  // cgroup v1 writes its "no limit" as the largest page-aligned signed 64-bit value.
  if (bytes >= (1ull << 62)) return std::nullopt;
  return bytes;
}

std::optional<uint64_t> CgroupMemoryLimit() {
  std::optional<uint64_t> limit;
  auto take = [&](std::optional<uint64_t> b) {
    if (b && (!limit || *b < *limit)) limit = b;
  };
  for (const std::string& file : CgroupV2Files("memory.max")) {
    if (std::optional<std::string> t = ReadSmallFile(file)) take(BytesOfMemoryMax(*t));
  }
  if (std::optional<std::string> t = ReadSmallFile("/sys/fs/cgroup/memory/memory.limit_in_bytes")) {
    take(BytesOfMemoryMax(*t));
  }
  return limit;
}

uint64_t MemoryBudgetBytes(double mib) {
  if (mib > 0) return static_cast<uint64_t>(mib * (1 << 20));
  if (mib < 0) return 0;
  const std::optional<uint64_t> limit = CgroupMemoryLimit();
  return limit ? *limit / 10 * 9 : 0;
}

}  // namespace carvemap
