#include "services/system/usable_cpus.h"

#include <sched.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "services/system/cgroup_files.h"

namespace carvemap {
namespace {

std::optional<double> ParseNumber(std::string_view text) {
  std::istringstream in{std::string(text)};
  double v = 0;
  if (!(in >> v)) return std::nullopt;
  return v;
}

std::optional<double> QuotaCpus() {
  std::optional<double> cpus;
  auto take = [&](std::optional<double> c) {
    if (c && (!cpus || *c < *cpus)) cpus = c;
  };
  for (const std::string& file : CgroupV2Files("cpu.max")) {
    if (std::optional<std::string> t = ReadSmallFile(file)) take(CpusOfCpuMax(*t));
  }
  // v1 (hybrid hosts): the cpu controller as mounted in the process's namespace.
  for (const char* dir : {"/sys/fs/cgroup/cpu", "/sys/fs/cgroup/cpu,cpuacct"}) {
    std::optional<std::string> quota = ReadSmallFile(std::string(dir) + "/cpu.cfs_quota_us");
    std::optional<std::string> period = ReadSmallFile(std::string(dir) + "/cpu.cfs_period_us");
    if (quota && period) take(CpusOfCfsQuota(*quota, *period));
  }
  return cpus;
}

}  // namespace

std::optional<double> CpusOfCpuMax(std::string_view text) {
  std::istringstream in{std::string(text)};
  std::string quota, period;
  if (!(in >> quota >> period) || quota == "max") return std::nullopt;
  std::optional<double> q = ParseNumber(quota), p = ParseNumber(period);
  if (!q || !p || *q <= 0 || *p <= 0) return std::nullopt;
  return *q / *p;
}

std::optional<double> CpusOfCfsQuota(std::string_view quota_text, std::string_view period_text) {
  std::optional<double> q = ParseNumber(quota_text), p = ParseNumber(period_text);
  if (!q || !p || *q <= 0 || *p <= 0) return std::nullopt;
  return *q / *p;
}

int UsableCpus() {
  int cpus = 0;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0) cpus = CPU_COUNT(&set);
  if (cpus <= 0) cpus = static_cast<int>(std::thread::hardware_concurrency());
  if (std::optional<double> quota = QuotaCpus()) {
    cpus = std::min(cpus, static_cast<int>(std::ceil(*quota - 1e-9)));
  }
  return std::max(1, cpus);
}

}  // namespace carvemap
