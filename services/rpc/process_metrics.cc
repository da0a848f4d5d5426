#include "services/rpc/process_metrics.h"

#include <prometheus/exposer.h>
#include <prometheus/metric_family.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

#include <spdlog/spdlog.h>

#include "absl/strings/str_cat.h"
#include "services/system/process_memory.h"

namespace carvemap {
namespace {

prometheus::MetricFamily One(const std::string& name, const std::string& help,
                             prometheus::MetricType type, double value,
                             const std::string& service) {
  prometheus::MetricFamily f;
  f.name = name;
  f.help = help;
  f.type = type;
  prometheus::ClientMetric m;
  m.label.push_back({"service", service});
  if (type == prometheus::MetricType::Counter) {
    m.counter.value = value;
  } else {
    m.gauge.value = value;
  }
  f.metric.push_back(std::move(m));
  return f;
}

}  // namespace

ProcessStats ReadProcessStats() {
  ProcessStats s;
  const ProcessStatus status = ReadProcessStatus();
  s.threads = status.threads;
  s.resident_bytes = status.resident_bytes;
  s.peak_resident_bytes = status.peak_resident_bytes;
  {
    std::ifstream io("/proc/self/io");
    std::string line;
    while (std::getline(io, line)) {
      unsigned long long n = 0;
      if (std::sscanf(line.c_str(), "rchar: %llu", &n) == 1) s.read_bytes = n;
      if (std::sscanf(line.c_str(), "wchar: %llu", &n) == 1) s.written_bytes = n;
    }
  }
  std::error_code ec;
  int64_t fds = 0;
  for (std::filesystem::directory_iterator it("/proc/self/fd", ec), end; !ec && it != end;
       it.increment(ec)) {
    ++fds;
  }
  if (!ec) s.open_fds = fds - 1;  // less the iterator's own descriptor
  rusage ru{};
  if (getrusage(RUSAGE_SELF, &ru) == 0) {
    s.cpu_seconds = double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
                    1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  }
  return s;
}

double ProcessCollector::StartTime() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::vector<prometheus::MetricFamily> ProcessCollector::Collect() const {
  using prometheus::MetricType;
  const ProcessStats s = ReadProcessStats();
  std::vector<prometheus::MetricFamily> out;
  out.push_back(One("process_resident_memory_bytes", "Resident memory size in bytes",
                    MetricType::Gauge, double(s.resident_bytes), service_));
  out.push_back(One("carvemap_process_peak_resident_memory_bytes",
                    "Largest resident memory since the process started (VmHWM), bytes",
                    MetricType::Gauge, double(s.peak_resident_bytes), service_));
  out.push_back(One("process_cpu_seconds_total", "User and system CPU time spent in seconds",
                    MetricType::Counter, s.cpu_seconds, service_));
  out.push_back(One("process_threads", "Threads of the process", MetricType::Gauge,
                    double(s.threads), service_));
  if (s.open_fds >= 0) {
    out.push_back(One("process_open_fds", "Open file descriptors", MetricType::Gauge,
                      double(s.open_fds), service_));
  }
  out.push_back(One("process_start_time_seconds",
                    "Start time of the process since the Unix epoch in seconds",
                    MetricType::Gauge, start_time_s_, service_));
  if (s.read_bytes) {
    out.push_back(One("carvemap_process_read_bytes_total",
                      "Bytes read through read calls (files, page cache included, and sockets)",
                      MetricType::Counter, double(*s.read_bytes), service_));
  }
  if (s.written_bytes) {
    out.push_back(One("carvemap_process_written_bytes_total",
                      "Bytes written through write calls (files and sockets)",
                      MetricType::Counter, double(*s.written_bytes), service_));
  }
  return out;
}

MetricsEndpoint::MetricsEndpoint() = default;
MetricsEndpoint::MetricsEndpoint(MetricsEndpoint&&) noexcept = default;
MetricsEndpoint& MetricsEndpoint::operator=(MetricsEndpoint&&) noexcept = default;
MetricsEndpoint::~MetricsEndpoint() = default;

absl::StatusOr<MetricsEndpoint> ServeMetrics(
    const std::string& address,
    const std::vector<std::shared_ptr<prometheus::Collectable>>& collectables,
    const std::string& service) {
  MetricsEndpoint endpoint;
  try {
    endpoint.exposer = std::make_unique<prometheus::Exposer>(address, 1);
    endpoint.collectables = collectables;
    endpoint.collectables.push_back(std::make_shared<ProcessCollector>(service));
    for (const auto& c : endpoint.collectables) endpoint.exposer->RegisterCollectable(c);
    const std::vector<int> ports = endpoint.exposer->GetListeningPorts();
    endpoint.port = ports.empty() ? 0 : ports.front();
  } catch (const std::exception& e) {
    return absl::UnavailableError(
        absl::StrCat(service, ": cannot serve metrics on ", address, ": ", e.what()));
  }
  // The line tests and operators read the bound port from (with port 0).
  spdlog::info("{}: metrics on http://{}:{}/metrics", service,
               address.substr(0, address.rfind(':')), endpoint.port);
  return endpoint;
}

}  // namespace carvemap
