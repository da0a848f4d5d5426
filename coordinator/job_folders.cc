#include "coordinator/job_folders.h"

#include <algorithm>
#include <filesystem>
#include <utility>
#include <vector>

namespace carvemap {

namespace fs = std::filesystem;

CoordinatorFolders CoordinatorFolders::Of(std::string data_root, std::string output_root,
                                          std::string storage_root, std::string work_dir) {
  CoordinatorFolders f;
  f.data_root = std::move(data_root);
  f.output_root = std::move(output_root);
  f.storage_root = std::move(storage_root);
  f.work_dir =
      !work_dir.empty()
          ? std::move(work_dir)
          : (fs::path(f.storage_root.empty() ? f.output_root : f.storage_root) / ".carvemap")
                .string();
  return f;
}

std::string CoordinatorFolders::DataDir(const std::string& tenant_dir) const {
  return (fs::path(data_root) / tenant_dir).lexically_normal().string();
}

std::string CoordinatorFolders::OutputRoot(const std::string& tenant_dir) const {
  return (fs::path(output_root) / tenant_dir).lexically_normal().string();
}

std::string CoordinatorFolders::OutputDir(const JobRecord& job) const {
  return (fs::path(OutputRoot(job.tenant_dir)) / job.output_name).string();
}

std::string CoordinatorFolders::TilesDir(const JobRecord& job) const {
  if (storage_root.empty()) return (fs::path(OutputDir(job)) / "tiles").string();
  return (fs::path(storage_root) / job.id / "tiles").string();
}

std::string CoordinatorFolders::PartialsDir(const JobRecord& job) const {
  return (fs::path(work_dir) / job.id / "partials").string();
}

std::string ObjectTilesDir(const std::string& tiles_dir) {
  return (fs::path(tiles_dir).parent_path() / "object_tiles").string();
}

std::string TenantView(std::string text, const JobFolders& folders, const std::string& work_dir) {
  // Longest first: the tiles live inside the output folder unless a storage root moves them.
  std::vector<std::pair<std::string, std::string>> dirs = {
      {ObjectTilesDir(folders.tiles_dir), "object_tiles"},
      {folders.tiles_dir, "tiles"},
      {folders.partials_dir, "partials"},
      {folders.output_dir, "."},
      {fs::absolute(work_dir).lexically_normal().string(), "work"}};
  std::stable_sort(dirs.begin(), dirs.end(),
                   [](const auto& a, const auto& b) { return a.first.size() > b.first.size(); });
  for (const auto& [dir, name] : dirs) {
    if (dir.size() < 2 || dir.front() != '/') continue;  // absolute folders only
    for (size_t at = text.find(dir); at != std::string::npos; at = text.find(dir, at)) {
      const size_t end = at + dir.size();
      const bool whole = end == text.size() || text[end] == '/' || text[end] == '\'' ||
                         text[end] == ':' || text[end] == ' ' || text[end] == ',';
      if (!whole) {
        at = end;
        continue;
      }
      const bool slash = end < text.size() && text[end] == '/' && name == ".";
      text.replace(at, dir.size() + (slash ? 1 : 0), slash ? "" : name);
      at += slash ? 0 : name.size();
    }
  }
  return text;
}

}  // namespace carvemap
