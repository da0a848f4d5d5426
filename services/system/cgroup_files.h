// The files of the cgroups that bind this process, shared by usable_cpus and process_memory.
#ifndef CARVEMAP_SERVICES_SYSTEM_CGROUP_FILES_H_
#define CARVEMAP_SERVICES_SYSTEM_CGROUP_FILES_H_

#include <optional>
#include <string>
#include <vector>

namespace carvemap {

// The whole of a small file (a /proc or /sys entry), nullopt when it cannot be read.
std::optional<std::string> ReadSmallFile(const std::string& path);

// "/sys/fs/cgroup<group>/<name>" for the process's cgroup v2 group and each of its parents up
// to the root (a limit anywhere above the process's group binds it too); empty without v2.
std::vector<std::string> CgroupV2Files(const std::string& name);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_SYSTEM_CGROUP_FILES_H_
