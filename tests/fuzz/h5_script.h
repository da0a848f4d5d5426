// HDF5 files from byte scripts, for the structure-aware fuzz targets (scan_reader, tile_reader).
//
// Why: mutating an HDF5 file's bytes mostly breaks HDF5's own metadata (B-trees, heaps, object
// headers), and Debian's libhdf5 1.10.8 crashes on much of that inside its own code (README.md
// beside this file). Our readers are meant to survive any file HDF5 can open, so these targets
// feed them files that HDF5 itself wrote, from a script of operations that libFuzzer mutates:
// groups, links, attributes and datasets of any name, type, shape, layout and raw content.
//
// Script (all integers little-endian; a script ending early reads as zeros):
//   u8 flags                          bit 0: latest file format, bit 1: track link order
//   then ops until the end:
//   u8 op % 5:
//     0 group     str path
//     1 attribute str object, str name, type, space, data
//     2 dataset   str path, type, space, u8 layout, [u32 chunk rows], u32 rows to write, data
//     3 soft link str path, str target
//     4 hard link str path, str target
//   str   = u8 length, bytes
//   space = u8 rank % 3 (0 = scalar), u32 dims[rank]
//   type  = u8 code: 0 f32le 1 f64le 2 f32be 3 f64be 4 i8 5 u8 6 i16le 7 u16le 8 i32le 9 u32le
//           10 i64le 11 u64le 12 i64be | 13 fixed string: u8 size, u8 pad | 14 variable string
//           | 15 compound: u8 members (≤ 16), each str name, u8 scalar code (0–12); u8 padding
//   layout = u8 % 4: 0 contiguous, 1 chunked, 2 chunked + shuffle + deflate, 3 compact;
//            chunked datasets grow along rows (unlimited) and store only the rows written, so
//            a dataset may declare 2^32 rows on a few bytes of file
//   data  = the elements' raw bytes in the file's type (variable strings: one str each); for a
//           dataset only its first `rows to write` rows. To keep an execution in milliseconds,
//           data is capped at 64 KiB, chunks at 64 rows and 64 KiB, 16 chunks are written at
//           most, and a contiguous dataset over 64 KiB is declared but not written.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "absl/status/statusor.h"

namespace carvemap::fuzz {

// Builds the file at `path` (replacing it) from `script`. Operations HDF5 refuses (a bad name,
// a duplicate, a type of size 0, ...) are skipped: the result is always a file HDF5 wrote.
void BuildH5FromScript(std::span<const uint8_t> script, const std::string& path);

// The script that rebuilds the file at `path`: its groups, attributes and datasets with their
// types, shapes, layouts and raw bytes (links are followed as objects). For making seeds from
// files our writers wrote.
absl::StatusOr<std::string> ScriptFromH5(const std::string& path);

}  // namespace carvemap::fuzz
