#include "storage/import/tum_import.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <png.h>

#include "storage/png_io.h"
#include "storage/import/import_writer.h"
#include "storage/scan_reader.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const std::string kDir = std::string(CARVEMAP_TEST_DATA_DIR) + "/tum_fr2_pioneer_slam2";

// Frames kept in memory are fine for 10 images of 640×480.
const absl::StatusOr<ImportedScan>& Fixture() {
  static const auto* scan = new absl::StatusOr<ImportedScan>(ImportTum(kDir));
  return *scan;
}

TEST(TumImportTest, FixtureFramesAndPath) {
  const auto& scan = Fixture();
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(scan->sensor.name, "depth");
  EXPECT_EQ(scan->sensor.kind, SensorKind::kGrid);
  EXPECT_EQ(scan->sensor.rows, 480u);
  EXPECT_EQ(scan->sensor.cols, 640u);
  ASSERT_EQ(scan->frames.size(), 10u);
  EXPECT_EQ(scan->point_count, 10u * 640 * 480);
  // 1611 association lines; the last one repeats the one before verbatim and is dropped.
  EXPECT_EQ(scan->path.size(), 1610u);
  for (size_t i = 1; i < scan->path.size(); ++i) {
    ASSERT_LT(scan->path[i - 1].t, scan->path[i].t) << "pose " << i;
  }
  for (size_t i = 0; i < scan->frames.size(); ++i) {
    const ImportedFrame& f = scan->frames[i];
    EXPECT_EQ(f.points_sensor.size(), 640u * 480u);
    EXPECT_GT(f.t, scan->path.front().t);
    EXPECT_LT(f.t, scan->path.back().t);
    if (i > 0) {
      EXPECT_GT(f.t, scan->frames[i - 1].t);
    }
  }
  EXPECT_DOUBLE_EQ(scan->frames[0].t, 1311877813.991479);
  // Association: "... 0.1909 0.7167 -0.6507 -0.1627" is qx qy qz qw.
  const PathRecord& first = scan->path.front();
  EXPECT_DOUBLE_EQ(first.t, 1311877812.989574);
  EXPECT_DOUBLE_EQ(first.x, -2.2583);
  EXPECT_NEAR(first.qw, -0.1614, 1e-3);
  EXPECT_NEAR(first.qx, 0.1905, 1e-3);
  EXPECT_NEAR(first.qz, -0.6513, 1e-3);
  EXPECT_NEAR(Eigen::Vector4d(first.qw, first.qx, first.qy, first.qz).norm(), 1.0, 1e-12);
}

TEST(TumImportTest, PixelBackProjectsIntoTheCameraFrame) {
  const auto& scan = Fixture();
  ASSERT_TRUE(scan.ok()) << scan.status();
  auto image = ReadPngGray16(kDir + "/depth/1311877813.991479.png");
  ASSERT_TRUE(image.ok()) << image.status();
  // A pixel away from the centre with a return, and check one without.
  int hits = 0, holes = 0;
  for (int v : {50, 240, 400}) {
    for (int u : {40, 320, 600}) {
      const uint16_t raw = image->at(v, u);
      const Eigen::Vector3f& p = scan->frames[0].points_sensor[size_t(v) * 640 + u];
      const double z = raw / 5000.0;
      const Eigen::Vector3d expected((u - 325.1) * z / 520.9, (v - 249.7) * z / 521.0, z);
      if (raw == 0 || expected.norm() > 8.0) {
        EXPECT_TRUE(p.array().isNaN().all()) << u << "," << v;
        ++holes;
      } else {
        EXPECT_NEAR(p.x(), expected.x(), 1e-5) << u << "," << v;
        EXPECT_NEAR(p.y(), expected.y(), 1e-5) << u << "," << v;
        EXPECT_NEAR(p.z(), expected.z(), 1e-5) << u << "," << v;
        ++hits;
      }
    }
  }
  EXPECT_GT(hits, 4);
  // Zero depth ➜ NaN row everywhere in the frame.
  for (size_t i = 0; i < image->pixels.size(); ++i) {
    if (image->pixels[i] == 0) {
      ASSERT_TRUE(scan->frames[0].points_sensor[i].array().isNaN().all()) << i;
    }
  }
}

TEST(TumImportTest, StrideKeepsEveryNthPixel) {
  TumOptions options;
  options.stride = 3;
  auto scan = ImportTum(kDir, options);
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(scan->sensor.rows, 160u);
  EXPECT_EQ(scan->sensor.cols, 214u);  // columns 0, 3, ..., 639
  const auto& full = Fixture();
  ASSERT_TRUE(full.ok());
  for (uint32_t r : {0u, 80u, 159u}) {
    for (uint32_t c : {0u, 100u, 213u}) {
      const Eigen::Vector3f& a = scan->frames[3].points_sensor[size_t(r) * 214 + c];
      const Eigen::Vector3f& b = full->frames[3].points_sensor[size_t(r * 3) * 640 + c * 3];
      EXPECT_TRUE(a == b || (a.array().isNaN().all() && b.array().isNaN().all()));
    }
  }
}

// A copy of the fixture's association with one depth image of our own.
std::string MakeDir(const std::string& name, const std::string& association) {
  const fs::path dir = fs::path(::testing::TempDir()) / name;
  fs::remove_all(dir);
  fs::create_directories(dir / "depth");
  std::ofstream(dir / "my_association.txt") << association;
  return dir.string();
}

TEST(TumImportTest, EightBitDepthImageIsNamed) {
  const std::string dir = MakeDir(
      "tum8", "# c\nrgb/10.0.png depth/10.5.png 0 0 0 0 0 0 1\n"
              "rgb/11.0.png depth/11.5.png 1 0 0 0 0 0 1\n");
  Image<uint8_t> gray;
  gray.width = 640;
  gray.height = 480;
  gray.pixels.assign(640 * 480, 7);
  ASSERT_TRUE(WritePngGray8(dir + "/depth/10.5.png", gray).ok());
  auto scan = ImportTum(dir);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("depth/10.5.png"));
  EXPECT_THAT(scan.status().message(), HasSubstr("16-bit"));
}

TEST(TumImportTest, WrongSizeDepthImageIsNamed) {
  const std::string dir = MakeDir("tumsize", "rgb/10.0.png depth/10.5.png 0 0 0 0 0 0 1\n"
                                             "rgb/11.0.png depth/11.5.png 1 0 0 0 0 0 1\n");
  // libpng's simplified API writes 16-bit gray ("linear") images.
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = 320;
  image.height = 240;
  image.format = PNG_FORMAT_LINEAR_Y;
  std::vector<uint16_t> pixels(320 * 240, 5000);
  ASSERT_TRUE(png_image_write_to_file(&image, (dir + "/depth/10.5.png").c_str(), 0,
                                      pixels.data(), 0, nullptr));
  auto scan = ImportTum(dir);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("depth/10.5.png: image is 320×240"));
}

TEST(TumImportTest, MalformedAssociationLineIsNamed) {
  const std::string dir =
      MakeDir("tumbad", "# c\nrgb/10.0.png depth/10.5.png 0 0 0 0 0 1\n");
  auto scan = ImportTum(dir);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("my_association.txt: line 2"));
}

// Found by tests/fuzz (tum_import): a depth image name longer than the system allows made
// std::filesystem::exists throw (ENAMETOOLONG), and the import died of the exception.
TEST(TumImportTest, DepthNameTooLongIsNamed) {
  const std::string long_name = "depth/1" + std::string(300, '0') + ".png";
  const std::string dir =
      MakeDir("tumlong", "rgb/10.0.png " + long_name + " 0 0 0 0 0 0 1\n");
  auto scan = ImportTum(dir);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("my_association.txt: line 1: depth image"));
  EXPECT_THAT(scan.status().message(), HasSubstr("too long"));
}

TEST(TumImportTest, NonUnitQuaternionIsRejected) {
  const std::string dir =
      MakeDir("tumq", "rgb/10.0.png depth/10.5.png 0 0 0 0 0 0.5 1\n");
  auto scan = ImportTum(dir);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("line 1"));
  EXPECT_THAT(scan.status().message(), HasSubstr("norm"));
}

TEST(TumImportTest, ConflictingPosesAtOneTimeAreRejected) {
  const std::string dir = MakeDir("tumdup", "rgb/10.0.png depth/10.5.png 0 0 0 0 0 0 1\n"
                                            "rgb/10.0.png depth/10.6.png 1 0 0 0 0 0 1\n");
  auto scan = ImportTum(dir);
  ASSERT_FALSE(scan.ok());
  EXPECT_THAT(scan.status().message(), HasSubstr("lines 1 and 2"));
}

TEST(TumImportTest, BadOptionsAreRejected) {
  TumOptions options;
  options.stride = 0;
  EXPECT_EQ(ImportTum(kDir, options).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(TumImportTest, WritesAScanThatValidates) {
  const std::string out = (fs::path(::testing::TempDir()) / "tum.h5").string();
  TumOptions options;
  options.stride = 2;
  auto summary = WriteImport(out, TumSensor(options), [&](const FrameSink& sink) {
    return ImportTum(kDir, options, sink);
  });
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frames, 10u);
  auto reader = ScanReader::Open(out);
  ASSERT_TRUE(reader.ok()) << reader.status();
  ASSERT_TRUE((*reader)->Validate().ok()) << (*reader)->Validate();
  const SensorInfo& s = (*reader)->sensors()[0];
  EXPECT_EQ(s.kind, SensorKind::kGrid);
  EXPECT_EQ(s.rows, 240u);
  EXPECT_EQ(s.cols, 320u);
  EXPECT_EQ(s.max_range_m, 8.0);
  EXPECT_EQ((*reader)->frame_count(0), 10u);
  EXPECT_EQ((*reader)->path().size(), 1610u);
  auto frame = (*reader)->ReadFrame(0, 4);
  ASSERT_TRUE(frame.ok()) << frame.status();
  const auto& full = Fixture();
  ASSERT_TRUE(full.ok());
  EXPECT_EQ(frame->t, full->frames[4].t);
  const Eigen::Vector3f a = frame->points_sensor[100 * 320 + 150];
  const Eigen::Vector3f b = full->frames[4].points_sensor[200 * 640 + 300];
  EXPECT_TRUE(a == b || (a.array().isNaN().all() && b.array().isNaN().all()));
}

}  // namespace
}  // namespace carvemap
