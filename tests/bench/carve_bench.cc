// Carving throughput against OctoMap, single thread, same rays, same resolution:
//   carve_bench [walk seconds = 10] [rate Hz = 10] [beam step deg = 1] [preset = office2]
// 1. simulates the preset (seed 1, noise on) for the first seconds of its walk;
// 2. ingests it (wedges ➜ spill files) and carves every chunk on one thread with
//    CarveChunkToTile (decode, eq 4.8 carving, §4.3.2 simplification, tile write);
// 3. inserts the same rays into an octomap::OcTree at the same resolution with
//    insertPointCloud (origin = the sensor position of the frame, end = the point mean; rays
//    without return skipped), one call per frame;
// and prints rays/s of both, their ratio, and tile/spill bytes per ray. Rays are the scan's
// returns (what both carve). Then the cost per unit of work: carvemap's leaf votes (eq 4.8)
// against OctoMap's key updates (computeUpdate's sets, counted outside its timing), and the
// arithmetic of a vote alone (eq 4.7 by EvaluateMany and the sums, on the scan's own rays at
// points along them, no leaf listing): the floor that any listing of the leaves adds to.
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
  uint64_t spill_bytes = 0, tile_bytes = 0, leaves = 0, updates = 0, touches = 0;
  double carve_s = 0, read_s = 0, carve_cpu_s = 0;
  for (const SpilledChunk& c : ingest->chunks) {
    spill_bytes += c.file_bytes;
    t0 = Clock::now();
    absl::StatusOr<ChunkSpillFile> f = ReadChunkSpillFile(c.path);
    if (!f.ok()) return Fail(f.status());
    read_s += Seconds(t0);
    CarveChunkRequest req;
    req.chunk = c.chunk;
    req.grid = *grid;
    req.wedge_payload = f->payload;
    req.tiles_dir = root + "/tiles";
    t0 = Clock::now();
    const double c0 = ThreadCpuS();
    absl::StatusOr<CarveChunkResult> r = CarveChunkToTile(req);
    if (!r.ok()) return Fail(r.status());
    carve_s += Seconds(t0);
    carve_cpu_s += ThreadCpuS() - c0;
    tile_bytes += r->tile_bytes;
    leaves += r->leaves;
    updates += r->leaf_updates;
    touches += r->leaf_touches;
  }

  // --- The arithmetic of the votes alone: every chunk's rays prepared once, each evaluated at
  //     kPerRay points from its sensor to 3σ past its point, up to two leaves across it as in
  //     a wedge, into a small array of sums (in cache, as a chunk's leaves mostly are).
  constexpr size_t kPerRay = 256;
  std::vector<double> par(kPerRay), lat_a(kPerRay), lat_b(kPerRay), vp(kPerRay), vw(kPerRay);
  std::vector<LeafStats> sums(kPerRay);
  double arith_cpu_s = 0;
  uint64_t arith_votes = 0;
  for (const SpilledChunk& c : ingest->chunks) {
    absl::StatusOr<ChunkSpillFile> f = ReadChunkSpillFile(c.path);
    if (!f.ok()) return Fail(f.status());
    absl::StatusOr<IndexedWedges> decoded = DecodeWedgePayload(f->payload);
    if (!decoded.ok()) return Fail(decoded.status());
    const double c0 = ThreadCpuS();
    for (const RayModel& model : decoded->rays) {
      absl::StatusOr<PreparedRay> ray = PreparedRay::Make(model);
      if (!ray.ok()) continue;
      const double end = ray->length() + 3 * ray->point_sigma_along();
      for (size_t i = 0; i < kPerRay; ++i) {
        par[i] = end * double(i) / kPerRay;
        lat_a[i] = resolution_m * (double(i % 5) - 2);
        lat_b[i] = resolution_m * (double(i % 3) - 1);
      }
      ray->EvaluateMany(par.data(), lat_a.data(), lat_b.data(), kPerRay, vp.data(), vw.data());
      // Counted as the carve counts its votes: the sums a point gets (w ≥ kMinRayWeight), so
      // points evaluated to no weight cost time but count nothing, as in the carve.
      for (size_t i = 0; i < kPerRay; ++i) {
        if (vw[i] < kMinRayWeight) continue;
        sums[i].Add(vp[i], vw[i]);
        ++arith_votes;
      }
    }
    arith_cpu_s += ThreadCpuS() - c0;
  }
  double checksum = 0;  // keeps the sums alive
  for (const LeafStats& l : sums) checksum += l.sum_wp;

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
  const double ours = rays / carve_cpu_s;
  const double theirs = octomap_rays / octomap_cpu_s;
  std::printf("%s seed 1, %.0f s walk, %.1f Hz, %.2f deg beams, %.4f m: %llu rays, %llu returns\n",
              preset.c_str(), walk_s, rate_hz, beam_deg, resolution_m,
              static_cast<unsigned long long>(ingest->rays),
              static_cast<unsigned long long>(ingest->returns));
  std::printf("ingest (1 thread): %.2f CPU s (%.2f s wall), %.0f rays/s per core, %llu wedges, "
              "%llu chunks, %llu wedge-chunk pairs\n",
              ingest_cpu_s, ingest_s, rays / ingest_cpu_s,
              static_cast<unsigned long long>(ingest->wedges),
              static_cast<unsigned long long>(ingest->chunks.size()),
              static_cast<unsigned long long>(ingest->wedge_chunk_pairs));
  std::printf("carvemap carve (1 thread): %.2f CPU s (%.2f s wall), %.0f rays/s per core "
              "(+ %.2f s reading spill files), %llu leaf updates (%.1f per ray), %llu leaf "
              "touches (%.1f per wedge-chunk pair), %llu leaves\n",
              carve_cpu_s, carve_s, ours, read_s, static_cast<unsigned long long>(updates),
              updates / double(ingest->returns), static_cast<unsigned long long>(touches),
              touches / double(ingest->wedge_chunk_pairs), static_cast<unsigned long long>(leaves));
  std::printf("octomap insertPointCloud (1 thread): %.2f CPU s (%.2f s wall), %.0f rays/s per "
              "core, %zu nodes, %llu key updates (%.1f per ray)\n",
              octomap_cpu_s, octomap_s, theirs, tree.size(),
              static_cast<unsigned long long>(octomap_updates), octomap_updates / double(octomap_rays));
  // Per unit of work rather than per ray: carvemap's leaf updates are eq 4.8 votes (eq 4.7
  // evaluated at the leaf), OctoMap's are log-odds additions to a key.
  std::printf("time per update: carvemap %.1f ns per leaf vote, octomap %.1f ns per key update\n",
              1e9 * carve_cpu_s / double(updates), 1e9 * octomap_cpu_s / double(octomap_updates));
  std::printf("eq 4.7 + 4.8 arithmetic alone: %.1f ns per vote over %llu votes (checksum %.3g); "
              "at %.1f votes per ray that is %.0f rays/s per core, %.2f of octomap's\n",
              1e9 * arith_cpu_s / double(arith_votes),
              static_cast<unsigned long long>(arith_votes), checksum, updates / rays,
              double(arith_votes) / arith_cpu_s / (updates / rays),
              double(arith_votes) / arith_cpu_s / (updates / rays) / theirs);
  std::printf("ratio carvemap/octomap: %.3f (carving); %.3f (ingest + carving: %.0f rays/s)\n",
              ours / theirs, rays / (ingest_cpu_s + carve_cpu_s) / theirs,
              rays / (ingest_cpu_s + carve_cpu_s));
  std::printf("tile bytes/ray: %.1f, spill bytes/ray: %.1f\n", tile_bytes / rays,
              spill_bytes / rays);
  fs::remove_all(root);
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }
