// building.ifc read by an independent implementation, IFC++ (Debian's libifcplusplus-dev):
// against the output folder's levels.json and job.json, the file loads as IFC 4 without an
// error or warning, holds one IfcBuildingStorey per level at the level's floor height, and one
// IfcSpace per room of job.json, aggregated under its level's storey, whose NetFloorArea is the
// room's area. Prints the counts; exit 1 with the problems otherwise.
//
// Usage: ifcpp_check OUT
#include <ifcpp/IFC4/include/IfcAreaMeasure.h>
#include <ifcpp/IFC4/include/IfcBuildingStorey.h>
#include <ifcpp/IFC4/include/IfcElementQuantity.h>
#include <ifcpp/IFC4/include/IfcLabel.h>
#include <ifcpp/IFC4/include/IfcLengthMeasure.h>
#include <ifcpp/IFC4/include/IfcQuantityArea.h>
#include <ifcpp/IFC4/include/IfcRelAggregates.h>
#include <ifcpp/IFC4/include/IfcRelDefinesByProperties.h>
#include <ifcpp/IFC4/include/IfcSpace.h>
#include <ifcpp/model/BuildingModel.h>
#include <ifcpp/reader/ReaderSTEP.h>

#include <cmath>
#include <codecvt>
#include <fstream>
#include <iostream>
#include <locale>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace {

std::vector<std::string> problems;
int messages = 0;

void OnMessage(void*, shared_ptr<StatusCallback::Message> m) {
  const auto t = m->m_message_type;
  if (t == StatusCallback::MESSAGE_TYPE_WARNING || t == StatusCallback::MESSAGE_TYPE_ERROR ||
      t == StatusCallback::MESSAGE_TYPE_MINOR_WARNING) {
    if (++messages <= 5) {
      problems.push_back("IFC++: " + std::wstring_convert<std::codecvt_utf8<wchar_t>>().to_bytes(
                                         m->m_message_text));
    }
  }
}

std::string Narrow(const shared_ptr<IfcLabel>& label) {
  return label ? std::wstring_convert<std::codecvt_utf8<wchar_t>>().to_bytes(label->m_value)
               : std::string();
}

nlohmann::json ReadJson(const std::string& path) {
  std::ifstream in(path);
  nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  if (j.is_discarded()) problems.push_back(path + ": not JSON");
  return j;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: ifcpp_check OUT\n";
    return 2;
  }
  const std::string out = argv[1];
  const nlohmann::json levels = ReadJson(out + "/levels.json");
  const nlohmann::json job = ReadJson(out + "/job.json");
  std::ifstream in(out + "/building.ifc");
  if (!in) {
    std::cerr << out << "/building.ifc: cannot be read\n";
    return 1;
  }
  std::stringstream text;
  text << in.rdbuf();
  auto model = std::make_shared<BuildingModel>();
  auto reader = std::make_shared<ReaderSTEP>();
  reader->setMessageCallBack(nullptr, &OnMessage);
  // loadModelFromFile takes a wide path, which this build reads as nothing on Linux.
  std::string content = text.str();
  reader->loadModelFromString(content, model);
  if (model->getIfcSchemaVersion().m_ifc_file_schema_enum != BuildingModel::IFC4) {
    problems.push_back("the file's schema is not IFC4");
  }

  std::map<std::string, double> storey_z;  // name -> elevation
  std::map<std::string, std::string> space_storey;
  std::map<std::string, double> space_area;
  std::map<std::string, int> count;
  for (const auto& [id, e] : model->getMapIfcEntities()) {
    count[e->className()]++;
    if (auto s = std::dynamic_pointer_cast<IfcBuildingStorey>(e)) {
      storey_z[Narrow(s->m_Name)] = s->m_Elevation ? s->m_Elevation->m_value : NAN;
    } else if (auto r = std::dynamic_pointer_cast<IfcRelAggregates>(e)) {
      auto storey = std::dynamic_pointer_cast<IfcBuildingStorey>(r->m_RelatingObject);
      for (const auto& o : r->m_RelatedObjects) {
        if (auto sp = std::dynamic_pointer_cast<IfcSpace>(o); sp && storey) {
          space_storey[Narrow(sp->m_Name)] = Narrow(storey->m_Name);
        }
      }
    } else if (auto d = std::dynamic_pointer_cast<IfcRelDefinesByProperties>(e)) {
      auto q = std::dynamic_pointer_cast<IfcElementQuantity>(d->m_RelatingPropertyDefinition);
      if (!q) continue;
      for (const auto& quantity : q->m_Quantities) {
        auto area = std::dynamic_pointer_cast<IfcQuantityArea>(quantity);
        if (!area || !area->m_AreaValue || !area->m_Name ||
            area->m_Name->m_value != L"NetFloorArea") {
          continue;
        }
        for (const auto& o : d->m_RelatedObjects) {
          if (auto sp = std::dynamic_pointer_cast<IfcSpace>(o)) {
            space_area[Narrow(sp->m_Name)] = area->m_AreaValue->m_value;
          }
        }
      }
    }
  }

  if (storey_z.size() != levels.size()) {
    problems.push_back(std::to_string(storey_z.size()) + " storeys, levels.json has " +
                       std::to_string(levels.size()) + " levels");
  }
  for (const auto& level : levels) {
    const std::string name = "level " + std::to_string(level.value("index", -1));
    const auto it = storey_z.find(name);
    if (it == storey_z.end()) {
      problems.push_back("no storey \"" + name + "\"");
    } else if (!(std::abs(it->second - level.value("floor_z", 0.0)) < 1e-6)) {
      problems.push_back(name + ": elevation " + std::to_string(it->second) + ", floor_z " +
                         std::to_string(level.value("floor_z", 0.0)));
    }
  }
  std::set<std::string> rooms;
  for (const auto& room : job.value("rooms", nlohmann::json::array())) {
    if (!(room.value("area_m2", 0.0) > 0)) continue;
    const int level = room.value("level", -1);
    const std::string name =
        "level " + std::to_string(level) + " room " + std::to_string(room.value("room", -1));
    rooms.insert(name);
    if (space_storey.count(name) == 0) {
      problems.push_back("room \"" + name + "\" of job.json: no IfcSpace under a storey");
    } else if (space_storey[name] != "level " + std::to_string(level)) {
      problems.push_back(name + ": under storey \"" + space_storey[name] + "\"");
    }
    const double area = room.value("area_m2", 0.0);
    if (!(std::abs(space_area[name] - area) <= 1e-3 * area + 1e-6)) {
      problems.push_back(name + ": NetFloorArea " + std::to_string(space_area[name]) +
                         ", job.json area_m2 " + std::to_string(area));
    }
  }
  if (count["IfcSpace"] != static_cast<int>(rooms.size())) {
    problems.push_back(std::to_string(count["IfcSpace"]) + " IfcSpace, job.json has " +
                       std::to_string(rooms.size()) + " rooms");
  }
  std::cout << "IFC++ read " << model->getMapIfcEntities().size()
            << " entities: " << storey_z.size() << " storeys, " << count["IfcSpace"] << " spaces, "
            << count["IfcWall"] << " walls, " << count["IfcDoor"] << " doors\n";
  for (const std::string& p : problems) std::cerr << out << "/building.ifc: " << p << "\n";
  return problems.empty() ? 0 : 1;
}
