#include "services/building/truth_writer.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "services/building/building_presets.h"

namespace carvemap {
namespace {

std::set<std::string> Keys(const nlohmann::json& j) {
  std::set<std::string> k;
  for (auto it = j.begin(); it != j.end(); ++it) k.insert(it.key());
  return k;
}

std::string Header(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string line, header;
  while (std::getline(in, line) && line != "end_header") header += line + "\n";
  return header;
}

TEST(TruthWriterTest, WritesDesignSection4Layout) {
  absl::StatusOr<Building> b = MakePresetBuilding("office2", 3);
  ASSERT_TRUE(b.ok()) << b.status();
  const std::string dir = ::testing::TempDir() + "/truth_writer_test/gt";
  std::filesystem::remove_all(dir);
  ASSERT_TRUE(WriteTruth(*b, dir).ok());

  std::ifstream in(dir + "/building.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(Keys(j), (std::set<std::string>{"name", "levels", "rooms", "doors", "objects"}));
  ASSERT_EQ(j["levels"].size(), b->levels.size());
  for (const auto& l : j["levels"]) {
    EXPECT_EQ(Keys(l), (std::set<std::string>{"index", "floor_z", "ceiling_z"}));
  }
  ASSERT_EQ(j["rooms"].size(), b->rooms.size());
  for (size_t i = 0; i < b->rooms.size(); ++i) {
    const auto& r = j["rooms"][i];
    EXPECT_EQ(Keys(r), (std::set<std::string>{"id", "level", "polygon", "holes", "floor_z",
                                              "ceiling_z", "entered", "area_m2"}));
    EXPECT_EQ(r["polygon"].size(), b->rooms[i].polygon.size());
    EXPECT_EQ(r["polygon"][0].size(), 2u);
    EXPECT_DOUBLE_EQ(r["polygon"][1][0].get<double>(), b->rooms[i].polygon[1].x());
    EXPECT_EQ(r["holes"].size(), b->rooms[i].holes.size());
    EXPECT_EQ(r["entered"].get<bool>(), b->rooms[i].entered);
  }
  ASSERT_EQ(j["doors"].size(), b->doors.size());
  for (const auto& d : j["doors"]) {
    EXPECT_EQ(Keys(d), (std::set<std::string>{"id", "level", "rooms", "segment", "width"}));
    EXPECT_EQ(d["rooms"].size(), 2u);
    EXPECT_EQ(d["segment"].size(), 2u);
  }
  ASSERT_EQ(j["objects"].size(), b->objects.size());
  for (const auto& o : j["objects"]) {
    EXPECT_EQ(Keys(o), (std::set<std::string>{"id", "kind", "level", "aabb"}));
    ASSERT_EQ(o["aabb"].size(), 2u);
    for (int k = 0; k < 3; ++k) {
      EXPECT_LE(o["aabb"][0][k].get<double>(), o["aabb"][1][k].get<double>());
    }
  }

  const std::string surfaces = Header(dir + "/surfaces.ply");
  EXPECT_NE(surfaces.find("format binary_little_endian 1.0"), std::string::npos);
  EXPECT_NE(surfaces.find(absl::StrCat("element face ", StructureMesh(*b).triangles.size())),
            std::string::npos);
  const std::string objects = Header(dir + "/objects.ply");
  EXPECT_NE(objects.find("property list uchar int vertex_indices\nproperty int object"),
            std::string::npos);
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(e.path().extension(), e.path().extension() == ".json" ? ".json" : ".ply");
  }
}

}  // namespace
}  // namespace carvemap
