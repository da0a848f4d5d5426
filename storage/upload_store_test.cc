#include "storage/upload_store.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "storage/file_hash.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;

class UploadStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = (fs::path(::testing::TempDir()) /
            ("upload_store_" +
             std::string(::testing::UnitTest::GetInstance()->current_test_info()->name())))
               .string();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    std::mt19937 rng(7);
    bytes_.resize(100000);
    for (char& c : bytes_) c = static_cast<char>(rng());
  }
  UploadRequest Request(const std::string& name = "scan.h5") const {
    return {name, static_cast<int64_t>(bytes_.size()), Sha256Hex(bytes_)};
  }
  std::string ReadFile(const std::string& path) const {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  // Everything under the tenant's folder, relative, sorted.
  std::vector<std::string> Files() const {
    std::vector<std::string> out;
    for (const auto& e : fs::recursive_directory_iterator(dir_)) {
      if (e.is_regular_file()) out.push_back(fs::relative(e.path(), dir_).string());
    }
    std::sort(out.begin(), out.end());
    return out;
  }
  std::string dir_;
  std::string bytes_;
};

TEST_F(UploadStoreTest, WholeFileAppearsOnlyAtTheEnd) {
  UploadStore store({});
  absl::StatusOr<UploadState> s = store.Start(dir_, Request(), 1000);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->id, UploadId(Request()));
  EXPECT_EQ(s->input_path, "uploads/scan.h5");
  EXPECT_EQ(s->received_bytes, 0);
  absl::StatusOr<std::unique_ptr<UploadWriter>> w = store.OpenWriter(dir_, s->id);
  ASSERT_TRUE(w.ok()) << w.status();
  for (size_t at = 0; at < bytes_.size(); at += 30000) {
    ASSERT_FALSE(fs::exists(fs::path(dir_) / "uploads/scan.h5"));
    absl::StatusOr<UploadState> a =
        (*w)->Append(static_cast<int64_t>(at), absl::string_view(bytes_).substr(at, 30000));
    ASSERT_TRUE(a.ok()) << a.status();
  }
  EXPECT_FALSE(fs::exists(fs::path(dir_) / "uploads/scan.h5"));
  absl::StatusOr<UploadState> f = (*w)->Finish();
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_TRUE(f->complete);
  EXPECT_EQ(ReadFile(dir_ + "/uploads/scan.h5"), bytes_);
  EXPECT_EQ(Files(), (std::vector<std::string>{".uploads/" + s->id + ".json", "uploads/scan.h5"}));
  w->reset();
  // Starting the same file again finds it finished; Find too.
  absl::StatusOr<UploadState> again = store.Start(dir_, Request(), 2000);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE(again->complete);
  EXPECT_EQ(again->received_bytes, again->size_bytes);
  absl::StatusOr<UploadState> found = store.Find(dir_, s->id);
  ASSERT_TRUE(found.ok()) << found.status();
  EXPECT_TRUE(found->complete);
}

TEST_F(UploadStoreTest, ResumesWhereTheBytesStopAlsoAfterARestart) {
  std::string id;
  {
    UploadStore store({});
    absl::StatusOr<UploadState> s = store.Start(dir_, Request(), 1000);
    ASSERT_TRUE(s.ok()) << s.status();
    id = s->id;
    auto w = store.OpenWriter(dir_, id);
    ASSERT_TRUE(w.ok());
    ASSERT_TRUE((*w)->Append(0, absl::string_view(bytes_).substr(0, 41234)).ok());
  }
  UploadStore restarted({});
  absl::StatusOr<UploadState> s = restarted.Start(dir_, Request(), 5000);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->id, id);
  EXPECT_EQ(s->received_bytes, 41234);
  auto w = restarted.OpenWriter(dir_, id);
  ASSERT_TRUE(w.ok());
  // Not where the server stands: refused, saying where to resume.
  absl::StatusOr<UploadState> wrong = (*w)->Append(0, "x");
  EXPECT_TRUE(absl::IsFailedPrecondition(wrong.status())) << wrong.status();
  EXPECT_TRUE(absl::StrContains(wrong.status().message(), "resume from 41234"));
  EXPECT_TRUE(absl::IsFailedPrecondition((*w)->Finish().status()));
  ASSERT_TRUE((*w)->Append(41234, absl::string_view(bytes_).substr(41234)).ok());
  absl::StatusOr<UploadState> f = (*w)->Finish();
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(ReadFile(dir_ + "/uploads/scan.h5"), bytes_);
}

TEST_F(UploadStoreTest, WrongHashDropsTheBytesAndLeavesNothing) {
  UploadStore store({});
  UploadRequest r = Request();
  r.sha256_hex = Sha256Hex("something else");
  absl::StatusOr<UploadState> s = store.Start(dir_, r, 1000);
  ASSERT_TRUE(s.ok()) << s.status();
  auto w = store.OpenWriter(dir_, s->id);
  ASSERT_TRUE(w.ok());
  ASSERT_TRUE((*w)->Append(0, bytes_).ok());
  absl::StatusOr<UploadState> f = (*w)->Finish();
  EXPECT_TRUE(absl::IsDataLoss(f.status())) << f.status();
  EXPECT_TRUE(absl::StrContains(f.status().message(), "upload the file again"));
  EXPECT_TRUE(Files().empty());
  EXPECT_TRUE(absl::IsNotFound(store.Find(dir_, s->id).status()));
}

TEST_F(UploadStoreTest, PastTheAnnouncedSizeIsRefused) {
  UploadStore store({});
  UploadRequest r = Request();
  r.size_bytes = 10;
  absl::StatusOr<UploadState> s = store.Start(dir_, r, 1000);
  ASSERT_TRUE(s.ok());
  auto w = store.OpenWriter(dir_, s->id);
  ASSERT_TRUE(w.ok());
  EXPECT_TRUE(absl::IsInvalidArgument((*w)->Append(0, "01234567890").status()));
  EXPECT_EQ((*w)->state().received_bytes, 0);
}

TEST_F(UploadStoreTest, OneWriterAtATime) {
  UploadStore store({});
  absl::StatusOr<UploadState> s = store.Start(dir_, Request(), 1000);
  ASSERT_TRUE(s.ok());
  auto first = store.OpenWriter(dir_, s->id);
  ASSERT_TRUE(first.ok());
  EXPECT_TRUE(absl::IsAborted(store.OpenWriter(dir_, s->id).status()));
  first->reset();
  EXPECT_TRUE(store.OpenWriter(dir_, s->id).ok());
}

TEST_F(UploadStoreTest, BadRequestsAndNames) {
  UploadStore store({});
  for (const std::string& name :
       std::vector<std::string>{"", ".hidden", "a/b", "../x", std::string(129, 'a')}) {
    EXPECT_TRUE(absl::IsInvalidArgument(store.Start(dir_, Request(name), 1).status())) << name;
  }
  UploadRequest r = Request();
  r.size_bytes = 0;
  EXPECT_TRUE(absl::IsInvalidArgument(store.Start(dir_, r, 1).status()));
  r = Request();
  r.sha256_hex = "abc";
  EXPECT_TRUE(absl::IsInvalidArgument(store.Start(dir_, r, 1).status()));
  EXPECT_TRUE(absl::IsNotFound(store.Find(dir_, "u-0123").status()));
  EXPECT_TRUE(absl::IsNotFound(store.Find(dir_, "../../etc/passwd").status()));
  EXPECT_TRUE(absl::IsNotFound(store.OpenWriter(dir_, UploadId(Request())).status()));
}

TEST_F(UploadStoreTest, NameTakenByAFileOrAnotherUpload) {
  UploadStore store({});
  ASSERT_TRUE(store.Start(dir_, Request("a.h5"), 1000).ok());
  UploadRequest other = Request("a.h5");
  other.size_bytes = 5;
  absl::StatusOr<UploadState> s = store.Start(dir_, other, 1000);
  EXPECT_TRUE(absl::IsAlreadyExists(s.status())) << s.status();
  std::ofstream(dir_ + "/uploads/b.h5") << "mine";
  s = store.Start(dir_, Request("b.h5"), 1000);
  EXPECT_TRUE(absl::IsAlreadyExists(s.status())) << s.status();
}

TEST_F(UploadStoreTest, QuotaCountsFinishedAndAnnouncedBytes) {
  UploadStore store({.quota_bytes = 250000});
  ASSERT_TRUE(store.Start(dir_, Request("a.h5"), 1000).ok());
  std::ofstream(dir_ + "/uploads/old.h5") << std::string(60000, 'x');
  // 60 000 + 100 000 announced + 100 000 > 250 000.
  absl::StatusOr<UploadState> s = store.Start(dir_, Request("b.h5"), 1000);
  EXPECT_TRUE(absl::IsResourceExhausted(s.status())) << s.status();
  EXPECT_TRUE(absl::StrContains(s.status().message(), "quota of 250000"));
  fs::remove(dir_ + "/uploads/old.h5");
  EXPECT_TRUE(store.Start(dir_, Request("b.h5"), 1000).ok());
}

TEST_F(UploadStoreTest, StaleUnfinishedUploadsExpire) {
  UploadStore store({.expire_after_ms = 1000});
  absl::StatusOr<UploadState> stale = store.Start(dir_, Request("a.h5"), 0);
  ASSERT_TRUE(stale.ok());
  const int64_t now_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                             std::chrono::system_clock::now().time_since_epoch())
                             .count();
  // Within the second: kept. A minute later: removed when the next upload starts.
  ASSERT_TRUE(store.Start(dir_, Request("b.h5"), now_ms).ok());
  EXPECT_TRUE(store.Find(dir_, stale->id).ok());
  ASSERT_TRUE(store.Start(dir_, Request("c.h5"), now_ms + 60000).ok());
  EXPECT_TRUE(absl::IsNotFound(store.Find(dir_, stale->id).status()));
  EXPECT_FALSE(fs::exists(dir_ + "/.uploads/" + stale->id + ".partial"));
}

TEST_F(UploadStoreTest, ALinkInPlaceOfTheFoldersIsRefused) {
  const std::string elsewhere = dir_ + "_elsewhere";
  fs::create_directories(elsewhere);
  fs::create_directory_symlink(elsewhere, dir_ + "/uploads");
  UploadStore store({});
  absl::StatusOr<UploadState> s = store.Start(dir_, Request(), 1000);
  EXPECT_TRUE(absl::IsFailedPrecondition(s.status())) << s.status();
  EXPECT_TRUE(fs::is_empty(elsewhere));
}

TEST_F(UploadStoreTest, ACrashBetweenPlacingTheFileAndMarkingItIsRecognized) {
  UploadStore store({});
  absl::StatusOr<UploadState> s = store.Start(dir_, Request(), 1000);
  ASSERT_TRUE(s.ok());
  // What Finish leaves if the process dies after link(2) and before the record says complete.
  std::ofstream(dir_ + "/uploads/scan.h5", std::ios::binary) << bytes_;
  fs::remove(dir_ + "/.uploads/" + s->id + ".partial");
  absl::StatusOr<UploadState> found = store.Find(dir_, s->id);
  ASSERT_TRUE(found.ok()) << found.status();
  EXPECT_TRUE(found->complete);
}

}  // namespace
}  // namespace carvemap
