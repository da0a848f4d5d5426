#include "services/system/cgroup_files.h"

#include <fstream>
#include <sstream>

namespace carvemap {

std::optional<std::string> ReadSmallFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return std::nullopt;
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

std::vector<std::string> CgroupV2Files(const std::string& name) {
  // The process's group: the "0::/kubepods/..." line of /proc/self/cgroup.
  std::string group;
  {
    std::ifstream in("/proc/self/cgroup");
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("0::", 0) == 0) {
        group = line.substr(3);
        break;
      }
    }
  }
  std::vector<std::string> files;
  while (!group.empty()) {
    files.push_back("/sys/fs/cgroup" + (group == "/" ? std::string() : group) + "/" + name);
    if (group == "/") break;
    const size_t slash = group.rfind('/');
    group = slash == 0 ? "/" : group.substr(0, slash);
  }
  return files;
}

}  // namespace carvemap
