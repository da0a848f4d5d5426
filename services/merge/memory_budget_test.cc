#include "services/merge/memory_budget.h"

#include <vector>

#include <gtest/gtest.h>

#include "services/mesh/planar_mesh.h"

namespace carvemap {
namespace {

// Horizontal faces at the given heights.
std::vector<BoundaryFace> FacesAt(const std::vector<std::pair<double, int>>& z_count) {
  std::vector<BoundaryFace> faces;
  for (const auto& [z, n] : z_count) {
    for (int i = 0; i < n; ++i) {
      BoundaryFace f;
      f.axis = 2;
      f.center = Eigen::Vector3d(0.1 * i, 0, z);
      f.isosurface_m = z;
      f.size_m = 0.0625;
      faces.push_back(f);
    }
  }
  return faces;
}

std::vector<Level> TwoLevels() {
  std::vector<Level> levels(2);
  levels[0].index = 0;
  levels[0].split_z_low = -0.5;
  levels[0].split_z_high = 3.0;
  levels[1].index = 1;
  levels[1].split_z_low = 3.0;
  levels[1].split_z_high = 6.5;
  return levels;
}

TEST(CheckPlanarMemory, PassesUnderTheBudgetAndWithoutOne) {
  const std::vector<BoundaryFace> faces = FacesAt({{0.0, 1000}, {3.2, 500}});
  const uint64_t need = 1500 * kPlanarBytesPerFace;
  EXPECT_TRUE(CheckPlanarMemory("x", faces, TwoLevels(), 1 << 20, 0).ok());  // no budget
  EXPECT_TRUE(CheckPlanarMemory("x", faces, TwoLevels(), 1 << 20, (1 << 20) + need).ok());
  const absl::Status over =
      CheckPlanarMemory("x", faces, TwoLevels(), 1 << 20, (1 << 20) + need - 1);
  EXPECT_EQ(over.code(), absl::StatusCode::kResourceExhausted) << over;
}

TEST(CheckPlanarMemory, NamesTheStageTheLevelsTheEstimateAndTheBudget) {
  const std::vector<BoundaryFace> faces = FacesAt({{0.0, 3000}, {3.2, 2000}, {9.0, 7}});
  const absl::Status s = CheckPlanarMemory("the building's planar mesh", faces, TwoLevels(),
                                           uint64_t{3} << 29, uint64_t{1} << 30);
  ASSERT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  const std::string m(s.message());
  EXPECT_NE(m.find("the building's planar mesh: 5007 boundary faces (level 0: 3000, level 1: "
                   "2000, outside the levels: 7)"),
            std::string::npos)
      << m;
  EXPECT_NE(m.find("on top of the 1.50 GiB the merge holds"), std::string::npos) << m;
  EXPECT_NE(m.find("memory budget of 1.00 GiB"), std::string::npos) << m;
  EXPECT_NE(m.find("--memory-mb"), std::string::npos) << m;
  // Before the levels are known: the faces only.
  const absl::Status early = CheckPlanarMemory("planar regions", faces, {}, 0, 1000);
  EXPECT_NE(std::string(early.message()).find("planar regions: 5007 boundary faces need about"),
            std::string::npos)
      << early;
}

}  // namespace
}  // namespace carvemap
