#include "coordinator/job_folders.h"

#include <gtest/gtest.h>

namespace carvemap {
namespace {

JobRecord Job(std::string id, std::string tenant_dir, std::string output_name) {
  JobRecord j;
  j.id = std::move(id);
  j.tenant_dir = std::move(tenant_dir);
  j.output_name = std::move(output_name);
  return j;
}

TEST(JobFoldersTest, TenantsGetTheirOwnFolders) {
  const CoordinatorFolders f = CoordinatorFolders::Of("/data", "/out", "", "");
  EXPECT_EQ(f.work_dir, "/out/.carvemap");
  EXPECT_EQ(f.DataDir("acme"), "/data/acme");
  EXPECT_EQ(f.DataDir(""), "/data/");  // shared folders: the root itself
  EXPECT_EQ(f.OutputRoot("acme"), "/out/acme");
  const JobRecord job = Job("j-1", "acme", "office");
  EXPECT_EQ(f.OutputDir(job), "/out/acme/office");
  EXPECT_EQ(f.TilesDir(job), "/out/acme/office/tiles");
  EXPECT_EQ(f.PartialsDir(job), "/out/.carvemap/j-1/partials");
  EXPECT_EQ(ObjectTilesDir(f.TilesDir(job)), "/out/acme/office/object_tiles");
}

TEST(JobFoldersTest, AStorageRootHoldsTheTilesAndTheWork) {
  const CoordinatorFolders f = CoordinatorFolders::Of("/data", "/out", "/fast", "");
  EXPECT_EQ(f.work_dir, "/fast/.carvemap");
  const JobRecord job = Job("j-2", "", "office");
  EXPECT_EQ(f.OutputDir(job), "/out/office");
  EXPECT_EQ(f.TilesDir(job), "/fast/j-2/tiles");
  EXPECT_EQ(ObjectTilesDir(f.TilesDir(job)), "/fast/j-2/object_tiles");
  // A work folder given explicitly wins.
  EXPECT_EQ(CoordinatorFolders::Of("/d", "/o", "/s", "/w").PartialsDir(job), "/w/j-2/partials");
}

TEST(JobFoldersTest, TenantViewNamesTheJobsFoldersAsFetchArtifactDoes) {
  const JobFolders f{"/out/acme/office", "/out/acme/office/tiles", "/work/j-1/partials"};
  EXPECT_EQ(TenantView("/out/acme/office/tiles/0_0_0.h5: truncated", f, "/work"),
            "tiles/0_0_0.h5: truncated");
  EXPECT_EQ(TenantView("cannot write /out/acme/office/mesh/dense.ply", f, "/work"),
            "cannot write mesh/dense.ply");
  EXPECT_EQ(TenantView("'/out/acme/office/object_tiles/1_2_3.h5': bad", f, "/work"),
            "'object_tiles/1_2_3.h5': bad");
  EXPECT_EQ(TenantView("/work/j-1/partials/slice_3.part, /work/jobs.db", f, "/work"),
            "partials/slice_3.part, work/jobs.db");
  // The output folder alone is ".".
  EXPECT_EQ(TenantView("no space in /out/acme/office", f, "/work"), "no space in .");
}

TEST(JobFoldersTest, TenantViewReplacesWholeComponentsOnly) {
  const JobFolders f{"/out/acme/office", "/out/acme/office/tiles", "/work/j-1/partials"};
  // "/out/acme/office2" is another job's folder: not this one's, left alone.
  EXPECT_EQ(TenantView("see /out/acme/office2/x", f, "/work"), "see /out/acme/office2/x");
  EXPECT_EQ(TenantView("/out/acme/office/tilesX", f, "/work"), "tilesX");
  // Text without any folder is unchanged.
  EXPECT_EQ(TenantView("HDF5: bad magic", f, "/work"), "HDF5: bad magic");
  // Relative folders are never replaced (a relative name is not the server's layout).
  EXPECT_EQ(TenantView("office/tiles/a", JobFolders{"office", "office/tiles", "p"}, "w"),
            "office/tiles/a");
}

}  // namespace
}  // namespace carvemap
