// §5.5 trimming of the scan's point cloud (trimmed_points.h) on a plan with one room: points
// in the room and within the trim distance of it stay, points farther out on the level go,
// points above every level stay; the file is what ReadPly reads back, or nothing on errors.
#include "services/merge/trimmed_points.h"

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "services/segment/segment_test_util.h"
#include "storage/ply_io.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

class TrimmedPointsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // One room [0, 4]² with floor 0 and ceiling 2.5, its level's range z ∈ [−0.5, 3).
    plan_ = testing::RectanglePlan({{{0, 0}, {4, 4}, 0, 2.5}});
    const PlanLevelInput in{&plan_, 0, -0.5, 3.0};
    volume_ = *RasterizePlanVolume({&in, 1}, 0.0625, 2.0);
    dir_ = fs::path(::testing::TempDir()) / "trimmed_points_test";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }

  // The cloud in two batches: {kept, trimmed, kept} then {kept, trimmed, kept}.
  static std::vector<std::vector<Eigen::Vector3d>> Batches() {
    return {{{2, 2, 1},          // in the room
             {6.5, 2, 1},        // 2.5 m east of its wall, on the level: seen through a window
             {4.5, 2, 1}},       // 0.5 m east: within the 1 m (an exterior wall's far side)
            {{2, -0.9, 0.2},     // 0.9 m south
             {2, -1.2, 2},       // 1.2 m south
             {9, 9, 4}}};        // far out but above every level: kept
  }

  static CloudStreamFn Stream(std::vector<std::vector<Eigen::Vector3d>> batches) {
    return [batches](const CloudBatchSink& sink) {
      for (const auto& b : batches) {
        std::vector<CloudPoint> pts;
        for (const Eigen::Vector3d& p : b) pts.push_back({p, Eigen::Vector3d::Zero(), 0});
        if (absl::Status s = sink(pts); !s.ok()) return s;
      }
      return absl::OkStatus();
    };
  }

  FloorPlan plan_;
  PlanVolume volume_;
  fs::path dir_;
};

TEST_F(TrimmedPointsTest, DropsPointsFartherThanTheTrimDistanceFromThePlan) {
  const std::string path = (dir_ / "points.ply").string();
  absl::StatusOr<TrimmedPointsCounts> counts =
      WriteTrimmedPoints(Stream(Batches()), volume_, 1.0, path);
  ASSERT_TRUE(counts.ok()) << counts.status();
  EXPECT_EQ(counts->kept, 4u);
  EXPECT_EQ(counts->trimmed, 2u);
  absl::StatusOr<PlyMesh> ply = ReadPly(path);
  ASSERT_TRUE(ply.ok()) << ply.status();
  EXPECT_TRUE(ply->mesh.triangles.empty());
  const std::vector<Eigen::Vector3f> expected = {{2, 2, 1}, {4.5, 2, 1}, {2, -0.9, 0.2},
                                                 {9, 9, 4}};
  ASSERT_EQ(ply->mesh.vertices.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) EXPECT_EQ(ply->mesh.vertices[i], expected[i]);
  EXPECT_FALSE(fs::exists(path + ".partial"));
  // The count goes into the header after the points: the file is exactly header + 4 vertices.
  std::ifstream in(path, std::ios::binary);
  std::string header, line;
  while (std::getline(in, line)) {
    header += line + "\n";
    if (line == "end_header") break;
  }
  EXPECT_NE(header.find("\nelement vertex 4\n"), std::string::npos) << header;
  EXPECT_EQ(fs::file_size(path), header.size() + 4 * 3 * sizeof(float));

  // A larger distance keeps the point 1.2 m out; the one 2.5 m out still goes.
  counts = WriteTrimmedPoints(Stream(Batches()), volume_, 2.0, path);
  ASSERT_TRUE(counts.ok()) << counts.status();
  EXPECT_EQ(counts->kept, 5u);
  EXPECT_EQ(counts->trimmed, 1u);
}

TEST_F(TrimmedPointsTest, ErrorsLeaveNoFile) {
  const std::string path = (dir_ / "points.ply").string();
  // A stream that fails after its first batch (a read error half way through the file).
  const CloudStreamFn failing = [](const CloudBatchSink& sink) {
    auto batches = Batches();
    batches.resize(1);
    if (absl::Status s = Stream(batches)(sink); !s.ok()) return s;
    return absl::DataLossError("scan.h5: /scans/s0 row 7: truncated");
  };
  absl::StatusOr<TrimmedPointsCounts> counts = WriteTrimmedPoints(failing, volume_, 1.0, path);
  ASSERT_FALSE(counts.ok());
  EXPECT_EQ(counts.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(counts.status().message().find("points.ply"), std::string::npos);
  EXPECT_NE(counts.status().message().find("scan.h5: /scans/s0 row 7"), std::string::npos);
  EXPECT_FALSE(fs::exists(path));
  EXPECT_FALSE(fs::exists(path + ".partial"));

  // An output directory that does not exist.
  counts = WriteTrimmedPoints(Stream(Batches()), volume_, 1.0, (dir_ / "no" / "p.ply").string());
  ASSERT_FALSE(counts.ok());
  EXPECT_NE(counts.status().message().find("p.ply"), std::string::npos);
}

}  // namespace
}  // namespace carvemap
