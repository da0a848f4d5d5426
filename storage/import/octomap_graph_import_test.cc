#include "storage/import/octomap_graph_import.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <octomap/ScanGraph.h>
#include "storage/import/import_writer.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

using ::testing::HasSubstr;

const std::string kFixture = std::string(CARVEMAP_TEST_DATA_DIR) + "/octomap/spherical_scan.graph";

std::vector<char> ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::string WriteTemp(const std::string& name, const std::vector<char>& bytes) {
  const std::string path = (std::filesystem::path(::testing::TempDir()) / name).string();
  std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
  return path;
}

// Builds graphs in OctoMap's layout (little-endian host assumed, as in CI).
struct GraphBytes {
  std::vector<char> bytes;
  template <typename T>
  void Put(T v) {
    const char* p = reinterpret_cast<const char*>(&v);
    bytes.insert(bytes.end(), p, p + sizeof(T));
  }
  void Vec(std::initializer_list<double> v) {
    Put<int32_t>(int32_t(v.size()));
    for (double x : v) Put(x);
  }
  void Pose(double tx, double ty, double tz, double qw, double qx, double qy, double qz) {
    Vec({tx, ty, tz});
    Vec({qw, qx, qy, qz});
  }
};

// Two nodes (2 and 1 points) and one edge between ids 7 and 9.
std::vector<char> TwoNodeGraph(uint32_t edge_id2 = 9) {
  GraphBytes g;
  g.Put<uint32_t>(2);
  g.Put<uint32_t>(2);
  g.Vec({1, 2, 3});
  g.Vec({4, 5, 6});
  g.Pose(10, 20, 30, 1, 0, 0, 0);
  g.Put<uint32_t>(7);
  g.Put<uint32_t>(1);
  g.Vec({-1, -2, -3});
  g.Pose(0, 0, 1, 0, 0, 0, 1);
  g.Put<uint32_t>(9);
  g.Put<uint32_t>(1);
  g.Put<uint32_t>(7);
  g.Put<uint32_t>(edge_id2);
  g.Pose(1, 0, 0, 1, 0, 0, 0);
  g.Put<double>(1.0);
  return g.bytes;
}

TEST(OctomapGraphImportTest, FixtureMatchesOctomapsOwnReader) {
  auto scan = ImportOctomapGraph(kFixture);
  ASSERT_TRUE(scan.ok()) << scan.status();

  octomap::ScanGraph graph;
  ASSERT_TRUE(graph.readBinary(kFixture));
  ASSERT_EQ(scan->frames.size(), graph.size());
  ASSERT_EQ(scan->path.size(), graph.size());
  EXPECT_EQ(scan->frame_count, graph.size());
  EXPECT_EQ(scan->sensor.name, "graph");
  EXPECT_EQ(scan->sensor.kind, SensorKind::kPoints);
  EXPECT_TRUE(scan->sensor.R_s2c.isIdentity());

  uint64_t points = 0;
  size_t k = 0;
  for (const octomap::ScanNode* node : graph) {
    const ImportedFrame& frame = scan->frames[k];
    EXPECT_EQ(frame.t, double(k));  // synthetic times
    ASSERT_EQ(frame.points_sensor.size(), node->scan->size());
    points += frame.points_sensor.size();
    // OctoMap stores the f64 coordinates as f32, as we do: every point is equal.
    for (size_t i = 0; i < node->scan->size(); ++i) {
      const octomap::point3d& p = (*node->scan)[i];
      ASSERT_EQ(frame.points_sensor[i], Eigen::Vector3f(p.x(), p.y(), p.z())) << "point " << i;
    }
    const PathRecord& pose = scan->path[k];
    EXPECT_NEAR(pose.x, node->pose.trans().x(), 1e-6);
    EXPECT_NEAR(pose.y, node->pose.trans().y(), 1e-6);
    EXPECT_NEAR(pose.z, node->pose.trans().z(), 1e-6);
    EXPECT_NEAR(pose.qw, node->pose.rot().u(), 1e-6);
    EXPECT_NEAR(pose.qx, node->pose.rot().x(), 1e-6);
    EXPECT_NEAR(pose.qy, node->pose.rot().y(), 1e-6);
    EXPECT_NEAR(pose.qz, node->pose.rot().z(), 1e-6);
    ++k;
  }
  EXPECT_EQ(scan->point_count, points);
  EXPECT_EQ(points, 10201u);
}

TEST(OctomapGraphImportTest, SinkReceivesFramesInsteadOfTheResult) {
  std::vector<size_t> sizes;
  auto scan = ImportOctomapGraph(kFixture, {}, [&](double t, std::span<const Eigen::Vector3f> p) {
    sizes.push_back(p.size());
    return absl::OkStatus();
  });
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_TRUE(scan->frames.empty());
  EXPECT_EQ(sizes, std::vector<size_t>{10201});
}

TEST(OctomapGraphImportTest, SmallGraphWithEdge) {
  const std::string path = WriteTemp("two.graph", TwoNodeGraph());
  auto scan = ImportOctomapGraph(path);
  ASSERT_TRUE(scan.ok()) << scan.status();
  ASSERT_EQ(scan->frames.size(), 2u);
  EXPECT_EQ(scan->frames[0].points_sensor[1], Eigen::Vector3f(4, 5, 6));
  EXPECT_EQ(scan->frames[1].t, 1.0);
  EXPECT_EQ(scan->path[1].z, 1.0);
  EXPECT_EQ(scan->path[1].qz, 1.0);
}

TEST(OctomapGraphImportTest, EdgeToUnknownNodeIsAnError) {
  const std::string path = WriteTemp("bad_edge.graph", TwoNodeGraph(/*edge_id2=*/8));
  auto scan = ImportOctomapGraph(path);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("edge 0"));
  EXPECT_THAT(scan.status().message(), HasSubstr("unknown node ids 7 and 8"));
}

TEST(OctomapGraphImportTest, TruncationAnywhereIsAClearError) {
  const std::vector<char> whole = ReadAll(kFixture);
  ASSERT_EQ(whole.size(), 285708u);
  // Inside: the node count, a point count, the first point, a later point, the pose, the id,
  // the edge count.
  for (size_t size : {size_t{0}, size_t{2}, size_t{6}, size_t{10}, size_t{40}, whole.size() / 2,
                      whole.size() - 80, whole.size() - 30, whole.size() - 6,
                      whole.size() - 2}) {
    const std::string path =
        WriteTemp("cut_" + std::to_string(size) + ".graph",
                  std::vector<char>(whole.begin(), whole.begin() + std::ptrdiff_t(size)));
    auto scan = ImportOctomapGraph(path);
    ASSERT_FALSE(scan.ok()) << "cut at " << size;
    EXPECT_THAT(scan.status().message(), HasSubstr(path)) << "cut at " << size;
    EXPECT_THAT(scan.status().message(), HasSubstr("at byte ")) << "cut at " << size;
    if (size >= 4 + 72 && size < whole.size() - 4) {  // past the node-count check
      EXPECT_THAT(scan.status().message(), HasSubstr("node 0")) << scan.status();
    }
  }
}

TEST(OctomapGraphImportTest, AbsurdCountsAreRejectedBeforeAllocating) {
  std::vector<char> bytes = ReadAll(kFixture);
  const uint32_t huge = 0xFFFFFFFFu;
  std::vector<char> nodes = bytes;
  std::memcpy(nodes.data(), &huge, 4);
  auto scan = ImportOctomapGraph(WriteTemp("many_nodes.graph", nodes));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("node count 4294967295 cannot fit"));

  std::vector<char> points = bytes;
  std::memcpy(points.data() + 4, &huge, 4);
  scan = ImportOctomapGraph(WriteTemp("many_points.graph", points));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("node 0 at byte 4: point count 4294967295"));
}

// Found by tests/fuzz (graph_import): a finite f64 coordinate beyond float range became ±inf
// in the f32 points, so the import "succeeded" with a scan that fails validation.
TEST(OctomapGraphImportTest, CoordinateBeyondFloatRangeIsAnError) {
  std::vector<char> bytes = TwoNodeGraph();
  const double far = 1e300;
  std::memcpy(bytes.data() + 8 + 28 + 4 + 8, &far, 8);  // node 0, point 1, y
  auto scan = ImportOctomapGraph(WriteTemp("far.graph", bytes));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(),
              HasSubstr("node 0 point 1 at byte 36: coordinate beyond float range"));
}

// Found by tests/fuzz (graph_import): a graph of zero nodes (and zero edges) imported "fine"
// into a scan with no poses, which fails validation.
TEST(OctomapGraphImportTest, GraphWithoutNodesIsAnError) {
  GraphBytes g;
  g.Put<uint32_t>(0);  // nodes
  g.Put<uint32_t>(0);  // edges
  auto scan = ImportOctomapGraph(WriteTemp("empty.graph", g.bytes));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("header at byte 0: the graph has no nodes"));
}

TEST(OctomapGraphImportTest, WrongVectorMarkerIsAnError) {
  std::vector<char> bytes = ReadAll(kFixture);
  const int32_t four = 4;
  std::memcpy(bytes.data() + 8 + 28 * 5, &four, 4);  // the 6th point's marker
  auto scan = ImportOctomapGraph(WriteTemp("marker.graph", bytes));
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(),
              HasSubstr("node 0 at byte 148: a point: length marker is 4, expected 3"));
}

TEST(OctomapGraphImportTest, MissingFileIsNotFound) {
  auto scan = ImportOctomapGraph("/nonexistent/x.graph");
  EXPECT_EQ(scan.status().code(), absl::StatusCode::kNotFound);
}

TEST(OctomapGraphImportTest, WritesAScanThatValidates) {
  const std::string out = (std::filesystem::path(::testing::TempDir()) / "graph.h5").string();
  auto summary = WriteImport(out, OctomapGraphSensor(), [](const FrameSink& sink) {
    return ImportOctomapGraph(kFixture, {}, sink);
  });
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frames, 1u);
  EXPECT_EQ(summary->points, 10201u);
  auto reader = ScanReader::Open(out);
  ASSERT_TRUE(reader.ok()) << reader.status();
  ASSERT_TRUE((*reader)->Validate().ok()) << (*reader)->Validate();
  ASSERT_EQ((*reader)->sensors().size(), 1u);
  EXPECT_EQ((*reader)->sensors()[0].name, "graph");
  EXPECT_EQ((*reader)->point_count(0), 10201u);
  EXPECT_EQ((*reader)->path().size(), 1u);
  EXPECT_EQ((*reader)->path()[0].z, -0.5);
  auto frame = (*reader)->ReadFrame(0, 0);
  ASSERT_TRUE(frame.ok()) << frame.status();
  auto parsed = ImportOctomapGraph(kFixture);
  ASSERT_TRUE(parsed.ok());
  EXPECT_EQ(frame->points_sensor, parsed->frames[0].points_sensor);
}

TEST(OctomapGraphImportTest, FailedImportLeavesNoFile) {
  const std::string out = (std::filesystem::path(::testing::TempDir()) / "bad.h5").string();
  std::vector<char> bytes = ReadAll(kFixture);
  const std::string bad = WriteTemp("half.graph", {bytes.begin(), bytes.begin() + 1000});
  auto summary = WriteImport(out, OctomapGraphSensor(), [&](const FrameSink& sink) {
    return ImportOctomapGraph(bad, {}, sink);
  });
  EXPECT_FALSE(summary.ok());
  EXPECT_FALSE(std::filesystem::exists(out));
}

}  // namespace
}  // namespace carvemap
