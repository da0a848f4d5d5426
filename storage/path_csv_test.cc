#include "storage/path_csv.h"

#include <fstream>
#include <string>

#include <gtest/gtest.h>


namespace carvemap {
namespace {

std::string Write(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

TEST(PathCsv, ReadsCommaAndSpaceSeparatedWithHeaderAndComments) {
  const std::string p = Write("a.csv", "x,y,z\n# walk\n1.5,2\n\n3 4.25 9\n-1e-1,\t5\n");
  absl::StatusOr<std::vector<Eigen::Vector2d>> xy = ReadPathCsv(p);
  ASSERT_TRUE(xy.ok()) << xy.status();
  ASSERT_EQ(xy->size(), 3u);
  EXPECT_EQ((*xy)[0], Eigen::Vector2d(1.5, 2));
  EXPECT_EQ((*xy)[1], Eigen::Vector2d(3, 4.25));
  EXPECT_EQ((*xy)[2], Eigen::Vector2d(-0.1, 5));
}

TEST(PathCsv, BadLineNamesFileAndLine) {
  const std::string p = Write("b.csv", "1,2\n3,abc\n");
  absl::StatusOr<std::vector<Eigen::Vector2d>> xy = ReadPathCsv(p);
  ASSERT_EQ(xy.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(xy.status().message().find("b.csv:2"), std::string::npos) << xy.status();
}

TEST(PathCsv, NonFiniteEmptyAndMissingAreErrors) {
  EXPECT_EQ(ReadPathCsv(Write("c.csv", "1,2\nnan,1\n")).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadPathCsv(Write("d.csv", "# nothing\n\n")).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadPathCsv(::testing::TempDir() + "/missing.csv").status().code(),
            absl::StatusCode::kNotFound);
}

}  // namespace
}  // namespace carvemap
