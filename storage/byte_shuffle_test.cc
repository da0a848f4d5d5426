#include "storage/byte_shuffle.h"

#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

// Three 4-byte elements into planes of 5 (HDF5's layout of a partial last chunk: the plane is
// the chunk's length, the tail its fill).
TEST(ByteShuffle, PlanesOfEqualRankAndBack) {
  const std::vector<unsigned char> in = {0x10, 0x11, 0x12, 0x13, 0x20, 0x21,
                                         0x22, 0x23, 0x30, 0x31, 0x32, 0x33};
  std::vector<unsigned char> planes(4 * 5, 0xee);
  ShuffleBytes(in.data(), 3, 4, 5, planes.data());
  const std::vector<unsigned char> want = {0x10, 0x20, 0x30, 0xee, 0xee, 0x11, 0x21,
                                           0x31, 0xee, 0xee, 0x12, 0x22, 0x32, 0xee,
                                           0xee, 0x13, 0x23, 0x33, 0xee, 0xee};
  EXPECT_EQ(planes, want);
  std::vector<unsigned char> back(in.size(), 0);
  UnshuffleBytes(planes.data(), 3, 4, 5, back.data());
  EXPECT_EQ(back, in);
}

}  // namespace
}  // namespace carvemap
