// Reading the Prometheus text format (what the coordinator's /metrics serves) back into
// numbers, for `carvemap watch --metrics` and the tests: samples, sums over label sets, and
// histogram quantiles the way PromQL's histogram_quantile computes them (linear within the
// bucket). Plain code. The exposition format:
// https://prometheus.io/docs/instrumenting/exposition_formats/ (text format 0.0.4).
#ifndef CARVEMAP_SERVICES_RPC_METRICS_TEXT_H_
#define CARVEMAP_SERVICES_RPC_METRICS_TEXT_H_

#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace carvemap {

struct MetricSample {
  std::string name;  // e.g. "carvemap_rpc_duration_seconds_bucket"
  std::map<std::string, std::string> labels;
  double value = 0;
};
using MetricLabels = std::map<std::string, std::string>;

// Every sample line; comments (# HELP, # TYPE) skipped. INVALID_ARGUMENT naming the line for
// anything else that does not parse.
absl::StatusOr<std::vector<MetricSample>> ParsePrometheusText(absl::string_view text);

// Sum of the samples called `name` whose labels include all of `match`; 0 if none.
double SumOf(const std::vector<MetricSample>& samples, absl::string_view name,
             const MetricLabels& match = {});

// Quantile q (0..1) of histogram `name` (its "<name>_bucket" series, summed over every
// label set that includes `match`), interpolated linearly inside the bucket holding the
// rank; the largest finite bound if the rank falls in +Inf. NaN without observations.
double HistogramQuantile(const std::vector<MetricSample>& samples, absl::string_view name,
                         double q, const MetricLabels& match = {});

// One line for `carvemap watch --metrics`: workers, chunks queued/leased/done, rays/s, lease
// expiries, lost workers, refused calls, and p50/p99 of the busiest RPC methods.
std::string FormatCoordinatorMetrics(const std::vector<MetricSample>& samples);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_METRICS_TEXT_H_
