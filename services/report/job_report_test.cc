#include "services/report/job_report.h"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <gtest/gtest.h>

#include "services/report/report_assets.h"
#include "tests/support/test_meshes.h"

namespace carvemap {
namespace {

using testing::ReadFileBytes;

namespace fs = std::filesystem;

void Write(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << text;
}

class JobReportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::path(::testing::TempDir()) / "job_report_test";
    fs::remove_all(root_);
    libs_.three_dir = (root_ / "three").string();
    libs_.leaflet_dir = (root_ / "leaflet").string();
    Write(root_ / "three/three.min.js", "var THREE = {};");
    Write(root_ / "three/examples/js/loaders/GLTFLoader.js", "// loader");
    Write(root_ / "three/examples/js/controls/OrbitControls.js", "// controls");
    Write(root_ / "leaflet/leaflet.js", "var L = {};");
    Write(root_ / "leaflet/leaflet.css", ".leaflet {}");
    out_ = root_ / "out";
    Write(out_ / "levels.json", R"([{"index": 0, "floor_z": 0.0, "ceiling_z": 2.5},
                                    {"index": 1, "floor_z": 3.0, "ceiling_z": 5.5}])");
    Write(out_ / "level_0/floorplan.geojson", R"({"type": "FeatureCollection", "features": []})");
    Write(out_ / "level_0/topdown.json", R"({"image": "topdown.png", "origin_m": [-4, -2],
        "resolution_m": 0.0625, "width": 64, "height": 32})");
    Write(out_ / "level_1/topdown.json", R"({"image": "", "origin_m": [0, 0],
        "resolution_m": 0.0625, "width": 0, "height": 0})");
    Write(out_ / "mesh/model.glb", "glTF");
  }
  fs::path root_, out_;
  ReportLibraries libs_;
};

// The page, its script, the job's data and the libraries land where index.html looks for them.
TEST_F(JobReportTest, WritesThePageItsDataAndTheLibraries) {
  const nlohmann::json job = {{"job_id", "j-1"}, {"rooms", {{{"level", 0}, {"room", 0}}}}};
  ASSERT_TRUE(WriteJobReport(out_.string(), job, libs_).ok());
  EXPECT_EQ(ReadFileBytes(out_ / "index.html"), kReportIndexHtml);
  EXPECT_EQ(ReadFileBytes(out_ / "report/report.js"), kReportJs);
  EXPECT_EQ(ReadFileBytes(out_ / "report/lib/three.min.js"), "var THREE = {};");
  for (const char* f : {"GLTFLoader.js", "OrbitControls.js", "leaflet.js", "leaflet.css"}) {
    EXPECT_TRUE(fs::exists(out_ / "report/lib" / f)) << f;
    // Every library the page loads is one the report copies.
    EXPECT_NE(std::string(kReportIndexHtml).find(std::string("report/lib/") + f), std::string::npos)
        << f;
  }
  const std::string js = ReadFileBytes(out_ / "report/data.js");
  const std::string prefix = "window.CARVEMAP = ";
  ASSERT_EQ(js.substr(0, prefix.size()), prefix);
  ASSERT_EQ(js.substr(js.size() - 2), ";\n");
  const nlohmann::json data =
      nlohmann::json::parse(js.substr(prefix.size(), js.size() - prefix.size() - 2));
  EXPECT_EQ(data["job"], job);
  EXPECT_EQ(data["model"], "mesh/model.glb");
  ASSERT_EQ(data["levels"].size(), 2u);
  EXPECT_EQ(data["levels"][0]["topdown"]["image"], "level_0/topdown.png");
  EXPECT_EQ(data["levels"][0]["plan"]["type"], "FeatureCollection");
  EXPECT_DOUBLE_EQ(data["levels"][1]["floor_z"].get<double>(), 3.0);
  EXPECT_TRUE(data["levels"][1]["plan"].is_null());
  EXPECT_TRUE(data["levels"][1]["topdown"].is_null());  // an empty map has no image
  for (const auto& entry : fs::recursive_directory_iterator(out_)) {
    EXPECT_EQ(entry.path().string().find(".partial"), std::string::npos) << entry.path();
  }
}

// Without a library there is no page, and the error says which file and which package.
TEST_F(JobReportTest, MissingLibraryNamesItsPackage) {
  fs::remove(root_ / "leaflet/leaflet.js");
  const absl::Status s = WriteJobReport(out_.string(), nlohmann::json::object(), libs_);
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(s.message().find("leaflet.js"), std::string::npos) << s;
  EXPECT_NE(s.message().find("libjs-leaflet"), std::string::npos) << s;
  EXPECT_FALSE(fs::exists(out_ / "index.html"));
}

// A level file that is not JSON is named, and no page is written.
TEST_F(JobReportTest, BadLevelFileIsNamed) {
  Write(out_ / "level_0/floorplan.geojson", "{not json");
  const absl::Status s = WriteJobReport(out_.string(), nlohmann::json::object(), libs_);
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("level_0/floorplan.geojson"), std::string::npos) << s;
  EXPECT_FALSE(fs::exists(out_ / "index.html"));
}

}  // namespace
}  // namespace carvemap
