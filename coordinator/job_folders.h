// Where the coordinator keeps what (docs/DESIGN.md §8): a tenant's inputs and outputs under the
// data and output roots (in its own folder unless the folders are shared), a job's tiles in its
// output folder or under a separate storage root, its partial sums and the job store in the
// work folder; and the text of a job's error as its tenant may read it. Plain paths, no I/O.
#pragma once

#include <string>

#include "storage/job_store.h"  // JobRecord

namespace carvemap {

struct CoordinatorFolders {
  std::string data_root, output_root;
  std::string storage_root;  // "" = the tiles live in each job's output folder
  std::string work_dir;

  // `work_dir` "" = "<storage root, else output root>/.carvemap".
  static CoordinatorFolders Of(std::string data_root, std::string output_root,
                               std::string storage_root, std::string work_dir);

  // A tenant's folders ("" = the roots themselves).
  [[nodiscard]] std::string DataDir(const std::string& tenant_dir) const;
  [[nodiscard]] std::string OutputRoot(const std::string& tenant_dir) const;
  // A job's.
  [[nodiscard]] std::string OutputDir(const JobRecord& job) const;
  [[nodiscard]] std::string TilesDir(const JobRecord& job) const;
  [[nodiscard]] std::string PartialsDir(const JobRecord& job) const;
};

// §5.6.1's re-carved tiles: beside the job's tiles.
[[nodiscard]] std::string ObjectTilesDir(const std::string& tiles_dir);

// A job's folders as absolute, normal paths (what the workers and the merge are given).
struct JobFolders {
  std::string output_dir, tiles_dir, partials_dir;
};

// Job.error is the tenant's to read: the server's absolute folders in `text` (a worker's HDF5
// error, the merge's) become the names FetchArtifact uses, relative to the job's output
// folder ("tiles", "object_tiles", "partials", "work", and the output folder itself dropped),
// so the server's layout does not leak. A folder is replaced only where it is a whole path
// component (followed by '/', a quote, ':', ' ', ',' or the end), longest folder first.
[[nodiscard]] std::string TenantView(std::string text, const JobFolders& folders,
                                     const std::string& work_dir);

}  // namespace carvemap
