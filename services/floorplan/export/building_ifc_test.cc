#include "services/floorplan/export/building_ifc.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "services/floorplan/export/floorplan_dxf.h"
#include "services/floorplan/model/room_polygons.h"
#include "services/floorplan/test_plans.h"
#include "storage/atomic_file.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using Eigen::Vector2d;

// --- A small reader of ISO 10303-21 (STEP) text ----------------------------------------------

struct Value {
  enum Kind { kNull, kDerived, kRef, kString, kNumber, kEnum, kList, kTyped } kind = kNull;
  std::string text;  // a string's content, a number, an enumeration or a typed value's type
  int ref = 0;
  std::vector<Value> items;  // a list's items, or a typed value's argument
  double number() const { return std::stod(text); }
};

struct Entity {
  std::string type;
  std::vector<Value> args;
};

struct StepFile {
  std::string header;
  std::map<int, Entity> entities;
  std::vector<std::string> errors;
};

class StepParser {
 public:
  explicit StepParser(const std::string& s) : s_(s) {}

  StepFile Parse() {
    StepFile f;
    const size_t data = s_.find("\nDATA;\n");
    const size_t end = s_.rfind("ENDSEC;");
    if (s_.rfind("ISO-10303-21;\nHEADER;\n", 0) != 0 || data == std::string::npos ||
        end == std::string::npos || end < data) {
      f.errors.push_back("not ISO 10303-21 text with a HEADER and a DATA section");
      return f;
    }
    f.header = s_.substr(0, data);
    at_ = data + 7;
    while (true) {
      Skip();
      if (s_.compare(at_, 7, "ENDSEC;") == 0) break;
      if (at_ >= s_.size() || s_[at_] != '#') {
        f.errors.push_back(Expected("an instance starting with '#'"));
        return f;
      }
      ++at_;
      const int id = Integer();
      Skip();
      if (!Eat('=')) {
        f.errors.push_back(Expected("'='"));
        return f;
      }
      Skip();
      Entity e;
      e.type = Keyword();
      Value args = List();
      if (!ok_ || !Eat(';')) {
        f.errors.push_back(Expected("an instance's arguments and ';'"));
        return f;
      }
      e.args = std::move(args.items);
      if (!f.entities.emplace(id, std::move(e)).second) {
        f.errors.push_back("#" + std::to_string(id) + " defined twice");
      }
    }
    return f;
  }

 private:
  std::string Expected(const std::string& what) {
    return "expected " + what + " at byte " + std::to_string(at_);
  }
  void Skip() {
    while (at_ < s_.size()) {
      if (std::isspace(static_cast<unsigned char>(s_[at_]))) {
        ++at_;
      } else if (s_.compare(at_, 2, "/*") == 0) {
        const size_t close = s_.find("*/", at_ + 2);
        at_ = close == std::string::npos ? s_.size() : close + 2;
      } else {
        break;
      }
    }
  }
  bool Eat(char c) {
    if (at_ < s_.size() && s_[at_] == c) {
      ++at_;
      return true;
    }
    return false;
  }
  int Integer() {
    size_t n = 0;
    while (at_ + n < s_.size() && std::isdigit(static_cast<unsigned char>(s_[at_ + n]))) ++n;
    if (n == 0) {
      ok_ = false;
      return 0;
    }
    const int v = std::stoi(s_.substr(at_, n));
    at_ += n;
    return v;
  }
  std::string Keyword() {
    size_t n = 0;
    while (at_ + n < s_.size() &&
           (std::isalnum(static_cast<unsigned char>(s_[at_ + n])) || s_[at_ + n] == '_')) {
      ++n;
    }
    std::string k = s_.substr(at_, n);
    at_ += n;
    if (k.empty()) ok_ = false;
    return k;
  }
  Value List() {
    Value v;
    v.kind = Value::kList;
    Skip();
    if (!Eat('(')) {
      ok_ = false;
      return v;
    }
    Skip();
    if (Eat(')')) return v;
    while (ok_) {
      v.items.push_back(One());
      Skip();
      if (Eat(')')) return v;
      if (!Eat(',')) ok_ = false;
    }
    return v;
  }
  Value One() {
    Skip();
    Value v;
    if (at_ >= s_.size()) {
      ok_ = false;
      return v;
    }
    const char c = s_[at_];
    if (c == '$') {
      ++at_;
    } else if (c == '*') {
      ++at_;
      v.kind = Value::kDerived;
    } else if (c == '#') {
      ++at_;
      v.kind = Value::kRef;
      v.ref = Integer();
    } else if (c == '\'') {
      v.kind = Value::kString;
      ++at_;
      while (true) {
        if (at_ >= s_.size()) {
          ok_ = false;
          break;
        }
        if (s_[at_] == '\'') {
          if (at_ + 1 < s_.size() && s_[at_ + 1] == '\'') {
            v.text.push_back('\'');
            at_ += 2;
            continue;
          }
          ++at_;
          break;
        }
        v.text.push_back(s_[at_++]);
      }
    } else if (c == '.') {
      ++at_;
      v.kind = Value::kEnum;
      v.text = Keyword();
      if (!Eat('.')) ok_ = false;
    } else if (c == '(') {
      v = List();
    } else if (c == '-' || c == '+' || std::isdigit(static_cast<unsigned char>(c))) {
      v.kind = Value::kNumber;
      size_t n = 0;
      while (at_ + n < s_.size() && std::strchr("+-0123456789.E", s_[at_ + n]) != nullptr) ++n;
      v.text = s_.substr(at_, n);
      at_ += n;
    } else if (std::isalpha(static_cast<unsigned char>(c))) {
      v.kind = Value::kTyped;
      v.text = Keyword();
      v.items = List().items;
    } else {
      ok_ = false;
    }
    return v;
  }

  const std::string& s_;
  size_t at_ = 0;
  bool ok_ = true;
};

// Attribute counts of the entities the writer uses, from the IFC4 ADD2 TC1 specification
// (each entity's attributes with its supertypes'; derived ones, written '*', included), checked
// against web-ifc's IFC4 schema (whose constructors leave the derived ones out: IfcSIUnit's
// Dimensions, the subcontext's four).
const std::map<std::string, size_t>& AttributeCounts() {
  static const std::map<std::string, size_t> counts = {
      {"IFCPROJECT", 9},
      {"IFCSITE", 14},
      {"IFCBUILDING", 12},
      {"IFCBUILDINGSTOREY", 10},
      {"IFCSPACE", 11},
      {"IFCWALL", 9},
      {"IFCDOOR", 13},
      {"IFCVIRTUALELEMENT", 8},
      {"IFCRELAGGREGATES", 6},
      {"IFCRELCONTAINEDINSPATIALSTRUCTURE", 6},
      {"IFCRELDEFINESBYPROPERTIES", 6},
      {"IFCRELSPACEBOUNDARY", 9},
      {"IFCELEMENTQUANTITY", 6},
      {"IFCQUANTITYAREA", 5},
      {"IFCQUANTITYLENGTH", 5},
      {"IFCQUANTITYVOLUME", 5},
      {"IFCUNITASSIGNMENT", 1},
      {"IFCSIUNIT", 4},
      {"IFCGEOMETRICREPRESENTATIONCONTEXT", 6},
      {"IFCGEOMETRICREPRESENTATIONSUBCONTEXT", 10},
      {"IFCCARTESIANPOINT", 1},
      {"IFCDIRECTION", 1},
      {"IFCAXIS2PLACEMENT3D", 3},
      {"IFCAXIS2PLACEMENT2D", 2},
      {"IFCLOCALPLACEMENT", 2},
      {"IFCPRODUCTDEFINITIONSHAPE", 3},
      {"IFCSHAPEREPRESENTATION", 4},
      {"IFCEXTRUDEDAREASOLID", 4},
      {"IFCARBITRARYCLOSEDPROFILEDEF", 3},
      {"IFCARBITRARYPROFILEDEFWITHVOIDS", 4},
      {"IFCPOLYLINE", 1},
      {"IFCRECTANGLEPROFILEDEF", 5},
  };
  return counts;
}

// Entities whose first attribute is an IfcRoot's GlobalId.
const std::set<std::string> kRooted = {"IFCPROJECT",
                                       "IFCSITE",
                                       "IFCBUILDING",
                                       "IFCBUILDINGSTOREY",
                                       "IFCSPACE",
                                       "IFCWALL",
                                       "IFCDOOR",
                                       "IFCVIRTUALELEMENT",
                                       "IFCRELAGGREGATES",
                                       "IFCRELCONTAINEDINSPATIALSTRUCTURE",
                                       "IFCRELDEFINESBYPROPERTIES",
                                       "IFCRELSPACEBOUNDARY",
                                       "IFCELEMENTQUANTITY"};

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void CollectRefs(const Value& v, std::vector<int>& out) {
  if (v.kind == Value::kRef) out.push_back(v.ref);
  for (const Value& item : v.items) CollectRefs(item, out);
}

// A parsed file with lookups.
struct Model {
  StepFile f;
  const Entity& at(int id) const { return f.entities.at(id); }
  const Entity& at(const Value& v) const { return at(v.ref); }
  std::vector<int> OfType(const std::string& type) const {
    std::vector<int> ids;
    for (const auto& [id, e] : f.entities) {
      if (e.type == type) ids.push_back(id);
    }
    return ids;
  }
  // The z of a local placement in the world: its own plus those it is relative to.
  double PlacementZ(int id) const {
    double z = 0;
    while (id != 0) {
      const Entity& p = at(id);
      EXPECT_EQ(p.type, "IFCLOCALPLACEMENT");
      z += at(at(p.args[1]).args[0]).args[0].items[2].number();
      id = p.args[0].kind == Value::kRef ? p.args[0].ref : 0;
    }
    return z;
  }
  // The points of an IfcPolyline, 2D.
  std::vector<Vector2d> Polyline(const Value& v) const {
    const Entity& line = at(v);
    EXPECT_EQ(line.type, "IFCPOLYLINE");
    std::vector<Vector2d> ring;
    for (const Value& p : line.args[0].items) {
      const auto& c = at(p).args[0].items;
      ring.emplace_back(c[0].number(), c[1].number());
    }
    EXPECT_GE(ring.size(), 4u);
    EXPECT_EQ(line.args[0].items.front().ref, line.args[0].items.back().ref) << "not closed";
    ring.pop_back();
    return ring;
  }
  // The area of a profile: its outer curve less its voids.
  double ProfileArea(const Value& v) const {
    const Entity& p = at(v);
    if (p.type == "IFCRECTANGLEPROFILEDEF") return p.args[3].number() * p.args[4].number();
    double area = std::abs(RingSignedArea(Polyline(p.args[2])));
    if (p.type == "IFCARBITRARYPROFILEDEFWITHVOIDS") {
      for (const Value& hole : p.args[3].items) area -= std::abs(RingSignedArea(Polyline(hole)));
    } else {
      EXPECT_EQ(p.type, "IFCARBITRARYCLOSEDPROFILEDEF");
    }
    return area;
  }
  // The solids of a product's Body representation.
  std::vector<const Entity*> Solids(const Entity& product) const {
    std::vector<const Entity*> solids;
    if (product.args[6].kind != Value::kRef) return solids;
    const Entity& shape = at(product.args[6]);
    EXPECT_EQ(shape.type, "IFCPRODUCTDEFINITIONSHAPE");
    for (const Value& rep : shape.args[2].items) {
      const Entity& r = at(rep);
      EXPECT_EQ(r.args[1].text, "Body");
      EXPECT_EQ(r.args[2].text, "SweptSolid");
      EXPECT_EQ(at(r.args[0]).type, "IFCGEOMETRICREPRESENTATIONSUBCONTEXT");
      for (const Value& item : r.args[3].items) {
        EXPECT_EQ(at(item).type, "IFCEXTRUDEDAREASOLID");
        solids.push_back(&at(item));
      }
    }
    return solids;
  }
  // The relationship instances of `type` whose attribute `from` references `id`.
  std::vector<const Entity*> RelsTo(const std::string& type, size_t from, int id) const {
    std::vector<const Entity*> out;
    for (const auto& [rid, e] : f.entities) {
      if (e.type != type) continue;
      std::vector<int> refs;
      CollectRefs(e.args[from], refs);
      if (std::find(refs.begin(), refs.end(), id) != refs.end()) out.push_back(&e);
    }
    return out;
  }
};

Model Parse(const std::string& text) {
  Model m;
  m.f = StepParser(text).Parse();
  return m;
}

// --- Hand-made plans ---------------------------------------------------------------------------

// A 2 × 1 m strip cut into two rooms by the line x = 1 (one doorway); room 1 lower than a door,
// whose height is then the room's.
FloorPlan TwoRooms() {
  FloorPlan plan = TwoRoomsPlan(0.0, 2.5);
  plan.rooms[1].ceiling_z = 2.0;
  return plan;
}

FloorPlan RoomInRoom() { return RoomInRoomPlan(3.0, 5.6); }

// One room in two unit squares 1 m apart (two pieces: two solids), and an empty room.
FloorPlan TwoPieces() {
  FloorPlan plan;
  plan.vertices = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {2, 0}, {3, 0}, {3, 1}, {2, 1}};
  plan.triangles = {{0, 1, 2}, {0, 2, 3}, {4, 5, 6}, {4, 6, 7}};
  plan.triangle_room = {0, 0, 0, 0};
  plan.rooms.resize(2);
  plan.rooms[0].seed_triangle = 0;
  SetPlanHeights(plan, 6.1, 8.4);
  return plan;
}

Level MakeLevel(int index, double floor_z, double ceiling_z) {
  Level level;
  level.index = index;
  level.floor_z = floor_z;
  level.ceiling_z = ceiling_z;
  return level;
}

std::vector<std::pair<Level, FloorPlan>> Building() {
  return {{MakeLevel(0, 0.0, 2.5), TwoRooms()},
          {MakeLevel(1, 3.0, 5.6), RoomInRoom()},
          {MakeLevel(2, 6.1, 8.4), TwoPieces()}};
}

double TriangleArea(const FloorPlan& plan, int room) {
  double area = 0;
  for (size_t t = 0; t < plan.triangles.size(); ++t) {
    if (plan.triangle_room[t] != room) continue;
    const Vector2d a = plan.vertices[plan.triangles[t][0]], b = plan.vertices[plan.triangles[t][1]],
                   c = plan.vertices[plan.triangles[t][2]];
    area += 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
  }
  return area;
}

std::string TestDir(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/building_ifc_" + name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// --- Tests -------------------------------------------------------------------------------------

TEST(BuildingIfc, FileIsWellFormedIfc4) {
  const auto plans = Building();
  const std::string path = TestDir("well_formed") + "/building.ifc";
  const absl::StatusOr<BuildingIfcCounts> counts = WriteBuildingIfc(path, plans);
  ASSERT_TRUE(counts.ok()) << counts.status();
  EXPECT_FALSE(fs::exists(PartialPath(path)));
  const std::string text = ReadFile(path);
  EXPECT_NE(text.find("\nFILE_SCHEMA(('IFC4'));\n"), std::string::npos);
  EXPECT_NE(text.find("\nFILE_NAME('building.ifc',"), std::string::npos);
  ASSERT_GE(text.size(), 26u);
  EXPECT_EQ(text.substr(text.size() - 26), "ENDSEC;\nEND-ISO-10303-21;\n");

  const Model m = Parse(text);
  ASSERT_TRUE(m.f.errors.empty()) << m.f.errors[0];
  EXPECT_EQ(m.f.entities.size(), counts->entities);
  std::set<std::string> guids;
  for (const auto& [id, e] : m.f.entities) {
    SCOPED_TRACE("#" + std::to_string(id) + " " + e.type);
    // Every entity is one of the schema's, with its number of attributes.
    const auto it = AttributeCounts().find(e.type);
    ASSERT_NE(it, AttributeCounts().end()) << "not in the table";
    EXPECT_EQ(e.args.size(), it->second);
    // Every reference resolves.
    std::vector<int> refs;
    for (const Value& v : e.args) CollectRefs(v, refs);
    for (int r : refs) EXPECT_TRUE(m.f.entities.count(r)) << "#" << r << " is not defined";
    // GlobalIds: 22 characters of IFC's base 64, the first 0–3 (2 bits), all different.
    if (kRooted.count(e.type)) {
      ASSERT_EQ(e.args[0].kind, Value::kString);
      const std::string& g = e.args[0].text;
      ASSERT_EQ(g.size(), 22u) << g;
      EXPECT_NE(std::string("0123").find(g[0]), std::string::npos) << g;
      for (char c : g) {
        EXPECT_TRUE(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '$') << g;
      }
      EXPECT_TRUE(guids.insert(g).second) << "GlobalId " << g << " repeated";
    }
  }
  // The units: metre, square metre, cubic metre and radian, unprefixed.
  std::set<std::string> units;
  for (int id : m.OfType("IFCSIUNIT")) {
    const Entity& u = m.at(id);
    EXPECT_EQ(u.args[0].kind, Value::kDerived);
    EXPECT_EQ(u.args[2].kind, Value::kNull);
    units.insert(u.args[1].text + " " + u.args[3].text);
  }
  EXPECT_EQ(units, (std::set<std::string>{"LENGTHUNIT METRE", "AREAUNIT SQUARE_METRE",
                                          "VOLUMEUNIT CUBIC_METRE", "PLANEANGLEUNIT RADIAN"}));
}

TEST(BuildingIfc, HierarchyStoreysSpacesWallsAndDoorsFollowThePlans) {
  const auto plans = Building();
  const std::string path = TestDir("hierarchy") + "/building.ifc";
  const absl::StatusOr<BuildingIfcCounts> counts = WriteBuildingIfc(path, plans);
  ASSERT_TRUE(counts.ok()) << counts.status();
  const Model m = Parse(ReadFile(path));
  ASSERT_TRUE(m.f.errors.empty()) << m.f.errors[0];

  // Project ➜ site ➜ building ➜ storeys, each by one IfcRelAggregates.
  const auto one = [&](const std::string& type) {
    const std::vector<int> ids = m.OfType(type);
    EXPECT_EQ(ids.size(), 1u) << type;
    return ids.empty() ? 0 : ids[0];
  };
  const int project = one("IFCPROJECT"), site = one("IFCSITE"), building = one("IFCBUILDING");
  const auto children = [&](int parent) {
    std::vector<int> out;
    for (const Entity* rel : m.RelsTo("IFCRELAGGREGATES", 4, parent)) {
      for (const Value& v : rel->args[5].items) out.push_back(v.ref);
    }
    return out;
  };
  EXPECT_EQ(children(project), std::vector<int>{site});
  EXPECT_EQ(children(site), std::vector<int>{building});
  const std::vector<int> storeys = children(building);
  ASSERT_EQ(storeys.size(), plans.size());
  EXPECT_EQ(m.OfType("IFCBUILDINGSTOREY").size(), plans.size());
  EXPECT_EQ(counts->storeys, plans.size());
  // The project's contexts: 'Model' 3D, and 'Body' under it.
  const Entity& context = m.at(m.at(project).args[7].items.at(0));
  EXPECT_EQ(context.type, "IFCGEOMETRICREPRESENTATIONCONTEXT");
  EXPECT_EQ(context.args[1].text, "Model");
  EXPECT_EQ(context.args[2].text, "3");
  const Entity& body = m.at(m.OfType("IFCGEOMETRICREPRESENTATIONSUBCONTEXT").at(0));
  EXPECT_EQ(body.args[0].text, "Body");
  EXPECT_EQ(body.args[6].ref, m.at(project).args[7].items[0].ref);

  size_t spaces_expected = 0, doors_expected = 0, openings_expected = 0;
  for (size_t k = 0; k < plans.size(); ++k) {
    const auto& [level, plan] = plans[k];
    SCOPED_TRACE("level " + std::to_string(level.index));
    const Entity& storey = m.at(storeys[k]);
    EXPECT_EQ(storey.type, "IFCBUILDINGSTOREY");
    EXPECT_EQ(storey.args[2].text, "level " + std::to_string(level.index));
    EXPECT_NEAR(storey.args[9].number(), level.floor_z, 1e-9);
    EXPECT_NEAR(m.PlacementZ(storey.args[5].ref), level.floor_z, 1e-9);

    // Spaces: one per room with triangles, its area and height the plan's.
    const std::vector<int> spaces = children(storeys[k]);
    std::map<std::string, int> by_name;
    for (int s : spaces) {
      EXPECT_EQ(m.at(s).type, "IFCSPACE");
      by_name[m.at(s).args[2].text] = s;
    }
    for (size_t r = 0; r < plan.rooms.size(); ++r) {
      const double area = TriangleArea(plan, static_cast<int>(r));
      const std::string name =
          "level " + std::to_string(level.index) + " room " + std::to_string(r);
      if (area <= 0) {
        EXPECT_FALSE(by_name.count(name)) << name << " has no triangles";
        continue;
      }
      ++spaces_expected;
      ASSERT_TRUE(by_name.count(name)) << name;
      SCOPED_TRACE(name);
      const Entity& space = m.at(by_name[name]);
      const double height = plan.rooms[r].ceiling_z - plan.rooms[r].floor_z;
      EXPECT_NEAR(m.PlacementZ(space.args[5].ref), plan.rooms[r].floor_z, 1e-9);
      double profile_area = 0;
      const auto solids = m.Solids(space);
      for (const Entity* solid : solids) {
        EXPECT_NEAR(solid->args[3].number(), height, 1e-6);
        const auto& dir = m.at(solid->args[2]).args[0].items;
        EXPECT_EQ(dir[2].number(), 1.0);
        profile_area += m.ProfileArea(solid->args[0]);
      }
      EXPECT_NEAR(profile_area, area, 1e-6);
      // Qto_SpaceBaseQuantities by IfcRelDefinesByProperties.
      const auto defines = m.RelsTo("IFCRELDEFINESBYPROPERTIES", 4, by_name[name]);
      ASSERT_EQ(defines.size(), 1u);
      const Entity& qto = m.at(defines[0]->args[5]);
      EXPECT_EQ(qto.type, "IFCELEMENTQUANTITY");
      EXPECT_EQ(qto.args[2].text, "Qto_SpaceBaseQuantities");
      std::map<std::string, const Entity*> q;
      for (const Value& v : qto.args[5].items) q[m.at(v).args[0].text] = &m.at(v);
      ASSERT_TRUE(q.count("NetFloorArea") && q.count("Height"));
      EXPECT_EQ(q["NetFloorArea"]->type, "IFCQUANTITYAREA");
      EXPECT_NEAR(q["NetFloorArea"]->args[3].number(), area, 1e-6);
      EXPECT_EQ(q["Height"]->type, "IFCQUANTITYLENGTH");
      EXPECT_NEAR(q["Height"]->args[3].number(), height, 1e-6);
      if (k == 1 && r == 0) {
        ASSERT_EQ(solids.size(), 1u);
        EXPECT_EQ(m.at(solids[0]->args[0]).type, "IFCARBITRARYPROFILEDEFWITHVOIDS");
      }
      if (k == 2 && r == 0) {
        EXPECT_EQ(solids.size(), 2u) << "one solid per piece";
      }
    }

    // Walls and doors, contained in the storey.
    const auto contained = m.RelsTo("IFCRELCONTAINEDINSPATIALSTRUCTURE", 5, storeys[k]);
    ASSERT_EQ(contained.size(), 1u);
    std::vector<int> walls, doors, openings;
    for (const Value& v : contained[0]->args[4].items) {
      const std::string& type = m.at(v).type;
      (type == "IFCWALL" ? walls : type == "IFCDOOR" ? doors : openings).push_back(v.ref);
      EXPECT_EQ(m.RelsTo("IFCRELCONTAINEDINSPATIALSTRUCTURE", 4, v.ref).size(), 1u);
    }
    // Borders as wide as a door are doors, the others virtual boundaries, in border order.
    const BuildingIfcOptions options;
    size_t next_door = 0, next_opening = 0;
    for (const auto& border : RoomBorders(plan)) {
      double length = 0;
      for (size_t j = 1; j < border.size(); ++j) length += (border[j] - border[j - 1]).norm();
      if (length < options.min_door_width_m || length > options.max_door_width_m) {
        ASSERT_LT(next_opening, openings.size());
        const int opening = openings[next_opening++];
        EXPECT_EQ(m.at(opening).type, "IFCVIRTUALELEMENT");
        EXPECT_EQ(m.at(opening).args.size(), 8u);
        const auto bounds = m.RelsTo("IFCRELSPACEBOUNDARY", 5, opening);
        ASSERT_EQ(bounds.size(), 2u);
        EXPECT_EQ(bounds[0]->args[7].text, "VIRTUAL");
        continue;
      }
      ++doors_expected;
      ASSERT_LT(next_door, doors.size());
      const Entity& door = m.at(doors[next_door]);
      EXPECT_NEAR(door.args[9].number(), length, 1e-6);  // OverallWidth
      EXPECT_EQ(door.args[10].text, "DOOR");
      // Bounding both rooms' spaces.
      const auto bounds = m.RelsTo("IFCRELSPACEBOUNDARY", 5, doors[next_door++]);
      ASSERT_EQ(bounds.size(), 2u);
      EXPECT_EQ(bounds[0]->args[7].text, "PHYSICAL");
    }
    EXPECT_EQ(next_door, doors.size());
    EXPECT_EQ(next_opening, openings.size());
    openings_expected += openings.size();
    // The walls' runs cover the wall loops: their lengths add up to the loops' perimeter.
    const absl::StatusOr<FloorPlanOutline> outline = TraceFloorPlan(plan);
    ASSERT_TRUE(outline.ok());
    double perimeter = 0, run_lengths = 0;
    for (const auto& loop : outline->walls) {
      for (size_t j = 1; j < loop.size(); ++j) perimeter += (loop[j] - loop[j - 1]).norm();
    }
    for (int w : walls) {
      const auto solids = m.Solids(m.at(w));
      ASSERT_EQ(solids.size(), 1u);
      const Entity& profile = m.at(solids[0]->args[0]);
      ASSERT_EQ(profile.type, "IFCRECTANGLEPROFILEDEF");
      run_lengths += profile.args[3].number();
      EXPECT_NEAR(profile.args[4].number(), BuildingIfcOptions{}.wall_thickness_m, 1e-9);
      EXPECT_EQ(m.RelsTo("IFCRELSPACEBOUNDARY", 5, w).size(), 1u);
    }
    EXPECT_NEAR(run_lengths, perimeter, 1e-6);
  }
  EXPECT_EQ(m.OfType("IFCSPACE").size(), spaces_expected);
  EXPECT_EQ(counts->spaces, spaces_expected);
  EXPECT_EQ(m.OfType("IFCDOOR").size(), doors_expected);
  EXPECT_EQ(counts->doors, doors_expected);
  EXPECT_EQ(counts->openings, openings_expected);
  EXPECT_GT(openings_expected, 0u);  // the room in a room: a 4 m closed border
  EXPECT_GT(doors_expected, 0u);
  EXPECT_EQ(m.OfType("IFCWALL").size(), counts->walls);
  EXPECT_EQ(m.OfType("IFCWALLSTANDARDCASE").size(), 0u);
}

TEST(BuildingIfc, StraightWallsAreOneWallEachAndDoorsTakeTheRoomsHeight) {
  // TwoRooms' loop: 6 edges, the bottom and top cut where the rooms meet: 6 walls. Its door
  // is 1 m wide and as high as room 1 (2 m, under the 2.1 m of a door).
  const std::vector<std::pair<Level, FloorPlan>> plans = {{MakeLevel(0, 0, 2.5), TwoRooms()}};
  const std::string path = TestDir("walls") + "/building.ifc";
  const absl::StatusOr<BuildingIfcCounts> counts = WriteBuildingIfc(path, plans);
  ASSERT_TRUE(counts.ok()) << counts.status();
  EXPECT_EQ(counts->walls, 6u);
  EXPECT_EQ(counts->doors, 1u);
  const Model m = Parse(ReadFile(path));
  const Entity& door = m.at(m.OfType("IFCDOOR").at(0));
  EXPECT_NEAR(door.args[8].number(), 2.0, 1e-9);  // OverallHeight
  EXPECT_NEAR(door.args[9].number(), 1.0, 1e-9);  // OverallWidth
  // A square room: 4 walls, though its sides come in 2 edges each.
  FloorPlan square;
  square.vertices = {{0, 0}, {1, 0}, {2, 0}, {2, 2}, {0, 2}};
  square.triangles = {{0, 1, 4}, {1, 3, 4}, {1, 2, 3}};
  square.triangle_room = {0, 0, 0};
  square.rooms.resize(1);
  SetPlanHeights(square, 0, 2.5);
  const std::vector<std::pair<Level, FloorPlan>> one = {{MakeLevel(0, 0, 2.5), square}};
  const absl::StatusOr<BuildingIfcCounts> square_counts = WriteBuildingIfc(path, one);
  ASSERT_TRUE(square_counts.ok()) << square_counts.status();
  EXPECT_EQ(square_counts->walls, 4u);
  EXPECT_EQ(square_counts->doors, 0u);
}

TEST(BuildingIfc, TheSamePlansGiveTheSameBytes) {
  const auto plans = Building();
  const std::string a = TestDir("same_a") + "/building.ifc";
  const std::string b = TestDir("same_b") + "/building.ifc";
  ASSERT_TRUE(WriteBuildingIfc(a, plans).ok());
  ASSERT_TRUE(WriteBuildingIfc(b, plans).ok());
  EXPECT_EQ(ReadFile(a), ReadFile(b));
  // Another building gets other GlobalIds.
  auto moved = plans;
  moved[0].second.vertices[0].x() += 0.01;
  ASSERT_TRUE(WriteBuildingIfc(b, moved).ok());
  const Model ma = Parse(ReadFile(a)), mb = Parse(ReadFile(b));
  EXPECT_NE(ma.at(ma.OfType("IFCPROJECT")[0]).args[0].text,
            mb.at(mb.OfType("IFCPROJECT")[0]).args[0].text);
}

TEST(BuildingIfc, AFolderThatCannotBeWrittenNamesTheFileAndLeavesNothing) {
  const std::string path = ::testing::TempDir() + "/building_ifc_no_such_folder/building.ifc";
  const absl::StatusOr<BuildingIfcCounts> counts = WriteBuildingIfc(path, Building());
  ASSERT_FALSE(counts.ok());
  EXPECT_NE(counts.status().message().find(path), std::string::npos) << counts.status();
  EXPECT_FALSE(fs::exists(path));
  EXPECT_FALSE(fs::exists(PartialPath(path)));
}

TEST(BuildingIfc, ABadPlanNamesItsLevelAndWritesNothing) {
  auto plans = Building();
  plans[1].second.rooms[1].ceiling_z = std::nan("");
  const std::string path = TestDir("bad") + "/building.ifc";
  const absl::StatusOr<BuildingIfcCounts> counts = WriteBuildingIfc(path, plans);
  EXPECT_EQ(counts.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(counts.status().message().find("level 1 room 1"), std::string::npos) << counts.status();
  EXPECT_FALSE(fs::exists(path));
  plans = Building();
  plans[2].second.triangle_room[0] = 7;  // no such room
  const absl::StatusOr<BuildingIfcCounts> traced = WriteBuildingIfc(path, plans);
  EXPECT_FALSE(traced.ok());
  EXPECT_NE(traced.status().message().find("level 2"), std::string::npos) << traced.status();
  EXPECT_FALSE(fs::exists(path));
}

}  // namespace
}  // namespace carvemap
