#include "storage/atomic_file.h"

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

TEST(AtomicFileTest, WritesThenRenames) {
  const std::string path = testing::TempDir() + "/atomic.txt";
  ASSERT_TRUE(WriteFileAtomically(path, [](std::ostream& out) { out << "hello"; }).ok());
  EXPECT_FALSE(std::filesystem::exists(PartialPath(path)));
  std::ifstream in(path);
  std::string text;
  in >> text;
  EXPECT_EQ(text, "hello");
}

TEST(AtomicFileTest, FailedWriteLeavesNothing) {
  const std::string path = testing::TempDir() + "/failed.txt";
  std::filesystem::remove(path);
  absl::Status s = WriteFileAtomically(path, [](std::ostream& out) {
    out << "partial";
    out.setstate(std::ios::badbit);  // what a full disk looks like to the stream
  });
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(std::string(s.message()).find(path), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_FALSE(std::filesystem::exists(PartialPath(path)));
}

TEST(AtomicFileTest, UnwritableDirectoryNamesThePath) {
  absl::Status s = WriteFileAtomically("/nonexistent-dir/x", [](std::ostream&) {});
  EXPECT_FALSE(s.ok());
  EXPECT_NE(std::string(s.message()).find("/nonexistent-dir/x"), std::string::npos);
}

TEST(AtomicFileTest, RenameDurablyMovesTheFileAndNamesPathsOnFailure) {
  const std::string dir = testing::TempDir() + "/durable";
  std::filesystem::create_directories(dir);
  const std::string from = dir + "/a.tmp", to = dir + "/a.txt";
  std::ofstream(from) << "data";
  ASSERT_TRUE(RenameDurably(from, to).ok());
  EXPECT_FALSE(std::filesystem::exists(from));
  EXPECT_EQ(std::filesystem::file_size(to), 4u);
  // A source that is not there: nothing renamed, the error names it.
  absl::Status s = RenameDurably(dir + "/missing.tmp", dir + "/b.txt");
  EXPECT_FALSE(s.ok());
  EXPECT_NE(std::string(s.message()).find(dir + "/missing.tmp"), std::string::npos) << s;
  EXPECT_FALSE(std::filesystem::exists(dir + "/b.txt"));
  s = SyncPath(dir + "/nothing-here");
  EXPECT_NE(std::string(s.message()).find(dir + "/nothing-here"), std::string::npos) << s;
  EXPECT_TRUE(SyncPath(dir).ok());  // a folder syncs too
  EXPECT_TRUE(SyncFolderOf(to).ok());
}

}  // namespace
}  // namespace carvemap
