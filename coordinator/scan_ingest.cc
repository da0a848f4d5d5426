// IngestScan: scan.h5 ➜ wedges ➜ per-chunk spill files (DESIGN §5).
#include "coordinator/scan_ingest.h"

#include <chrono>
#include <memory>
#include <span>
#include <utility>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Every error of IngestScan names the scan file; lower layers (the wedge builder, the
// spiller) name what they know, so the file is prefixed unless already there.
absl::Status NameFile(const std::string& file, const absl::Status& s) {
  if (s.ok() || absl::StrContains(s.message(), file)) return s;
  return absl::Status(s.code(), absl::StrCat("scan_ingest ", file, ": ", s.message()));
}

// Progress is reported at most this often: the callback may redraw a terminal line or send
// an RPC, and frames arrive thousands of times a second.
constexpr double kProgressPeriodS = 0.5;

}  // namespace

absl::Status IngestOptions::Validate() const {
  if (scan_path.empty()) return absl::InvalidArgumentError("scan_ingest: no scan path");
  if (spill_dir.empty()) return absl::InvalidArgumentError("scan_ingest: no spill directory");
  if (memory_budget_bytes == 0) {
    return absl::InvalidArgumentError("scan_ingest: memory_budget_bytes must be > 0");
  }
  if (auto s = wedges.Validate(); !s.ok()) return s;
  ChunkSpillOptions spill{spill_dir, memory_budget_bytes, sigmas};
  return spill.Validate();
}

absl::StatusOr<IngestResult> IngestScan(const IngestOptions& options,
                                        const IngestProgressCallback& progress) {
  const Clock::time_point t0 = Clock::now();
  if (auto s = options.Validate(); !s.ok()) return s;

  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(options.scan_path);
  if (!reader.ok()) return NameFile(options.scan_path, reader.status());
  ScanReader& scan = **reader;
  // Validate reads every row once more, but a bad row found half-way through carving would
  // leave a job with half its chunks spilled; failing up front names the row instead.
  if (auto s = scan.Validate(); !s.ok()) return NameFile(scan.file(), s);

  absl::StatusOr<std::unique_ptr<ChunkSpiller>> spiller = ChunkSpiller::Create(
      ChunkSpillOptions{options.spill_dir, options.memory_budget_bytes, options.sigmas});
  if (!spiller.ok()) return spiller.status();
  ChunkSpiller& spill = **spiller;

  IngestResult result;
  result.bounds.setEmpty();
  WedgeSink sink = [&](const Wedge& wedge, std::span<const RayId> ids) -> absl::Status {
    for (int i = 0; i < wedge.num_rays; ++i) {
      result.bounds.extend(wedge.rays[i].sensor_mean.cast<double>());
      result.bounds.extend(wedge.rays[i].point_mean.cast<double>());
    }
    return spill.Add(wedge, ids);
  };
  IngestProgress p;
  for (int s = 0; s < static_cast<int>(scan.sensors().size()); ++s) {
    p.frames_total += scan.frame_count(s);
  }
  double last_report_s = 0;
  auto after_frame = [&](const WedgeBuilderStats& st) {
    if (!progress) return;
    const double now_s = SecondsSince(t0);
    if (now_s - last_report_s < kProgressPeriodS) return;
    last_report_s = now_s;
    p.frames_done = st.frames;
    p.rays = st.rays;
    p.wedges = st.wedges + st.single_ray_wedges;
    p.elapsed_s = now_s;
    progress(p);
  };
  absl::StatusOr<WedgeBuilderStats> built =
      BuildWedges(scan, options.wedges, std::move(sink), after_frame);
  if (!built.ok()) return NameFile(scan.file(), built.status());
  absl::StatusOr<std::vector<SpilledChunk>> chunks = spill.Finish();
  if (!chunks.ok()) return NameFile(scan.file(), chunks.status());

  const WedgeBuilderStats& st = *built;
  result.chunks = *std::move(chunks);
  result.frames = st.frames;
  result.rays = st.rays;
  result.returns = st.rays - st.rays_without_return;
  result.wedges = st.wedges + st.single_ray_wedges;
  result.single_ray_wedges = st.single_ray_wedges;
  result.wedge_chunk_pairs = spill.records_written();
  result.default_covariance = st.default_covariance;
  result.elapsed_s = SecondsSince(t0);
  if (progress) {
    p.frames_done = st.frames;
    p.rays = st.rays;
    p.wedges = result.wedges;
    p.elapsed_s = result.elapsed_s;
    progress(p);
  }
  return result;
}

}  // namespace carvemap
