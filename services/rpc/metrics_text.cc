#include "services/rpc/metrics_text.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"

namespace carvemap {
namespace {

bool ParseValue(absl::string_view text, double& out) {
  if (text == "+Inf" || text == "Inf") {
    out = std::numeric_limits<double>::infinity();
    return true;
  }
  if (text == "-Inf") {
    out = -std::numeric_limits<double>::infinity();
    return true;
  }
  if (text == "NaN") {
    out = std::numeric_limits<double>::quiet_NaN();
    return true;
  }
  return absl::SimpleAtod(text, &out);
}

bool Matches(const MetricSample& s, absl::string_view name, const MetricLabels& match) {
  if (s.name != name) return false;
  for (const auto& [k, v] : match) {
    auto it = s.labels.find(k);
    if (it == s.labels.end() || it->second != v) return false;
  }
  return true;
}

}  // namespace

absl::StatusOr<std::vector<MetricSample>> ParsePrometheusText(absl::string_view text) {
  std::vector<MetricSample> out;
  int line_no = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_no;
    line = absl::StripAsciiWhitespace(line);
    if (line.empty() || line.front() == '#') continue;
    auto bad = [&](absl::string_view why) {
      return absl::InvalidArgumentError(absl::StrCat("metrics line ", line_no, ": ", why));
    };
    MetricSample s;
    size_t i = 0;
    while (i < line.size() && line[i] != '{' && line[i] != ' ' && line[i] != '\t') ++i;
    s.name = std::string(line.substr(0, i));
    if (s.name.empty()) return bad("no metric name");
    if (i < line.size() && line[i] == '{') {
      ++i;
      while (true) {
        while (i < line.size() && (line[i] == ' ' || line[i] == ',')) ++i;
        if (i < line.size() && line[i] == '}') {
          ++i;
          break;
        }
        const size_t eq = line.find('=', i);
        if (eq == absl::string_view::npos || eq + 1 >= line.size() || line[eq + 1] != '"') {
          return bad("label without =\"value\"");
        }
        std::string key(absl::StripAsciiWhitespace(line.substr(i, eq - i)));
        std::string value;
        size_t j = eq + 2;
        for (; j < line.size() && line[j] != '"'; ++j) {
          if (line[j] == '\\' && j + 1 < line.size()) {
            ++j;
            value.push_back(line[j] == 'n' ? '\n' : line[j]);
          } else {
            value.push_back(line[j]);
          }
        }
        if (j >= line.size()) return bad("unterminated label value");
        s.labels[key] = value;
        i = j + 1;
      }
    }
    std::vector<absl::string_view> rest =
        absl::StrSplit(line.substr(i), absl::ByAnyChar(" \t"), absl::SkipEmpty());
    if (rest.empty() || !ParseValue(rest[0], s.value)) return bad("no number after the name");
    out.push_back(std::move(s));
  }
  return out;
}

double SumOf(const std::vector<MetricSample>& samples, absl::string_view name,
             const MetricLabels& match) {
  double sum = 0;
  for (const MetricSample& s : samples) {
    if (Matches(s, name, match)) sum += s.value;
  }
  return sum;
}

double HistogramQuantile(const std::vector<MetricSample>& samples, absl::string_view name,
                         double q, const MetricLabels& match) {
  const std::string bucket = absl::StrCat(name, "_bucket");
  std::map<double, double> cumulative;  // le → count, summed over the matching series
  for (const MetricSample& s : samples) {
    if (!Matches(s, bucket, match)) continue;
    auto le = s.labels.find("le");
    double bound = 0;
    if (le == s.labels.end() || !ParseValue(le->second, bound)) continue;
    cumulative[bound] += s.value;
  }
  if (cumulative.empty()) return std::numeric_limits<double>::quiet_NaN();
  const double total = cumulative.rbegin()->second;
  if (!(total > 0)) return std::numeric_limits<double>::quiet_NaN();
  const double rank = std::clamp(q, 0.0, 1.0) * total;
  double lower = 0, below = 0;
  for (const auto& [bound, count] : cumulative) {
    if (count >= rank) {
      if (std::isinf(bound)) return lower;  // the largest finite bound
      const double in_bucket = count - below;
      return in_bucket > 0 ? lower + (bound - lower) * (rank - below) / in_bucket : bound;
    }
    lower = bound;
    below = count;
  }
  return lower;
}

std::string FormatCoordinatorMetrics(const std::vector<MetricSample>& samples) {
  std::string line = absl::StrFormat(
      "workers %d  chunks %d queued / %d leased / %d done  %.2f M rays/s  lease expiries %d  "
      "workers lost %d  refused calls %d",
      static_cast<int64_t>(SumOf(samples, "carvemap_workers")),
      static_cast<int64_t>(SumOf(samples, "carvemap_chunks", {{"state", "queued"}})),
      static_cast<int64_t>(SumOf(samples, "carvemap_chunks", {{"state", "leased"}})),
      static_cast<int64_t>(SumOf(samples, "carvemap_chunks", {{"state", "done"}})),
      SumOf(samples, "carvemap_rays_per_second") * 1e-6,
      static_cast<int64_t>(SumOf(samples, "carvemap_lease_expiries_total")),
      static_cast<int64_t>(SumOf(samples, "carvemap_workers_lost_total")),
      static_cast<int64_t>(SumOf(samples, "carvemap_calls_unauthenticated_total")));
  // The busiest methods first, with their latency.
  constexpr char kRpc[] = "carvemap_rpc_duration_seconds";
  std::set<std::string> methods;
  for (const MetricSample& s : samples) {
    if (s.name == absl::StrCat(kRpc, "_count") && s.labels.count("method")) {
      methods.insert(s.labels.at("method"));
    }
  }
  std::vector<std::pair<double, std::string>> busiest;
  for (const std::string& m : methods) {
    busiest.emplace_back(SumOf(samples, absl::StrCat(kRpc, "_count"), {{"method", m}}), m);
  }
  std::sort(busiest.rbegin(), busiest.rend());
  if (!busiest.empty()) absl::StrAppend(&line, "  RPC p50/p99 ms:");
  for (size_t i = 0; i < busiest.size() && i < 4; ++i) {
    const std::string& m = busiest[i].second;
    absl::StrAppendFormat(&line, " %s %.1f/%.1f (%d)", m,
                          1e3 * HistogramQuantile(samples, kRpc, 0.5, {{"method", m}}),
                          1e3 * HistogramQuantile(samples, kRpc, 0.99, {{"method", m}}),
                          static_cast<int64_t>(busiest[i].first));
  }
  return line;
}

}  // namespace carvemap
