// ROS 2 bags, in either of rosbag2's storages, read into the same messages as ROS 1 bags
// (rosbag_reader.h), with their connections' encoding saying how to decode them:
//   - sqlite3 (.db3): tables topics (id, name, type, serialization_format) and messages
//     (topic_id, timestamp in ns, data), read in timestamp order;
//   - MCAP (.mcap, mcap.dev's specification): "\x89MCAP0\r\n", then records (opcode u8, length
//     u64, content): schemas (the type's name), channels (topic, message encoding), messages
//     (channel, log time in ns, data) and chunks of those (uncompressed, zstd or lz4, with
//     their size and CRC-32 checked), up to the data end record (whose CRC-32 of the data
//     section is checked when the writer set it); the summary section is not needed.
// A bag directory (metadata.yaml beside its files, as `ros2 bag record` leaves it) is its
// files in the order metadata.yaml's relative_file_paths lists them.
//
// Our own reader: MCAP's C++ library is not packaged by Debian, and rosbag2 is the C++ half of
// ROS 2. Tests read bags written by the MCAP project's own writer (@mcap/core) and Python's
// sqlite3, with messages serialized by @foxglove/cdr (tests/data/ros2/).
#pragma once

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "storage/import/rosbag_reader.h"

namespace carvemap {

// Whether `path` is a ROS 2 bag: a directory with metadata.yaml, or a file that starts as an
// MCAP or an SQLite file does.
bool IsRos2Bag(const std::string& path);

// As ReadBag: every message of `path` to `fn` in time order (file order for MCAP); errors name
// the file and the record (MCAP: the byte offset; sqlite3: SQLite's own message).
// `receive_time` is the message's log time.
absl::Status ReadRos2Bag(const std::string& path, const BagMessageFn& fn,
                         std::vector<BagConnection>* connections = nullptr);

}  // namespace carvemap
