// Carving throughput against OctoMap, single thread, same rays, same resolution:
//   carve_bench [walk seconds = 10] [rate Hz = 10] [beam step deg = 1] [preset = office2]
// 1. simulates the preset (seed 1, noise on) for the first seconds of its walk;
// 2. ingests it (wedges ➜ spill files) and carves every chunk on one thread with
//    CarveChunkToTile (decode, eq 4.8 carving, §4.3.2 simplification, tile write), once with
//    each evaluation of eq 4.7 (worker/chunk_octree.h: exact, the reference, and fast), and
//    compares the two carves' tiles (tests/support/tile_agreement.h);
// 3. inserts the same rays into an octomap::OcTree at the same resolution with
//    insertPointCloud (origin = the sensor position of the frame, end = the point mean; rays
//    without return skipped), one call per frame;
// and prints rays/s of each, their ratios, and tile/spill bytes per ray. Rays are the scan's
// returns (what both carve). Then the cost per unit of work: carvemap's leaf votes (eq 4.8)
// against OctoMap's key updates (computeUpdate's sets, counted outside its timing).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <octomap/OcTree.h>

#include "coordinator/scan_ingest.h"
#include "services/geometry/carve_map.h"
#include "services/sim/simulator.h"
#include "tests/support/tile_agreement.h"
#include "storage/scan_reader.h"
#include "storage/wedge_codec.h"
#include "worker/chunk_carver.h"
#include "worker/chunk_octree.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

// CPU seconds of this thread: the machines are shared, so wall time includes other jobs;
// rays per CPU-second is rays/s per core. Both are printed.
double ThreadCpuS() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + ts.tv_nsec * 1e-9;
}

int Fail(const absl::Status& s) {
  std::fprintf(stderr, "carve_bench: %s\n", std::string(s.message()).c_str());
  return 1;
}

int Main(int argc, char** argv) {
  const double walk_s = argc > 1 ? std::atof(argv[1]) : 10.0;
  const double rate_hz = argc > 2 ? std::atof(argv[2]) : 10.0;
  const double beam_deg = argc > 3 ? std::atof(argv[3]) : 1.0;
  const std::string preset = argc > 4 ? argv[4] : "office2";
  const double resolution_m = 0.0625;
  const std::string root = (fs::temp_directory_path() / "carve_bench").string();
  fs::remove_all(root);

  SimulateOptions so;
  so.preset = preset;
  so.seed = 1;
  so.rig.rate_hz = rate_hz;
  so.rig.beam_step_deg = beam_deg;
  so.max_duration_s = walk_s;
  so.output_dir = root + "/sim";
  absl::StatusOr<SimulationSummary> sim = Simulate(so);
  if (!sim.ok()) return Fail(sim.status());

  // --- carvemap: ingest, then carve every chunk on this thread.
  Clock::time_point t0 = Clock::now();
  const double ingest_c0 = ThreadCpuS();
  IngestOptions io;
  io.scan_path = sim->scan_path;
  io.spill_dir = root + "/spill";
  absl::StatusOr<IngestResult> ingest = IngestScan(io);
  if (!ingest.ok()) return Fail(ingest.status());
  const double ingest_s = Seconds(t0);
  const double ingest_cpu_s = ThreadCpuS() - ingest_c0;
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(resolution_m);
  if (!grid.ok()) return Fail(grid.status());
  uint64_t spill_bytes = 0;
  for (const SpilledChunk& c : ingest->chunks) spill_bytes += c.file_bytes;
  struct Carve {
    const char* name;
    CarveEvaluation evaluation;
    std::string tiles;
    double cpu_s = 0, wall_s = 0;
    uint64_t tile_bytes = 0, leaves = 0, updates = 0, touches = 0;
  };
  Carve carves[2] = {{"exact", CarveEvaluation::kExact, root + "/tiles_exact"},
                     {"fast", CarveEvaluation::kFast, root + "/tiles_fast"}};
  double read_s = 0;
  for (const SpilledChunk& c : ingest->chunks) {
    t0 = Clock::now();
    absl::StatusOr<ChunkSpillFile> f = ReadChunkSpillFile(c.path);
    if (!f.ok()) return Fail(f.status());
    read_s += Seconds(t0);
    for (Carve& carve : carves) {
      CarveChunkRequest req;
      req.chunk = c.chunk;
      req.grid = *grid;
      req.wedge_payload = f->payload;
      req.tiles_dir = carve.tiles;
      req.evaluation = carve.evaluation;
      t0 = Clock::now();
      const double c0 = ThreadCpuS();
      absl::StatusOr<CarveChunkResult> r = CarveChunkToTile(req);
      if (!r.ok()) return Fail(r.status());
      carve.wall_s += Seconds(t0);
      carve.cpu_s += ThreadCpuS() - c0;
      carve.tile_bytes += r->tile_bytes;
      carve.leaves += r->leaves;
      carve.updates += r->leaf_updates;
      carve.touches += r->leaf_touches;
    }
  }
  // The fast carve against the exact one, chunk by chunk.
  testing::TileAgreement agreement;
  for (const SpilledChunk& c : ingest->chunks) {
    absl::StatusOr<TileData> exact = ReadTile(carves[0].tiles + "/" + TileFileName(c.chunk));
    absl::StatusOr<TileData> fast = ReadTile(carves[1].tiles + "/" + TileFileName(c.chunk));
    if (!exact.ok()) return Fail(exact.status());
    if (!fast.ok()) return Fail(fast.status());
    testing::AddTilePair(&*exact, &*fast, agreement);
  }

  // --- OctoMap on the same rays.
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(sim->scan_path);
  if (!reader.ok()) return Fail(reader.status());
  octomap::OcTree tree(resolution_m);
  std::unique_ptr<ScanReader::FrameStream> stream = (*reader)->StreamFrames();
  ScanFrame frame;
  double octomap_s = 0, octomap_cpu_s = 0;
  uint64_t octomap_rays = 0, octomap_updates = 0;
  octomap::Pointcloud cloud;
  octomap::KeySet free_keys, occupied_keys;
  while (true) {
    absl::StatusOr<bool> more = stream->Next(frame);
    if (!more.ok()) return Fail(more.status());
    if (!*more) break;
    const SensorInfo& s = (*reader)->sensors()[frame.sensor];
    const Pose pose = (*reader)->PoseAt(frame.t);
    const Eigen::Vector3d origin = pose * s.T_s2c;
    cloud.clear();
    for (const Eigen::Vector3f& p : frame.points_sensor) {
      if (!p.allFinite()) continue;
      const Eigen::Vector3d w = pose * (s.R_s2c * p.cast<double>() + s.T_s2c);
      cloud.push_back(float(w.x()), float(w.y()), float(w.z()));
    }
    octomap_rays += cloud.size();
    t0 = Clock::now();
    const double c0 = ThreadCpuS();
    tree.insertPointCloud(cloud, octomap::point3d(float(origin.x()), float(origin.y()),
                                                  float(origin.z())));
    octomap_s += Seconds(t0);
    octomap_cpu_s += ThreadCpuS() - c0;
    // What that call updated, counted outside the timing: insertPointCloud updates each key
    // of computeUpdate's free and occupied sets once (a frame's rays share their keys).
    free_keys.clear();
    occupied_keys.clear();
    tree.computeUpdate(cloud, octomap::point3d(float(origin.x()), float(origin.y()),
                                               float(origin.z())),
                       free_keys, occupied_keys, -1.0);
    octomap_updates += free_keys.size() + occupied_keys.size();
  }

  const double rays = double(ingest->returns);
  const double theirs = octomap_rays / octomap_cpu_s;
  std::printf("%s seed 1, %.0f s walk, %.1f Hz, %.2f deg beams, %.4f m: %llu rays, %llu returns\n",
              preset.c_str(), walk_s, rate_hz, beam_deg, resolution_m,
              static_cast<unsigned long long>(ingest->rays),
              static_cast<unsigned long long>(ingest->returns));
  std::printf("ingest (1 thread): %.2f CPU s (%.2f s wall), %.0f rays/s per core, %llu wedges, "
              "%llu chunks, %llu wedge-chunk pairs (+ %.2f s reading spill files)\n",
              ingest_cpu_s, ingest_s, rays / ingest_cpu_s,
              static_cast<unsigned long long>(ingest->wedges),
              static_cast<unsigned long long>(ingest->chunks.size()),
              static_cast<unsigned long long>(ingest->wedge_chunk_pairs), read_s);
  for (const Carve& c : carves) {
    std::printf("carvemap carve, %s (1 thread): %.2f CPU s (%.2f s wall), %.0f rays/s per core, "
                "%llu leaf votes (%.1f per ray), %.1f ns per vote, %llu leaf touches (%.1f per "
                "wedge-chunk pair), %llu leaves; ratio to octomap %.3f (carving), %.3f (ingest + "
                "carving)\n",
                c.name, c.cpu_s, c.wall_s, rays / c.cpu_s,
                static_cast<unsigned long long>(c.updates), c.updates / rays,
                1e9 * c.cpu_s / double(c.updates), static_cast<unsigned long long>(c.touches),
                c.touches / double(ingest->wedge_chunk_pairs),
                static_cast<unsigned long long>(c.leaves), rays / c.cpu_s / theirs,
                rays / (ingest_cpu_s + c.cpu_s) / theirs);
  }
  std::printf("fast / exact: %.2fx the rays/s; labels equal on %.6f of %llu finest leaves, "
              "|dp| <= 0.01 on %.6f of %llu stored leaves (|dp| p99 %.3g, max %.3g)\n",
              carves[0].cpu_s / carves[1].cpu_s, agreement.LabelShare(),
              static_cast<unsigned long long>(agreement.finest_leaves), agreement.PShare(),
              static_cast<unsigned long long>(agreement.stored_leaves),
              agreement.DpQuantile(0.99), agreement.max_dp);
  std::printf("octomap insertPointCloud (1 thread): %.2f CPU s (%.2f s wall), %.0f rays/s per "
              "core, %zu nodes, %llu key updates (%.1f per ray), %.1f ns per key update\n",
              octomap_cpu_s, octomap_s, theirs, tree.size(),
              static_cast<unsigned long long>(octomap_updates),
              octomap_updates / double(octomap_rays), 1e9 * octomap_cpu_s / double(octomap_updates));
  std::printf("tile bytes/ray: %.1f, spill bytes/ray: %.1f\n", carves[1].tile_bytes / rays,
              spill_bytes / rays);
  fs::remove_all(root);
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }
