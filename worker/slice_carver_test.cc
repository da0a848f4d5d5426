// The carve by time slices (SliceCarver, then CombineChunkToTile) against the carve of whole
// chunks (every wedge of the scan binned into its chunks in scan order, each chunk carved in
// one ChunkOctree call): the same votes, so the same tiles up to the order of the additions;
// the same bytes for the same slices whatever the order they are carved in; §5.6.1's
// restricted pass.
#include "worker/slice_carver.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <span>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "absl/container/flat_hash_map.h"
#include "coordinator/chunk_binning.h"
#include "coordinator/wedge_builder.h"
#include "geometry/wedge_geometry.h"
#include "services/sim/simulator.h"
#include "storage/partial_sums.h"
#include "storage/tile_store.h"
#include "tests/support/tile_agreement.h"
#include "worker/chunk_combiner.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

class SliceCarverTest : public ::testing::Test {
 protected:
  // The `office` preset at 10 Hz, 1° beams, 20 s: three line scanners, several rooms, sensors
  // whose frames interleave (and drift, so rays are wide and wedges long).
  static void SetUpTestSuite() {
    root_ = new std::string(fs::path(::testing::TempDir()) / "slice_carver_test");
    fs::remove_all(*root_);
    SimulateOptions o;
    o.preset = "office";
    o.seed = 5;
    o.rig.rate_hz = 10;
    o.rig.beam_step_deg = 1;
    o.max_duration_s = 20;
    o.output_dir = *root_ + "/sim";
    absl::StatusOr<SimulationSummary> sim = Simulate(o);
    ASSERT_TRUE(sim.ok()) << sim.status();
    scan_ = new std::string(sim->scan_path);
    // The reference: whole chunks, exactly. Every wedge binned into the chunks its hull
    // touches, in scan order, each ray once per chunk (eq 4.8's set); one carve per chunk.
    std::map<ChunkKey, IndexedWedges, ChunkKeyLess> bins;
    std::map<ChunkKey, absl::flat_hash_map<std::tuple<uint32_t, uint64_t, uint32_t>, uint32_t>,
             ChunkKeyLess>
        ray_index;
    absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(*scan_);
    ASSERT_TRUE(reader.ok()) << reader.status();
    absl::StatusOr<WedgeBuilderStats> built = BuildWedges(
        **reader, WedgeBuilderOptions{},
        [&](const Wedge& wedge, std::span<const RayId> ids) -> absl::Status {
          uint64_t facets = 0;
          for (const ChunkKey& c : ChunksOfWedge(MakeWedgeHull(wedge, 3.0, &facets))) {
            IndexedWedges& bin = bins[c];
            WedgeRef ref;
            ref.num_rays = wedge.num_rays;
            ref.facets = facets;
            for (int r = 0; r < wedge.num_rays; ++r) {
              auto [it, inserted] = ray_index[c].try_emplace(
                  {ids[r].sensor, ids[r].frame, ids[r].index}, uint32_t(bin.rays.size()));
              if (inserted) bin.rays.push_back(wedge.rays[r]);
              ref.ray[r] = it->second;
            }
            bin.wedges.push_back(ref);
          }
          return absl::OkStatus();
        });
    ASSERT_TRUE(built.ok()) << built.status();
    reference_ = new std::map<ChunkKey, TileData, ChunkKeyLess>();
    for (const auto& [chunk, bin] : bins) {
      OctreeGrid grid;
      grid.chunk_depth = 5;
      ChunkOctree tree(grid, chunk);
      tree.SetEvaluation(CarveEvaluation::kExact);
      ASSERT_TRUE(tree.CarveIndexed(bin).ok());
      tree.Simplify();
      reference_->emplace(chunk, tree.ToTile("j"));
    }
  }
  static void TearDownTestSuite() {
    delete root_;
    delete scan_;
    delete reference_;
  }

  // The reader's scan cut into slices of `slice_s`.
  static absl::StatusOr<std::vector<ScanSlice>> SlicesOf(ScanReader& reader, double slice_s) {
    std::vector<std::vector<FrameRecord>> frames;
    std::vector<SensorKind> kinds;
    for (size_t s = 0; s < reader.sensors().size(); ++s) {
      absl::StatusOr<std::vector<FrameRecord>> rows = reader.FrameRecords(int(s));
      if (!rows.ok()) return rows.status();
      frames.push_back(*std::move(rows));
      kinds.push_back(reader.sensors()[s].kind);
    }
    return PlanSlices(frames, kinds, slice_s);
  }

  // Plans slices of `slice_s`, carves them in `order` (indices into the plan) with `options`,
  // combines every chunk; returns the tiles by chunk and the partial files by slice.
  struct Carved {
    std::map<ChunkKey, TileData, ChunkKeyLess> tiles;
    std::vector<std::string> partials;
    uint64_t slices = 0, leaf_updates = 0, batches = 0, flushes = 0;
  };
  // `own_poses`: each slice through a reader holding only its poses (SliceOpenOptions), as
  // the workers read; else one reader of the whole path.
  static Carved CarveBySlices(const std::string& name, double slice_s, SliceCarveOptions options,
                              bool reversed = false, bool own_poses = false) {
    Carved out;
    absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(*scan_);
    EXPECT_TRUE(reader.ok()) << reader.status();
    absl::StatusOr<std::vector<ScanSlice>> slices = SlicesOf(**reader, slice_s);
    EXPECT_TRUE(slices.ok()) << slices.status();
    out.slices = slices->size();
    const std::string dir = *root_ + "/" + name;
    fs::create_directories(dir);
    std::vector<size_t> order(slices->size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = reversed ? order.size() - 1 - i : i;
    out.partials.resize(slices->size());
    for (size_t i : order) {
      const ScanSlice& s = (*slices)[i];
      out.partials[i] = dir + "/slice_" + std::to_string(s.index) + ".part";
      ScanReader* from = reader->get();
      std::unique_ptr<ScanReader> own;
      if (own_poses) {
        absl::StatusOr<std::unique_ptr<ScanReader>> r =
            ScanReader::Open(*scan_, SliceOpenOptions(s));
        EXPECT_TRUE(r.ok()) << r.status();
        if (!r.ok()) return out;
        own = *std::move(r);
        EXPECT_LT(own->timed_path().size(), (*reader)->timed_path().size());
        from = own.get();
      }
      absl::StatusOr<SliceCarveStats> st = CarveSliceToFile(*from, s, options, out.partials[i]);
      EXPECT_TRUE(st.ok()) << st.status();
      if (!st.ok()) return out;
      out.leaf_updates += st->leaf_updates;
      out.batches += st->batches;
      out.flushes += st->flushes;
    }
    std::vector<PartialSource> sources;
    for (const std::string& p : out.partials) {
      absl::StatusOr<PartialSumsIndex> index = ReadPartialIndex(p);
      EXPECT_TRUE(index.ok()) << index.status();
      sources.push_back({p, *index});
    }
    for (const auto& [chunk, sections] : GroupSections(sources)) {
      CombineChunkRequest req;
      req.job_id = "j";
      req.chunk = chunk;
      req.grid = options.grid;
      req.sources = &sources;
      req.sections = sections;
      req.tiles_dir = dir + "/tiles";
      absl::StatusOr<CarveChunkResult> r = CombineChunkToTile(req);
      EXPECT_TRUE(r.ok()) << r.status();
      absl::StatusOr<TileData> tile = ReadTile(r->tile_path);
      EXPECT_TRUE(tile.ok()) << tile.status();
      out.tiles.emplace(chunk, *std::move(tile));
    }
    return out;
  }

  static SliceCarveOptions Options(CarveEvaluation e) {
    SliceCarveOptions o;
    o.grid.chunk_depth = 5;
    o.evaluation = e;
    return o;
  }

  // Tiles equal node for node, counts and points equal, sums within `relative` (and the
  // wedges carved the same, unless wedges joining slices or batches were carved twice).
  static void ExpectSameTiles(const std::map<ChunkKey, TileData, ChunkKeyLess>& a,
                              const std::map<ChunkKey, TileData, ChunkKeyLess>& b,
                              double relative, bool same_wedges = true) {
    ASSERT_EQ(a.size(), b.size());
    size_t leaves = 0;
    for (const auto& [chunk, tile] : a) {
      auto it = b.find(chunk);
      ASSERT_NE(it, b.end()) << chunk.transpose();
      ASSERT_EQ(tile.leaves.size(), it->second.leaves.size()) << chunk.transpose();
      if (same_wedges) {
        EXPECT_EQ(tile.params.num_wedges, it->second.params.num_wedges) << chunk.transpose();
      } else {
        EXPECT_GE(it->second.params.num_wedges, tile.params.num_wedges) << chunk.transpose();
      }
      for (size_t i = 0; i < tile.leaves.size(); ++i) {
        const TileLeaf& x = tile.leaves[i];
        const TileLeaf& y = it->second.leaves[i];
        ASSERT_EQ(x.node.local, y.node.local) << chunk.transpose();
        ASSERT_EQ(x.node.depth, y.node.depth);
        ASSERT_EQ(x.stats.count, y.stats.count);
        ASSERT_EQ(x.stats.points, y.stats.points);
        const auto close = [relative](double u, double v) {
          return std::abs(u - v) <= relative * std::max(1.0, std::abs(u));
        };
        ASSERT_TRUE(close(x.stats.sum_w, y.stats.sum_w)) << x.stats.sum_w << " " << y.stats.sum_w;
        ASSERT_TRUE(close(x.stats.sum_wp, y.stats.sum_wp));
        ASSERT_TRUE(close(x.stats.sum_wp2, y.stats.sum_wp2));
        ++leaves;
      }
    }
    EXPECT_GT(leaves, 10000u);
  }

  static std::string* root_;
  static std::string* scan_;
  static std::map<ChunkKey, TileData, ChunkKeyLess>* reference_;
};
std::string* SliceCarverTest::root_ = nullptr;
std::string* SliceCarverTest::scan_ = nullptr;
std::map<ChunkKey, TileData, ChunkKeyLess>* SliceCarverTest::reference_ = nullptr;

// One slice in one batch: the very sums of the whole chunks, in the same order.
TEST_F(SliceCarverTest, OneSliceIsTheWholeChunksCarve) {
  SliceCarveOptions o = Options(CarveEvaluation::kExact);
  o.batch_rays = uint64_t{1} << 40;
  const Carved c = CarveBySlices("one", 1e6, o);
  EXPECT_EQ(c.slices, 1u);
  EXPECT_EQ(c.batches, 1u);
  ExpectSameTiles(*reference_, c.tiles, 0);
}

// Many slices, many batches per slice and a memory budget small enough to flush several times:
// the same votes, so the same nodes, counts and points; the sums within rounding.
TEST_F(SliceCarverTest, SlicesBatchesAndFlushesChangeOnlyTheRounding) {
  SliceCarveOptions o = Options(CarveEvaluation::kExact);
  o.batch_rays = 10'000;
  o.memory_budget_bytes = 8u << 20;
  const Carved c = CarveBySlices("many", 4.0, o);
  EXPECT_EQ(c.slices, 5u);
  EXPECT_GT(c.batches, 2 * c.slices);
  EXPECT_GT(c.flushes, c.slices);
  ExpectSameTiles(*reference_, c.tiles, 1e-12, /*same_wedges=*/false);
}

// One batch whose chunks add more sums than the budget: flushed between its chunks, not once
// at its end, so the sums held stay near the budget whatever a batch holds.
TEST_F(SliceCarverTest, TheBudgetIsCheckedAfterEachChunkOfABatch) {
  SliceCarveOptions o = Options(CarveEvaluation::kExact);
  o.batch_rays = uint64_t{1} << 40;
  o.memory_budget_bytes = 256u << 10;
  const Carved c = CarveBySlices("one_batch_small_budget", 1e6, o);
  EXPECT_EQ(c.slices, 1u);
  EXPECT_EQ(c.batches, 1u);
  EXPECT_GE(c.flushes, 4u);
  ExpectSameTiles(*reference_, c.tiles, 1e-12);
}

// The progress moves while a batch is carved, chunk by chunk: with the whole slice in one
// batch, counting at the frames read would jump from 0 to all before the carve began.
TEST_F(SliceCarverTest, ProgressCountsRaysAsTheirChunksAreCarved) {
  SliceCarveOptions o = Options(CarveEvaluation::kFast);
  o.batch_rays = uint64_t{1} << 40;
  absl::StatusOr<std::unique_ptr<ScanReader>> reader = ScanReader::Open(*scan_);
  ASSERT_TRUE(reader.ok()) << reader.status();
  absl::StatusOr<std::vector<ScanSlice>> slices = SlicesOf(**reader, 1e6);
  ASSERT_TRUE(slices.ok()) << slices.status();
  ASSERT_EQ(slices->size(), 1u);
  // Fed frame by frame, as CarveSliceToFile does, with the one batch carved by Finish.
  const ScanSlice& slice = slices->front();
  absl::StatusOr<std::unique_ptr<SliceCarver>> carver = SliceCarver::Create(
      (*reader)->sensors(), slice, o,
      [](const ChunkKey&, uint64_t, std::span<const TileLeaf>) { return absl::OkStatus(); });
  ASSERT_TRUE(carver.ok()) << carver.status();
  std::vector<uint64_t> seen;
  (*carver)->SetProgress([&seen](uint64_t rays) { seen.push_back(rays); });
  absl::StatusOr<std::unique_ptr<ScanReader::FrameStream>> stream =
      (*reader)->StreamFrames(slice.read);
  ASSERT_TRUE(stream.ok()) << stream.status();
  std::span<const PathCovariance> cov;
  if ((*reader)->path_covariance().has_value()) cov = *(*reader)->path_covariance();
  ScanFrame frame;
  while (true) {
    absl::StatusOr<bool> more = (*stream)->Next(frame);
    ASSERT_TRUE(more.ok()) << more.status();
    if (!*more) break;
    absl::StatusOr<FrameContext> ctx =
        FrameContextAt((*reader)->timed_path(), cov, frame.t, o.wedges.noise);
    ASSERT_TRUE(ctx.ok()) << ctx.status();
    ASSERT_TRUE((*carver)->AddFrame(frame, *ctx).ok());
  }
  EXPECT_TRUE(seen.empty()) << "progress before any chunk was carved: " << seen.front();
  absl::StatusOr<SliceCarveStats> st = (*carver)->Finish();
  ASSERT_TRUE(st.ok()) << st.status();
  EXPECT_EQ(st->batches, 1u);
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back(), st->rays);
  EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
  std::set<uint64_t> between;
  for (uint64_t r : seen) {
    if (r > 0 && r < st->rays) between.insert(r);
  }
  EXPECT_GE(between.size(), 10u) << "of " << st->rays << " rays";
}

// The same slices carved in another order (as workers finish them) give the same bytes.
TEST_F(SliceCarverTest, SameSlicesSameBytesWhateverTheOrder) {
  const SliceCarveOptions o = Options(CarveEvaluation::kFast);
  const Carved a = CarveBySlices("fwd", 6.0, o, false);
  const Carved b = CarveBySlices("rev", 6.0, o, true);
  ASSERT_EQ(a.partials.size(), b.partials.size());
  for (size_t i = 0; i < a.partials.size(); ++i) {
    EXPECT_EQ(ReadBytes(a.partials[i]), ReadBytes(b.partials[i])) << i;
  }
  ExpectSameTiles(a.tiles, b.tiles, 0);
  // And the fast evaluation agrees with the exact reference as the chunk carve does.
  testing::TileAgreement agreement;
  for (const auto& [chunk, tile] : *reference_) {
    auto it = a.tiles.find(chunk);
    testing::AddTilePair(&tile, it == a.tiles.end() ? nullptr : &it->second, agreement);
  }
  EXPECT_GE(agreement.LabelShare(), 0.99999);
  EXPECT_LT(agreement.DpQuantile(0.99), 1e-5);
}

// A slice read with only the poses around its frames carves the same bytes as with the whole
// path (a pose, its covariance and the angular velocity read the two poses around a time).
TEST_F(SliceCarverTest, OnlyTheSlicesPosesSameBytes) {
  const SliceCarveOptions o = Options(CarveEvaluation::kFast);
  const Carved whole = CarveBySlices("whole_path", 5.0, o);
  const Carved own = CarveBySlices("own_poses", 5.0, o, false, /*own_poses=*/true);
  ASSERT_GT(whole.partials.size(), 2u);
  ASSERT_EQ(whole.partials.size(), own.partials.size());
  for (size_t i = 0; i < whole.partials.size(); ++i) {
    EXPECT_EQ(ReadBytes(whole.partials[i]), ReadBytes(own.partials[i])) << i;
  }
}

// §5.6.1: with regions, only the chunks listed, only inside their regions: the whole carve's
// leaves there (the combine's sums within rounding). Two shapes: each chunk's lower half, and
// one cell of an eighth of its side, which most wedges through the chunk pass by (they are
// left out of its carve before their leaves are listed).
TEST_F(SliceCarverTest, RegionsCarveOnlyThere) {
  // Two busy chunks.
  std::vector<ChunkKey> busiest;
  for (const auto& [chunk, tile] : *reference_) busiest.push_back(chunk);
  std::sort(busiest.begin(), busiest.end(), [](const ChunkKey& x, const ChunkKey& y) {
    return reference_->at(x).leaves.size() > reference_->at(y).leaves.size() ||
           (reference_->at(x).leaves.size() == reference_->at(y).leaves.size() &&
            ChunkKeyLess()(x, y));
  });
  busiest.resize(2);
  const ChunkRegion lower_half(1, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}});
  const ChunkRegion one_cell(3, {{3, 4, 1}});
  for (const ChunkRegion* shape : {&lower_half, &one_cell}) {
    SCOPED_TRACE(shape == &lower_half ? "lower half" : "one cell");
    RecarveRegionMap regions;
    for (const ChunkKey& c : busiest) regions.emplace(c, RecarveChunk::Of(c, *shape));
    SliceCarveOptions o = Options(CarveEvaluation::kExact);
    o.regions = &regions;
    const Carved c = CarveBySlices(shape == &lower_half ? "regions" : "regions_cell", 6.0, o);
    for (const auto& [chunk, tile] : c.tiles) {  // no tile of a chunk not listed
      EXPECT_NE(std::find(busiest.begin(), busiest.end(), chunk), busiest.end())
          << chunk.transpose();
    }
    int compared = 0;
    for (const ChunkKey& chunk : busiest) {
      // The reference tile's leaves in the region, against the region's tile: the finest
      // leaves agree (simplification may merge differently at the region's border).
      TileData inside = reference_->at(chunk);
      std::erase_if(inside.leaves, [&](const TileLeaf& l) {
        return l.node.depth < shape->depth() || !shape->Intersects(l.node);
      });
      if (inside.leaves.empty()) continue;  // merged into coarser leaves by the reference
      ++compared;
      ASSERT_TRUE(c.tiles.count(chunk)) << chunk.transpose();
      testing::TileAgreement agreement;
      testing::AddTilePair(&inside, &c.tiles.at(chunk), agreement);
      EXPECT_EQ(agreement.LabelShare(), 1.0) << chunk.transpose();
      EXPECT_LT(agreement.max_dp, 1e-9) << chunk.transpose();
      for (const TileLeaf& l : c.tiles.at(chunk).leaves) {
        EXPECT_TRUE(shape->Intersects(l.node)) << l.node.local.transpose();
      }
    }
    EXPECT_GT(compared, 0);
  }
}

// A second pass's decoded regions count in the budget with the sums and go at a flush: a
// long slice reaching many object chunks does not hold every one's tables to its end. With
// every chunk whole in the pass, the carve is the whole one's, however often it flushed.
TEST_F(SliceCarverTest, DecodedRegionsCountInTheBudget) {
  RecarveRegionMap regions;
  std::vector<Eigen::Vector3i> corners;  // spread over the chunk: the largest tables at depth 5
  for (int z = 0; z < 32; ++z)
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x) corners.emplace_back(x, y, z);
  const ChunkRegion whole_chunk(5, corners);
  for (const auto& [chunk, tile] : *reference_) {
    regions.emplace(chunk, RecarveChunk::Of(chunk, whole_chunk));
  }
  ASSERT_GT(regions.size(), 4u);
  SliceCarveOptions o = Options(CarveEvaluation::kExact);
  o.batch_rays = uint64_t{1} << 40;
  o.regions = &regions;
  const Carved roomy = CarveBySlices("regions_roomy", 1e6, o);
  EXPECT_EQ(roomy.flushes, 1u);  // only Finish's
  // Room for about two regions' tables and no sums: a flush after nearly every chunk.
  o.memory_budget_bytes = 2 * whole_chunk.memory_bytes() + (64u << 10);
  const Carved tight = CarveBySlices("regions_tight", 1e6, o);
  EXPECT_EQ(tight.slices, 1u);
  EXPECT_GE(tight.flushes, regions.size() / 2);
  ExpectSameTiles(*reference_, roomy.tiles, 1e-12);
  ExpectSameTiles(*reference_, tight.tiles, 1e-12);
}

// Grid frames carved through a SliceCarver with `batch_rays`: a wall 3 m ahead seen through
// ±20° × ±30° (20 × 30 pixels), the scanner turning a little each frame. Returns every leaf's
// sums over all sections (keyed by chunk and leaf), and the own rays carved as progress had
// them after each frame was added, and the values progress took during each AddFrame.
struct GridCarve {
  std::map<std::tuple<int, int, int, uint64_t>, LeafStats> leaves;
  std::vector<uint64_t> carved_after_frame;
  std::vector<std::vector<uint64_t>> progress_in_frame;
  SliceCarveStats stats;
};

GridCarve CarveGridFrames(uint64_t batch_rays, uint64_t frames) {
  SensorInfo grid;
  grid.name = "grid";
  grid.kind = SensorKind::kGrid;
  grid.rows = 20;
  grid.cols = 30;
  grid.range_sigma = {0.005, 0};
  grid.max_range_m = 10;
  const uint64_t rays = uint64_t{grid.rows} * grid.cols;
  ScanSlice slice;
  slice.own = {{0, frames}};
  slice.read = {{0, frames}};
  slice.own_rays = frames * rays;
  SliceCarveOptions o;
  o.grid.chunk_depth = 5;
  o.batch_rays = batch_rays;
  GridCarve out;
  absl::StatusOr<std::unique_ptr<SliceCarver>> carver = SliceCarver::Create(
      {grid}, slice, o, [&out](const ChunkKey& c, uint64_t, std::span<const TileLeaf> leaves) {
        for (const TileLeaf& l : leaves) {
          LeafStats& sum = out.leaves[{c.x(), c.y(), c.z(), MortonCode(l.node.local)}];
          sum.sum_w += l.stats.sum_w;
          sum.sum_wp += l.stats.sum_wp;
          sum.sum_wp2 += l.stats.sum_wp2;
          sum.count += l.stats.count;
        }
        return absl::OkStatus();
      });
  EXPECT_TRUE(carver.ok()) << carver.status();
  if (!carver.ok()) return out;
  uint64_t carved = 0;
  (*carver)->SetProgress([&](uint64_t r) {
    carved = r;
    if (!out.progress_in_frame.empty()) out.progress_in_frame.back().push_back(r);
  });
  const std::vector<TimedPose> path = {TimedPose{0, Pose{}}, TimedPose{10, Pose{}}};
  for (uint64_t f = 0; f < frames; ++f) {
    ScanFrame frame;
    frame.sensor = 0;
    frame.row = f;
    frame.t = double(f);
    for (uint32_t r = 0; r < grid.rows; ++r) {
      for (uint32_t c = 0; c < grid.cols; ++c) {
        const double el = (-20.0 + 2.0 * r) * M_PI / 180;
        const double az = (-30.0 + 2.0 * c + f) * M_PI / 180;
        const Eigen::Vector3d d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                                std::sin(el));
        frame.points_sensor.push_back((d * (3.0 / d.x())).cast<float>());
      }
    }
    absl::StatusOr<FrameContext> ctx = FrameContextAt(path, {}, frame.t, o.wedges.noise);
    EXPECT_TRUE(ctx.ok()) << ctx.status();
    out.progress_in_frame.emplace_back();
    EXPECT_TRUE((*carver)->AddFrame(frame, *ctx).ok());
    out.carved_after_frame.push_back(carved);
  }
  absl::StatusOr<SliceCarveStats> st = (*carver)->Finish();
  EXPECT_TRUE(st.ok()) << st.status();
  if (st.ok()) out.stats = *st;
  return out;
}

// A grid's wedges lie within one frame, so a batch of large grid frames is carved as soon as
// its last frame is in, before the next frame is read: a worker holds one such batch, not two.
TEST(SliceCarverGrid, ABatchOfGridFramesIsCarvedBeforeTheNextFrame) {
  const GridCarve g = CarveGridFrames(/*batch_rays=*/600, 4);
  for (uint64_t f = 0; f < 4; ++f) EXPECT_EQ(g.carved_after_frame[f], (f + 1) * 600) << f;
  EXPECT_EQ(g.stats.batches, 4u);
  EXPECT_EQ(g.stats.rays, 4u * 600);
}

// A grid frame larger than batch_rays is carved in bands of whole pixel rows while its wedges
// come (200 rays: bands of 6 rows, 180 rays), so memory holds a band's batch, not the frame's;
// the sums are the one-batch carve's up to the order of the additions.
TEST(SliceCarverGrid, AFrameLargerThanABatchIsCarvedInBandsOfRows) {
  const GridCarve banded = CarveGridFrames(/*batch_rays=*/200, 3);
  const GridCarve whole = CarveGridFrames(/*batch_rays=*/uint64_t{1} << 40, 3);
  EXPECT_EQ(banded.stats.batches, 3u * 4);  // 180 + 180 + 180 + 60 rays a frame
  for (uint64_t f = 0; f < 3; ++f) {
    // All but the last band, which a next frame smaller than a batch could still join; after
    // the slice's last frame, all.
    EXPECT_EQ(banded.carved_after_frame[f], f < 2 ? f * 600 + 540 : 1800) << f;
    // Bands carved while the frame's wedges were still coming.
    const std::vector<uint64_t>& p = banded.progress_in_frame[f];
    EXPECT_TRUE(std::any_of(p.begin(), p.end(),
                            [f](uint64_t r) { return r > f * 600 && r < (f + 1) * 600 - 60; }))
        << "frame " << f;
  }
  EXPECT_EQ(banded.stats.rays, 3u * 600);
  EXPECT_EQ(banded.stats.leaf_updates, whole.stats.leaf_updates) << "each ray votes once";
  ASSERT_EQ(banded.leaves.size(), whole.leaves.size());
  for (const auto& [key, w] : whole.leaves) {
    const auto it = banded.leaves.find(key);
    ASSERT_NE(it, banded.leaves.end());
    const LeafStats& b = it->second;
    EXPECT_EQ(b.count, w.count);
    EXPECT_NEAR(b.sum_w, w.sum_w, 1e-4 * std::abs(w.sum_w) + 1e-9);
    EXPECT_NEAR(b.sum_wp, w.sum_wp, 1e-4 * std::abs(w.sum_wp) + 1e-9);
  }
}

}  // namespace
}  // namespace carvemap
