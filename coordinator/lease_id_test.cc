#include "coordinator/lease_id.h"

#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

TEST(LeaseIdTest, RoundTrip) {
  const LeaseId id{"j-20261128-abcdef", {1, -2, 3}, 4};
  EXPECT_EQ(id.ToString(), "j-20261128-abcdef/1,-2,3/4");
  absl::StatusOr<LeaseId> back = LeaseId::Parse(id.ToString());
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, id);
}

TEST(LeaseIdTest, JobIdWithSlashes) {
  absl::StatusOr<LeaseId> id = LeaseId::Parse("a/b/c/7,8,9/12");
  ASSERT_TRUE(id.ok()) << id.status();
  EXPECT_EQ(id->job_id, "a/b/c");
  EXPECT_EQ(id->chunk, (ChunkCoord{7, 8, 9}));
  EXPECT_EQ(id->generation, 12);
  EXPECT_EQ(id->ToString(), "a/b/c/7,8,9/12");
}

TEST(LeaseIdTest, SliceTaskKeys) {
  // Slice tasks use x = kSliceTaskX, far outside any chunk's range.
  const LeaseId id{"j", SliceTaskKey(5, 1), 2};
  absl::StatusOr<LeaseId> back = LeaseId::Parse(id.ToString());
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->chunk, SliceTaskKey(5, 1));
}

TEST(LeaseIdTest, MalformedIsInvalidArgumentQuotingTheText) {
  for (const char* text :
       {"", "garbage", "j/1,2,3", "/1,2,3/4", "j//4", "j/1,2/4", "j/1,2,3,4/4", "j/1,x,3/4",
        "j/1,2,3/", "j/1,2,3/0", "j/1,2,3/-1", "j/1,2,3/4x", "j/1,2,99999999999/4"}) {
    absl::StatusOr<LeaseId> id = LeaseId::Parse(text);
    ASSERT_FALSE(id.ok()) << text;
    EXPECT_EQ(id.status().code(), absl::StatusCode::kInvalidArgument) << text;
    EXPECT_NE(id.status().message().find(absl::StrCat("\"", text, "\"")), std::string::npos)
        << id.status();
  }
}

}  // namespace
}  // namespace carvemap
