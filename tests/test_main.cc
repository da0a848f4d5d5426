// gtest main for every carvemap test binary. ctest runs each discovered test case as its own
// process, in parallel, so cases of one binary must not share scratch paths: each process gets
// a private TEST_TMPDIR (which ::testing::TempDir() returns), removed at exit unless
// CARVEMAP_KEEP_TEST_TMPDIR is set.
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>

#include <gtest/gtest.h>

int main(int argc, char** argv) {
  const char* parent = std::getenv("TMPDIR");
  std::string pattern = std::string(parent && *parent ? parent : "/tmp") + "/carvemap-test-XXXXXX";
  char* dir = mkdtemp(pattern.data());
  if (dir == nullptr) {
    std::cerr << "cannot create a scratch directory under " << pattern << "\n";
    return 1;
  }
  setenv("TEST_TMPDIR", dir, /*overwrite=*/1);
  ::testing::InitGoogleTest(&argc, argv);
  const int result = RUN_ALL_TESTS();
  if (std::getenv("CARVEMAP_KEEP_TEST_TMPDIR") == nullptr) {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  } else {
    std::cerr << "test scratch kept in " << dir << "\n";
  }
  return result;
}
