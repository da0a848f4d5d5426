// Carving throughput against OctoMap, single thread, same rays, same resolution:
//   carve_bench [walk seconds = 10] [rate Hz = 10] [beam step deg = 1] [preset = office2]
// 1. simulates the preset (seed 1, noise on) for the first seconds of its walk;
// 2. carves it on one thread as one time slice (worker/slice_carver.h: reading, noise model,
//    wedges, binning, eq 4.7/4.8 into partial sums) and combines every chunk
//    (worker/chunk_combiner.h: §4.3.2 simplification, tile write), once with each evaluation of
//    eq 4.7 (worker/chunk_octree.h: exact, the reference, and fast), and compares the two
//    carves' tiles (tests/support/tile_agreement.h);
// 3. inserts the same rays into an octomap::OcTree at the same resolution with
//    insertPointCloud (origin = the sensor position of the frame, end = the point mean; rays
//    without return skipped), one call per frame;
// and prints rays/s of each, their ratios, and tile and partial-sums bytes per ray. Rays are the
// scan's returns (what both carve). Then the cost per unit of work: carvemap's leaf votes (eq 4.8)
// against OctoMap's key updates (computeUpdate's sets, counted outside its timing).
// The work goes under $TMPDIR/carve_bench; with CARVE_BENCH_KEEP=1 it is kept (the fast carve's
// partial sums and tiles in fast/), to compare two builds' carves byte for byte.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <octomap/OcTree.h>

#include "coordinator/scan_slices.h"
#include "geometry/carve_map.h"
#include "services/sim/simulator.h"
#include "storage/partial_sums.h"
#include "storage/scan_reader.h"
#include "storage/tile_store.h"
#include "tests/support/tile_agreement.h"
#include "worker/chunk_combiner.h"
#include "worker/chunk_octree.h"
#include "worker/slice_carver.h"

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

  // --- carvemap: the scan carved as one time slice on this thread (read, noise model, wedges,
  //     binning, eq 4.7/4.8, partial sums), then every chunk combined (§4.3.2, tile write);
  //     once with each evaluation.
  absl::StatusOr<OctreeGrid> grid = OctreeGrid::FromResolution(resolution_m);
  if (!grid.ok()) return Fail(grid.status());
  absl::StatusOr<std::unique_ptr<ScanReader>> scan = ScanReader::Open(sim->scan_path);
  if (!scan.ok()) return Fail(scan.status());
  std::vector<std::vector<FrameRecord>> frames;
  std::vector<SensorKind> kinds;
  for (size_t i = 0; i < (*scan)->sensors().size(); ++i) {
    absl::StatusOr<std::vector<FrameRecord>> f = (*scan)->FrameRecords(int(i));
    if (!f.ok()) return Fail(f.status());
    frames.push_back(*std::move(f));
    kinds.push_back((*scan)->sensors()[i].kind);
  }
  absl::StatusOr<std::vector<ScanSlice>> slices = PlanSlices(frames, kinds, 1e9);
  if (!slices.ok() || slices->size() != 1) return Fail(absl::InternalError("no slice"));
  struct Carve {
    const char* name = "";
    CarveEvaluation evaluation = CarveEvaluation::kFast;
    std::string dir;
    double cpu_s = 0, wall_s = 0, combine_cpu_s = 0;
    uint64_t tile_bytes = 0, leaves = 0, updates = 0, pairs = 0, partial_bytes = 0;
    std::map<ChunkKey, TileData, ChunkKeyLess> tiles;
  };
  Carve carves[2];
  carves[0].name = "exact";
  carves[0].evaluation = CarveEvaluation::kExact;
  carves[0].dir = root + "/exact";
  carves[1].name = "fast";
  carves[1].evaluation = CarveEvaluation::kFast;
  carves[1].dir = root + "/fast";
  uint64_t returns = 0;
  for (Carve& carve : carves) {
    fs::create_directories(carve.dir);
    SliceCarveOptions options;
    options.grid = *grid;
    options.evaluation = carve.evaluation;
    const std::string partial = carve.dir + "/slice_0.part";
    Clock::time_point t0 = Clock::now();
    double c0 = ThreadCpuS();
    absl::StatusOr<SliceCarveStats> st =
        CarveSliceToFile(**scan, slices->front(), options, partial);
    if (!st.ok()) return Fail(st.status());
    carve.wall_s = Seconds(t0);
    carve.cpu_s = ThreadCpuS() - c0;
    carve.updates = st->leaf_updates;
    carve.pairs = st->wedge_chunk_pairs;
    carve.partial_bytes = fs::file_size(partial);
    returns = st->returns;
    c0 = ThreadCpuS();
    std::vector<PartialSource> sources;
    absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(partial);
    if (!index.ok()) return Fail(index.status());
    sources.push_back({partial, *std::move(index)});
    for (const auto& [chunk, sections] : GroupSections(sources)) {
      CombineChunkRequest req;
      req.chunk = chunk;
      req.grid = *grid;
      req.sources = &sources;
      req.sections = sections;
      req.tiles_dir = carve.dir + "/tiles";
      absl::StatusOr<CarveChunkResult> r = CombineChunkToTile(req);
      if (!r.ok()) return Fail(r.status());
      carve.tile_bytes += r->tile_bytes;
      carve.leaves += r->leaves;
      absl::StatusOr<TileData> tile = ReadTile(r->tile_path);
      if (!tile.ok()) return Fail(tile.status());
      carve.tiles.emplace(chunk, *std::move(tile));
    }
    carve.combine_cpu_s = ThreadCpuS() - c0;
  }
  // The fast carve against the exact one, chunk by chunk.
  testing::TileAgreement agreement;
  for (const auto& [chunk, tile] : carves[0].tiles) {
    auto it = carves[1].tiles.find(chunk);
    testing::AddTilePair(&tile, it == carves[1].tiles.end() ? nullptr : &it->second, agreement);
  }

  // --- OctoMap on the same rays.
  std::unique_ptr<ScanReader>& reader = *scan;
  octomap::OcTree tree(resolution_m);
  std::unique_ptr<ScanReader::FrameStream> stream = reader->StreamFrames();
  ScanFrame frame;
  double octomap_s = 0, octomap_cpu_s = 0;
  uint64_t octomap_rays = 0, octomap_updates = 0;
  octomap::Pointcloud cloud;
  octomap::KeySet free_keys, occupied_keys;
  while (true) {
    absl::StatusOr<bool> more = stream->Next(frame);
    if (!more.ok()) return Fail(more.status());
    if (!*more) break;
    const SensorInfo& s = reader->sensors()[frame.sensor];
    const Pose pose = reader->PoseAt(frame.t);
    const Eigen::Vector3d origin = pose * s.T_s2c;
    cloud.clear();
    for (const Eigen::Vector3f& p : frame.points_sensor) {
      if (!p.allFinite()) continue;
      const Eigen::Vector3d w = pose * (s.R_s2c * p.cast<double>() + s.T_s2c);
      cloud.push_back(float(w.x()), float(w.y()), float(w.z()));
    }
    octomap_rays += cloud.size();
    const Clock::time_point t0 = Clock::now();
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

  const double rays = double(returns);
  const double theirs = octomap_rays / octomap_cpu_s;
  std::printf("%s seed 1, %.0f s walk, %.1f Hz, %.2f deg beams, %.4f m: %llu returns\n",
              preset.c_str(), walk_s, rate_hz, beam_deg, resolution_m,
              static_cast<unsigned long long>(returns));
  for (const Carve& c : carves) {
    std::printf("carvemap, %s (1 thread): slice %.2f CPU s (%.2f s wall) + combine %.2f CPU s: "
                "%.0f rays/s per core; %llu leaf votes (%.1f per ray), %.1f ns per vote, %llu "
                "wedge-chunk pairs, %llu leaves; ratio to octomap %.3f\n",
                c.name, c.cpu_s, c.wall_s, c.combine_cpu_s, rays / (c.cpu_s + c.combine_cpu_s),
                static_cast<unsigned long long>(c.updates), c.updates / rays,
                1e9 * (c.cpu_s + c.combine_cpu_s) / double(c.updates),
                static_cast<unsigned long long>(c.pairs), static_cast<unsigned long long>(c.leaves),
                rays / (c.cpu_s + c.combine_cpu_s) / theirs);
  }
  std::printf("fast / exact: %.2fx the rays/s; labels equal on %.6f of %llu finest leaves, "
              "|dp| <= 0.01 on %.6f of %llu stored leaves (|dp| p99 %.3g, max %.3g)\n",
              (carves[0].cpu_s + carves[0].combine_cpu_s) /
                  (carves[1].cpu_s + carves[1].combine_cpu_s),
              agreement.LabelShare(), static_cast<unsigned long long>(agreement.finest_leaves),
              agreement.PShare(), static_cast<unsigned long long>(agreement.stored_leaves),
              agreement.DpQuantile(0.99), agreement.max_dp);
  std::printf("octomap insertPointCloud (1 thread): %.2f CPU s (%.2f s wall), %.0f rays/s per "
              "core, %zu nodes, %llu key updates (%.1f per ray), %.1f ns per key update\n",
              octomap_cpu_s, octomap_s, theirs, tree.size(),
              static_cast<unsigned long long>(octomap_updates),
              octomap_updates / double(octomap_rays), 1e9 * octomap_cpu_s / double(octomap_updates));
  std::printf("tile bytes/ray: %.1f, partial sums bytes/ray: %.1f\n", carves[1].tile_bytes / rays,
              carves[1].partial_bytes / rays);
  const char* keep = std::getenv("CARVE_BENCH_KEEP");
  if (keep == nullptr || std::string(keep) != "1") fs::remove_all(root);
  return 0;
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) { return carvemap::Main(argc, argv); }
