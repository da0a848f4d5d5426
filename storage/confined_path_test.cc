#include "storage/confined_path.h"

#include <fcntl.h>
#include <linux/openat2.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace carvemap {
namespace {
namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

// data/acme is the root; data/beta a sibling tenant; outside/ lies beyond the data root.
class ConfinedPathTest : public ::testing::Test {
 protected:
  void SetUp() override {
    base_ = fs::path(::testing::TempDir()) /
            ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(base_);
    root_ = base_ / "data" / "acme";
    fs::create_directories(root_ / "scans" / "deep");
    fs::create_directories(base_ / "data" / "beta");
    fs::create_directories(base_ / "outside" / "dir");
    Write(root_ / "scans" / "a.h5", "acme scan");
    Write(root_ / "scans" / "deep" / "b.h5", "deep scan");
    Write(base_ / "data" / "beta" / "scan.h5", "beta scan");
    Write(base_ / "outside" / "secret.h5", "outside secret");
    Write(base_ / "outside" / "dir" / "x.h5", "outside dir file");
  }
  static void Write(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }
  void Link(const std::string& target, const std::string& name) {
    fs::create_symlink(target, root_ / name);
  }
  absl::StatusOr<std::string> Resolve(const std::string& rel) {
    return ResolveConfinedPath(root_.string(), rel, "input_path");
  }
  std::string Canonical(const fs::path& p) { return fs::canonical(p).string(); }

  fs::path base_;
  fs::path root_;
};

TEST_F(ConfinedPathTest, TextChecksNeedNoDisk) {
  const std::vector<std::string> bads = {"",         "/etc/passwd",          "../beta/scan.h5",
                                         "scans/../a.h5", "scans/..",       std::string("a\0b", 3),
                                         std::string(kMaxConfinedPathBytes + 1, 'a')};
  for (const std::string& bad : bads) {
    absl::StatusOr<std::string> r =
        ResolveConfinedPath("/nonexistent-root", bad, "input_path");
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << bad;
  }
  EXPECT_TRUE(CheckConfinedPathText("scans/./a.h5", "x").ok());
  EXPECT_TRUE(CheckConfinedPathText("a..b/c..", "x").ok());  // ".." only as a whole component
}

TEST_F(ConfinedPathTest, PlainPathsAndLinksInsideResolve) {
  ASSERT_TRUE(Resolve("scans/a.h5").ok());
  EXPECT_EQ(*Resolve("scans/a.h5"), Canonical(root_ / "scans" / "a.h5"));
  EXPECT_EQ(*Resolve("scans//deep/./b.h5"), Canonical(root_ / "scans" / "deep" / "b.h5"));
  Link("scans/a.h5", "rel_link.h5");
  Link(Canonical(root_) + "/scans/deep", "abs_dir_link");
  Link("../a.h5", "scans/deep/up.h5");  // ".." in a link that stays inside
  EXPECT_EQ(*Resolve("rel_link.h5"), Canonical(root_ / "scans" / "a.h5"));
  EXPECT_EQ(*Resolve("abs_dir_link/b.h5"), Canonical(root_ / "scans" / "deep" / "b.h5"));
  EXPECT_EQ(*Resolve("scans/deep/up.h5"), Canonical(root_ / "scans" / "a.h5"));
  // The root may itself be reached through a symlink (the administrator's choice).
  fs::create_symlink(root_, base_ / "root_link");
  absl::StatusOr<std::string> via = ResolveConfinedPath((base_ / "root_link").string(),
                                                        "scans/a.h5", "input_path");
  ASSERT_TRUE(via.ok()) << via.status();
  EXPECT_EQ(*via, Canonical(root_ / "scans" / "a.h5"));
}

TEST_F(ConfinedPathTest, MissingInsideIsNotFound) {
  EXPECT_EQ(Resolve("scans/none.h5").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(Resolve("scans/a.h5/x").status().code(), absl::StatusCode::kNotFound);
  Link("scans/none.h5", "dangling.h5");
  EXPECT_EQ(Resolve("dangling.h5").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(ResolveConfinedPath((base_ / "data" / "gamma").string(), "a.h5", "input_path")
                .status()
                .code(),
            absl::StatusCode::kNotFound);
}

// Every way out: the same code and the same message whether the target exists or not, and
// no message names anything outside or the root itself.
TEST_F(ConfinedPathTest, EscapesAreRefusedAlikeWhetherTheTargetExistsOrNot) {
  const std::string outside = (base_ / "outside").string();
  Link(outside + "/secret.h5", "abs_exists.h5");
  Link(outside + "/missing.h5", "abs_missing.h5");
  Link("../../outside/secret.h5", "rel_exists.h5");
  Link("../../outside/missing.h5", "rel_missing.h5");
  Link("../beta/scan.h5", "sibling.h5");         // another tenant's file
  Link(outside + "/dir", "dir_out");             // a directory leading out
  Link("../../../../../../../../../../..", "up_to_slash");
  Link("deep/../../../beta", "scans/through_deep");  // climbs out after a real directory
  const std::vector<std::string> escapes = {
      "abs_exists.h5", "abs_missing.h5", "rel_exists.h5", "rel_missing.h5", "sibling.h5",
      "dir_out/x.h5",  "dir_out/missing.h5", "up_to_slash/etc/passwd",
      "scans/through_deep/scan.h5"};
  for (const std::string& rel : escapes) {
    absl::StatusOr<std::string> r = Resolve(rel);
    ASSERT_EQ(r.status().code(), absl::StatusCode::kPermissionDenied) << rel << " " << r.status();
    const std::string msg(r.status().message());
    EXPECT_EQ(msg, "input_path '" + rel +
                       "': a symlink on the way leads outside the allowed directory");
    EXPECT_THAT(msg, Not(HasSubstr("outside/")));
    EXPECT_THAT(msg, Not(HasSubstr(base_.string())));
    EXPECT_THAT(msg, Not(HasSubstr("beta")));
  }
  // ConfinedFile says the same.
  for (const std::string& rel : escapes) {
    EXPECT_EQ(ConfinedFile::Open(root_.string(), rel, "input_path").status().code(),
              absl::StatusCode::kPermissionDenied)
        << rel;
  }
}

TEST_F(ConfinedPathTest, SymlinkLoopsEnd) {
  Link("loop_b", "loop_a");
  Link("loop_a", "loop_b");
  EXPECT_EQ(Resolve("loop_a").status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(ConfinedPathTest, ConfinedFileReadsTheCheckedFileEvenAfterASwap) {
  absl::StatusOr<ConfinedFile> f = ConfinedFile::Open(root_.string(), "scans/a.h5", "input_path");
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(f->size_bytes(), 9);
  EXPECT_THAT(f->path(), ::testing::StartsWith("/proc/self/fd/"));
  // Errors of code that opened path() read as the client's name.
  absl::Status renamed = f->Rename(absl::DataLossError("ingest: " + f->path() + ": bad"));
  EXPECT_EQ(renamed.message(), "ingest: scans/a.h5: bad");
  EXPECT_EQ(renamed.code(), absl::StatusCode::kDataLoss);
  // Swap the checked file for a link to a file outside: path() still reads the checked one.
  fs::remove(root_ / "scans" / "a.h5");
  fs::create_symlink(base_ / "outside" / "secret.h5", root_ / "scans" / "a.h5");
  std::ifstream in(f->path());
  std::string text;
  std::getline(in, text);
  EXPECT_EQ(text, "acme scan");
  // And now the name itself is refused.
  EXPECT_EQ(ConfinedFile::Open(root_.string(), "scans/a.h5", "input_path").status().code(),
            absl::StatusCode::kPermissionDenied);
}

bool KernelHasOpenat2() {
  open_how how{};
  how.flags = O_RDONLY | O_DIRECTORY | O_CLOEXEC;
  const int fd = int(::syscall(SYS_openat2, AT_FDCWD, ".", &how, sizeof(how)));
  if (fd >= 0) ::close(fd);
  return fd >= 0;
}

// A folder on the resolved path swapped for a link leading outside after the path was
// resolved and before it is opened: refused by the kernel during the open (openat2 beneath
// the root), and, on a kernel without openat2, by the check of the opened file's name after.
TEST_F(ConfinedPathTest, ALinkSwappedBetweenResolutionAndOpenIsRefused) {
  fs::create_directories(base_ / "outside" / "scans_copy");
  Write(base_ / "outside" / "scans_copy" / "a.h5", "outside copy");
  ConfinedOpenTestHooks& hooks = ConfinedOpenHooksForTest();
  const auto swap = [&] {
    fs::rename(root_ / "scans", root_ / "scans_moved");
    fs::create_symlink(base_ / "outside" / "scans_copy", root_ / "scans");
  };
  const auto restore = [&] {
    fs::remove(root_ / "scans");
    fs::rename(root_ / "scans_moved", root_ / "scans");
  };
  for (const bool openat2 : {true, false}) {
    SCOPED_TRACE(openat2 ? "openat2" : "open and the name check");
    ASSERT_TRUE(ConfinedFile::Open(root_.string(), "scans/a.h5", "input_path").ok());
    hooks.no_openat2 = !openat2;
    hooks.between = swap;
    hooks.beneath_refusals = 0;
    absl::StatusOr<ConfinedFile> f =
        ConfinedFile::Open(root_.string(), "scans/a.h5", "input_path");
    const int refusals = hooks.beneath_refusals;
    hooks.no_openat2 = false;
    hooks.between = nullptr;
    restore();
    ASSERT_FALSE(f.ok()) << "opened " << f->path();
    EXPECT_EQ(f.status().code(), absl::StatusCode::kPermissionDenied) << f.status();
    EXPECT_THAT(f.status().message(), Not(HasSubstr("scans_copy")));  // no target named
    // Which check refused it: the kernel's, where it has openat2 (Linux ≥ 5.6).
    EXPECT_EQ(refusals, openat2 && KernelHasOpenat2() ? 1 : 0);
  }
}

TEST_F(ConfinedPathTest, AFileRemovedWhileReadIsNotFoundWhateverTheReaderSaid) {
  absl::StatusOr<ConfinedFile> f = ConfinedFile::Open(root_.string(), "scans/a.h5", "input_path");
  ASSERT_TRUE(f.ok()) << f.status();
  fs::remove(root_ / "scans" / "a.h5");
  // HDF5 reopening path() of a removed file reports a corrupt file; the cause is the removal.
  absl::Status renamed =
      f->Rename(absl::DataLossError(f->path() + ": truncated or corrupt HDF5 file"));
  EXPECT_EQ(renamed.code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(renamed.message(),
            "input_path 'scans/a.h5': no such file (removed while it was read: scans/a.h5: "
            "truncated or corrupt HDF5 file)");
}

TEST_F(ConfinedPathTest, DirectoriesAndFifosAreNotFiles) {
  absl::StatusOr<ConfinedFile> dir = ConfinedFile::Open(root_.string(), "scans", "input_path");
  EXPECT_EQ(dir.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(dir.status().message(), HasSubstr("not a regular file"));
  ASSERT_EQ(::mkfifo((root_ / "fifo").c_str(), 0600), 0);
  // O_NONBLOCK: no writer on the FIFO, and the open still returns at once.
  EXPECT_EQ(ConfinedFile::Open(root_.string(), "fifo", "input_path").status().code(),
            absl::StatusCode::kNotFound);
}

TEST_F(ConfinedPathTest, MovedFileKeepsItsDescriptor) {
  absl::StatusOr<ConfinedFile> f = ConfinedFile::Open(root_.string(), "scans/a.h5", "input_path");
  ASSERT_TRUE(f.ok());
  ConfinedFile moved = *std::move(f);
  EXPECT_GE(moved.fd(), 0);
  EXPECT_TRUE(fs::exists(moved.path()));
}

}  // namespace
}  // namespace carvemap
