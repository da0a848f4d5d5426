#include "storage/tile_store.h"

#include <hdf5.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <string_view>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "storage/atomic_file.h"
#include "storage/byte_shuffle.h"
#include "storage/h5_util.h"
#include "storage/hdf5_lock.h"

namespace carvemap {
namespace {

using h5::Hid;

// Rows per HDF5 chunk of each column: 16384 rows = 64–128 KiB uncompressed, large enough for
// deflate to work well and small enough that a reader of a tiny tile decompresses little.
constexpr hsize_t kChunkRows = 16384;
constexpr int kDeflateLevel = 4;
constexpr char kLeavesGroup[] = "leaves";

// Debian's libhdf5 is not thread-safe (see header): tile I/O from several worker threads goes
// through the process's one HDF5 lock.
std::mutex& TileMutex() { return Hdf5Lock(); }

// The first finest-depth cell of a node, as a Morton code at chunk_depth: the sort key that
// puts non-overlapping leaves of mixed depths in Z-curve order.
uint64_t FinestStart(int chunk_depth, uint64_t code, int depth) {
  return code << (3 * (chunk_depth - depth));
}
uint64_t FinestSpan(int chunk_depth, int depth) { return uint64_t{1} << (3 * (chunk_depth - depth)); }

// Columns as plain arrays, the in-memory twin of /leaves (TILE_FORMAT.md).
struct Columns {
  std::vector<uint64_t> key;
  std::vector<uint8_t> depth;
  std::vector<float> p;
  std::vector<double> weight;  // sum_w
  std::vector<float> variance;
  std::vector<uint32_t> count;
  std::vector<double> sum_wp;
  std::vector<double> sum_wp2;
  std::vector<uint32_t> points;  // version 2 (zeros when reading version 1)
};

struct ColumnSpec {
  const char* name;
  hid_t file_type;
  hid_t mem_type;
  bool integer;
};
// File types are fixed little-endian so the bytes do not depend on the host.
// Version 1 tiles have the first 8 columns only.
std::array<ColumnSpec, 9> ColumnSpecs() {
  return {{
      {"key", H5T_STD_U64LE, H5T_NATIVE_UINT64, true},
      {"depth", H5T_STD_U8LE, H5T_NATIVE_UINT8, true},
      {"p", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, false},
      {"weight", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, false},
      {"variance", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, false},
      {"count", H5T_STD_U32LE, H5T_NATIVE_UINT32, true},
      {"sum_wp", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, false},
      {"sum_wp2", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, false},
      {"points", H5T_STD_U32LE, H5T_NATIVE_UINT32, true},
  }};
}
// Each column's name and element size, usable without HDF5 (ColumnSpecs' types need its lock).
struct ColumnLayout {
  const char* name;
  size_t element_bytes;
};
constexpr std::array<ColumnLayout, 9> kColumnLayouts = {{{"key", 8},
                                                         {"depth", 1},
                                                         {"p", 4},
                                                         {"weight", 8},
                                                         {"variance", 4},
                                                         {"count", 4},
                                                         {"sum_wp", 8},
                                                         {"sum_wp2", 8},
                                                         {"points", 4}}};
// The stored chunks are copied to and from the columns as bytes: the file's little-endian
// types must be the host's.
static_assert(std::endian::native == std::endian::little);

std::array<void*, 9> ColumnData(Columns& c) {
  return {c.key.data(),      c.depth.data(), c.p.data(),      c.weight.data(),
          c.variance.data(), c.count.data(), c.sum_wp.data(), c.sum_wp2.data(),
          c.points.data()};
}
void ResizeColumns(Columns& c, size_t n) {
  c.key.resize(n);
  c.depth.resize(n);
  c.p.resize(n);
  c.weight.resize(n);
  c.variance.resize(n);
  c.count.resize(n);
  c.sum_wp.resize(n);
  c.sum_wp2.resize(n);
  c.points.resize(n);
}

bool ValidGrid(const OctreeGrid& grid) {
  return grid.chunk_depth >= kMinChunkDepth && grid.chunk_depth <= kMaxChunkDepth;
}

// ---- HDF5's shuffle and deflate filters, outside the HDF5 lock ------------------------------
// The same filters as HDF5's own (H5Zshuffle.c: byte j of element i goes to j·n + i, for
// elements wider than a byte in chunks of more than one; H5Zdeflate.c: zlib's compress2 at the
// dataset's level, in the zlib format), applied to each stored chunk on the caller's thread;
// the file takes and gives the chunks as stored (H5Dwrite_chunk, H5Dread_chunk). The files are
// those HDF5's filters write, and read either way (tile_store_test).

bool Shuffles(size_t chunk_rows, size_t element_bytes) {
  return element_bytes > 1 && chunk_rows > 1;
}

// One stored chunk of a column: `rows` elements at `data`, padded with zeros (the dataset's
// fill) to `chunk_rows`.
absl::StatusOr<std::string> ShuffleDeflate(const unsigned char* data, size_t rows,
                                           size_t chunk_rows, size_t element_bytes) {
  const size_t bytes = chunk_rows * element_bytes;
  std::vector<unsigned char> plain(bytes, 0);
  if (Shuffles(chunk_rows, element_bytes)) {
    ShuffleBytes(data, rows, element_bytes, chunk_rows, plain.data());
  } else {
    std::memcpy(plain.data(), data, rows * element_bytes);
  }
  uLongf stored_bytes = compressBound(bytes);
  std::string stored(stored_bytes, '\0');
  const int rc = compress2(reinterpret_cast<Bytef*>(stored.data()), &stored_bytes, plain.data(),
                           bytes, kDeflateLevel);
  if (rc != Z_OK) return absl::InternalError(absl::StrCat("zlib compress2 failed (", rc, ")"));
  stored.resize(stored_bytes);
  return stored;
}

// The first `rows` elements of a stored chunk into `out`. `mask` is the chunk's filter mask
// (bit 0: not shuffled, bit 1: not deflated).
absl::Status InflateUnshuffle(std::string_view stored, uint32_t mask, size_t chunk_rows,
                              size_t element_bytes, size_t rows, unsigned char* out) {
  const size_t bytes = chunk_rows * element_bytes;
  std::vector<unsigned char> plain;
  std::string_view shuffled = stored;
  if ((mask & 2u) == 0) {
    plain.resize(bytes);
    uLongf got = bytes;
    const int rc = uncompress(plain.data(), &got, reinterpret_cast<const Bytef*>(stored.data()),
                              stored.size());
    if (rc == Z_BUF_ERROR && got == bytes) {
      return absl::DataLossError(
          absl::StrCat("inflates to more than the chunk's ", bytes, " bytes"));
    }
    if (rc != Z_OK)
      return absl::DataLossError(absl::StrCat("cannot inflate (zlib error ", rc, ")"));
    if (got != bytes) {
      return absl::DataLossError(
          absl::StrCat("inflates to ", got, " bytes, the chunk holds ", bytes));
    }
    shuffled = std::string_view(reinterpret_cast<const char*>(plain.data()), bytes);
  } else if (stored.size() != bytes) {
    return absl::DataLossError(
        absl::StrCat("stores ", stored.size(), " bytes, the chunk holds ", bytes));
  }
  const auto* in = reinterpret_cast<const unsigned char*>(shuffled.data());
  if ((mask & 1u) == 0 && Shuffles(chunk_rows, element_bytes)) {
    UnshuffleBytes(in, rows, element_bytes, chunk_rows, out);
  } else {
    std::memcpy(out, in, rows * element_bytes);
  }
  return absl::OkStatus();
}

// ---- Writing ------------------------------------------------------------------------------

absl::Status ValidateForWrite(const TileData& tile) {
  if (!ValidGrid(tile.grid)) {
    return absl::InvalidArgumentError(absl::StrCat("chunk_depth ", tile.grid.chunk_depth,
                                                   " outside [", kMinChunkDepth, ", ",
                                                   kMaxChunkDepth, "]"));
  }
  const int k = tile.grid.chunk_depth;
  uint64_t prev_end = 0;
  for (size_t i = 0; i < tile.leaves.size(); ++i) {
    const TileLeaf& leaf = tile.leaves[i];
    const int d = leaf.node.depth;
    if (d < 0 || d > k) {
      return absl::InvalidArgumentError(
          absl::StrCat("leaf ", i, ": depth ", d, " outside [0, ", k, "]"));
    }
    const int side = 1 << d;
    if ((leaf.node.local.array() < 0).any() || (leaf.node.local.array() >= side).any()) {
      return absl::InvalidArgumentError(absl::StrCat("leaf ", i, ": local (", leaf.node.local.x(),
                                                     ", ", leaf.node.local.y(), ", ",
                                                     leaf.node.local.z(), ") outside [0, ", side,
                                                     ") at depth ", d));
    }
    const LeafStats& s = leaf.stats;
    if (!std::isfinite(s.sum_w) || !std::isfinite(s.sum_wp) || !std::isfinite(s.sum_wp2) ||
        s.sum_w < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("leaf ", i, ": sums must be finite with sum_w >= 0"));
    }
    const double p = s.p();
    if (!(p >= 0.0 && p <= 1.0)) {
      return absl::InvalidArgumentError(absl::StrCat("leaf ", i, ": p = ", p, " outside [0, 1]"));
    }
    // Leaves are sorted by their first finest cell (SortTileLeaves), so an overlap shows as a
    // leaf starting before the previous one ends.
    const uint64_t start = FinestStart(k, MortonCode(leaf.node.local), d);
    if (i > 0 && start < prev_end) {
      return absl::InvalidArgumentError(
          absl::StrCat("leaf ", i, " (depth ", d, ") overlaps the previous leaf"));
    }
    prev_end = start + FinestSpan(k, d);
  }
  return absl::OkStatus();
}

absl::Status WriteInt64sAttr(hid_t obj, const char* name, const std::vector<int64_t>& values) {
  const hsize_t dims[1] = {values.size()};
  Hid space(H5Screate_simple(1, dims, nullptr));
  auto attr = h5::CheckId(H5Acreate2(obj, name, H5T_STD_I64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT),
                          absl::StrCat("cannot create attribute '", name, "'"));
  if (!attr.ok()) return attr.status();
  return h5::CheckRc(H5Awrite(attr->get(), H5T_NATIVE_INT64, values.data()),
                     absl::StrCat("cannot write attribute '", name, "'"));
}

absl::Status WriteAttributes(hid_t root, const TileData& tile, uint64_t num_leaves) {
  absl::Status s = h5::WriteStringAttr(root, "format", kTileFormat);
  if (s.ok()) s = h5::WriteIntAttr(root, "version", kTileVersion);
  if (s.ok()) s = WriteInt64sAttr(root, "chunk", {tile.chunk.x(), tile.chunk.y(), tile.chunk.z()});
  if (s.ok()) s = h5::WriteIntAttr(root, "chunk_depth", tile.grid.chunk_depth);
  if (s.ok()) s = h5::WriteDoubleAttr(root, "resolution_m", tile.grid.resolution_m());
  if (s.ok()) s = h5::WriteStringAttr(root, "job_id", tile.params.job_id);
  if (s.ok()) s = h5::WriteIntAttr(root, "num_wedges", static_cast<int64_t>(tile.params.num_wedges));
  if (s.ok()) s = h5::WriteDoubleAttr(root, "hull_sigmas", tile.params.hull_sigmas);
  if (s.ok()) s = h5::WriteDoubleAttr(root, "min_weight", tile.params.min_weight);
  if (s.ok()) s = h5::WriteIntAttr(root, "simplified", tile.params.simplified ? 1 : 0);
  if (s.ok()) s = h5::WriteIntAttr(root, "num_leaves", static_cast<int64_t>(num_leaves));
  return s;
}

// A column of `n` rows from its stored chunks (EncodeTile), each `chunk_rows` long.
absl::Status WriteColumn(hid_t group, const ColumnSpec& spec, hsize_t n, hsize_t chunk_rows,
                         const std::vector<std::string>& chunks) {
  const hsize_t dims[1] = {n};
  Hid space(H5Screate_simple(1, dims, nullptr));
  Hid dcpl(H5Pcreate(H5P_DATASET_CREATE));
  H5Pset_obj_track_times(dcpl.get(), 0);  // no time stamps: equal content, equal bytes
  // A defined zero fill: the tail of a last, partial chunk is zeros, not leftover memory.
  const std::array<unsigned char, 8> zero{};
  H5Pset_fill_value(dcpl.get(), spec.file_type, zero.data());
  if (n > 0) {
    // An empty column stays contiguous: a chunked dataset needs a chunk no larger than its
    // fixed extent, and there is nothing to compress.
    const hsize_t chunk[1] = {chunk_rows};
    H5Pset_chunk(dcpl.get(), 1, chunk);
    H5Pset_shuffle(dcpl.get());  // byte planes compress far better for floats and codes
    H5Pset_deflate(dcpl.get(), kDeflateLevel);
  }
  auto dataset = h5::CheckId(
      H5Dcreate2(group, spec.name, spec.file_type, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
      absl::StrCat("cannot create dataset '/leaves/", spec.name, "'"));
  if (!dataset.ok()) return dataset.status();
  for (size_t k = 0; k < chunks.size(); ++k) {
    const hsize_t offset[1] = {k * chunk_rows};
    absl::Status s = h5::CheckRc(H5Dwrite_chunk(dataset->get(), H5P_DEFAULT, /*filters=*/0, offset,
                                                chunks[k].size(), chunks[k].data()),
                                 absl::StrCat("cannot write dataset '/leaves/", spec.name, "'"));
    if (!s.ok()) return s;
  }
  return absl::OkStatus();
}

absl::Status WriteFile(const std::string& path, const EncodedTile& tile) {
  Hid fcpl(H5Pcreate(H5P_FILE_CREATE));
  H5Pset_obj_track_times(fcpl.get(), 0);  // the root group too
  auto file = h5::CheckId(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, fcpl.get(), H5P_DEFAULT),
                          "cannot create file");
  if (!file.ok()) return file.status();
  Hid root(H5Gopen2(file->get(), "/", H5P_DEFAULT));
  absl::Status s = WriteAttributes(root.get(), tile.header, tile.num_leaves);
  if (!s.ok()) return s;
  Hid gcpl = h5::GroupCreatePlist(/*track_link_order=*/false);
  auto group = h5::CheckId(H5Gcreate2(file->get(), kLeavesGroup, H5P_DEFAULT, gcpl.get(), H5P_DEFAULT),
                           "cannot create group '/leaves'");
  if (!group.ok()) return group.status();
  const auto specs = ColumnSpecs();
  for (size_t j = 0; j < specs.size(); ++j) {
    s = WriteColumn(group->get(), specs[j], tile.num_leaves, tile.chunk_rows, tile.columns[j]);
    if (!s.ok()) return s;
  }
  group->Reset();
  root.Reset();
  return h5::CheckRc(H5Fclose(file->Release()), "cannot close the file");
}

// ---- Reading ------------------------------------------------------------------------------

absl::Status Corrupt(absl::string_view what) { return absl::DataLossError(what); }

absl::Status ReadAttributes(hid_t root, TileData& tile, int64_t& version_out) {
  auto format = h5::ReadStringAttr(root, "format");
  if (!format.ok()) return Corrupt(absl::StrCat("/: ", format.status().message()));
  if (*format != kTileFormat) {
    return Corrupt(absl::StrCat("/: attribute 'format' is '", *format, "', expected '",
                                kTileFormat, "'"));
  }
  auto version = h5::ReadIntAttr(root, "version");
  if (!version.ok()) return Corrupt(absl::StrCat("/: ", version.status().message()));
  if (*version < 1 || *version > kTileVersion) {
    return Corrupt(absl::StrCat("/: unsupported version ", *version, " (this reader knows 1 to ",
                                kTileVersion, ")"));
  }
  version_out = *version;
  auto chunk = h5::ReadDoublesAttr(root, "chunk", 3);
  if (!chunk.ok()) return Corrupt(absl::StrCat("/: ", chunk.status().message()));
  for (int a = 0; a < 3; ++a) {
    const double v = (*chunk)[a];
    if (!std::isfinite(v) || v != std::floor(v) || std::abs(v) > 1e9) {
      return Corrupt("/: attribute 'chunk' must hold 3 integers");
    }
    tile.chunk[a] = static_cast<int>(v);
  }
  auto depth = h5::ReadIntAttr(root, "chunk_depth");
  if (!depth.ok()) return Corrupt(absl::StrCat("/: ", depth.status().message()));
  if (*depth < kMinChunkDepth || *depth > kMaxChunkDepth) {
    return Corrupt(absl::StrCat("/: chunk_depth ", *depth, " outside [", kMinChunkDepth, ", ",
                                kMaxChunkDepth, "]"));
  }
  tile.grid.chunk_depth = static_cast<int>(*depth);
  auto resolution = h5::ReadDoublesAttr(root, "resolution_m", 1);
  if (!resolution.ok()) return Corrupt(absl::StrCat("/: ", resolution.status().message()));
  if (!(std::abs((*resolution)[0] - tile.grid.resolution_m()) <= 1e-9 * tile.grid.resolution_m())) {
    return Corrupt(absl::StrCat("/: resolution_m ", (*resolution)[0], " disagrees with chunk_depth ",
                                *depth, " (", tile.grid.resolution_m(), " m)"));
  }
  auto job = h5::ReadStringAttr(root, "job_id");
  if (!job.ok()) return Corrupt(absl::StrCat("/: ", job.status().message()));
  tile.params.job_id = *job;
  auto wedges = h5::ReadIntAttr(root, "num_wedges");
  if (!wedges.ok() || *wedges < 0) {
    return Corrupt(absl::StrCat("/: ", wedges.ok() ? "num_wedges < 0" : wedges.status().message()));
  }
  tile.params.num_wedges = static_cast<uint64_t>(*wedges);
  auto sigmas = h5::ReadDoublesAttr(root, "hull_sigmas", 1);
  if (!sigmas.ok()) return Corrupt(absl::StrCat("/: ", sigmas.status().message()));
  tile.params.hull_sigmas = (*sigmas)[0];
  auto min_weight = h5::ReadDoublesAttr(root, "min_weight", 1);
  if (!min_weight.ok()) return Corrupt(absl::StrCat("/: ", min_weight.status().message()));
  tile.params.min_weight = (*min_weight)[0];
  auto simplified = h5::ReadIntAttr(root, "simplified");
  if (!simplified.ok()) return Corrupt(absl::StrCat("/: ", simplified.status().message()));
  tile.params.simplified = *simplified != 0;
  return absl::OkStatus();
}

// The id of filter `index` of a dataset's pipeline, or -1.
H5Z_filter_t FilterAt(hid_t dcpl, unsigned index) {
  unsigned flags = 0, config = 0;
  size_t cd_count = 0;
  return H5Pget_filter2(dcpl, index, &flags, &cd_count, nullptr, 0, nullptr, &config);
}

// Reads /leaves/<spec.name> (rank 1, numeric) into `out`: its stored chunks when it is laid
// out as WriteColumn lays it out, else its values through HDF5. `n` is the rows it must have
// (SIZE_MAX: not known yet). Returns its rows.
absl::StatusOr<size_t> ReadColumn(hid_t group, const ColumnSpec& spec, size_t element_bytes,
                                  size_t n, RawTile::Column& out) {
  const std::string where = absl::StrCat("/leaves/", spec.name);
  if (H5Lexists(group, spec.name, H5P_DEFAULT) <= 0) {
    H5Eclear2(H5E_DEFAULT);
    return Corrupt(absl::StrCat(where, ": missing dataset"));
  }
  auto dataset = h5::CheckId(H5Dopen2(group, spec.name, H5P_DEFAULT),
                             absl::StrCat(where, ": cannot open dataset"));
  if (!dataset.ok()) return dataset.status();
  Hid type(H5Dget_type(dataset->get()));
  const H5T_class_t cls = H5Tget_class(type.get());
  if (cls != (spec.integer ? H5T_INTEGER : H5T_FLOAT)) {
    return Corrupt(absl::StrCat(where, ": expected ", spec.integer ? "integers" : "floats"));
  }
  if (absl::Status s = h5::CheckTypeIsSane(type.get()); !s.ok()) {
    return Corrupt(absl::StrCat(where, ": ", s.message()));
  }
  auto dims = h5::Dims(dataset->get());
  if (!dims.ok()) return h5::Prefixed(where, dims.status());
  if (dims->size() != 1) return Corrupt(absl::StrCat(where, ": rank ", dims->size(), ", expected 1"));
  const size_t rows = (*dims)[0];
  if (n != SIZE_MAX && rows != n) {
    return Corrupt(absl::StrCat(where, ": ", rows, " rows, but /leaves/key has ", n));
  }
  if (absl::Status s = h5::CheckDataStored(dataset->get()); !s.ok()) {
    return Corrupt(absl::StrCat(where, ": ", s.message()));
  }
  if (rows == 0) return rows;
  Hid dcpl(H5Dget_create_plist(dataset->get()));
  hsize_t chunk_rows = 0;
  const bool as_written =
      H5Pget_layout(dcpl.get()) == H5D_CHUNKED && H5Pget_chunk(dcpl.get(), 1, &chunk_rows) == 1 &&
      chunk_rows >= 1 && chunk_rows <= kChunkRows && H5Pget_nfilters(dcpl.get()) == 2 &&
      FilterAt(dcpl.get(), 0) == H5Z_FILTER_SHUFFLE &&
      FilterAt(dcpl.get(), 1) == H5Z_FILTER_DEFLATE && H5Tequal(type.get(), spec.file_type) > 0;
  H5Eclear2(H5E_DEFAULT);
  if (!as_written) {
    out.decoded.resize(rows * element_bytes);
    absl::Status s = h5::CheckRc(
        H5Dread(dataset->get(), spec.mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.decoded.data()),
        absl::StrCat(where, ": cannot read"));
    if (!s.ok()) return s;
    return rows;
  }
  out.chunk_rows = chunk_rows;
  const size_t num_chunks = (rows + chunk_rows - 1) / chunk_rows;
  // A stored chunk is at most what deflate makes of incompressible bytes.
  const uint64_t max_stored = compressBound(chunk_rows * element_bytes);
  out.chunks.resize(num_chunks);
  out.masks.resize(num_chunks);
  for (size_t k = 0; k < num_chunks; ++k) {
    const hsize_t offset[1] = {k * chunk_rows};
    hsize_t stored = 0;
    if (H5Dget_chunk_storage_size(dataset->get(), offset, &stored) < 0 || stored == 0 ||
        stored > max_stored) {
      H5Eclear2(H5E_DEFAULT);
      return Corrupt(absl::StrCat(where, ": the chunk at row ", offset[0], " stores ", stored,
                                  " bytes (1 to ", max_stored, " expected)"));
    }
    out.chunks[k].resize(stored);
    absl::Status s = h5::CheckRc(
        H5Dread_chunk(dataset->get(), H5P_DEFAULT, offset, &out.masks[k], out.chunks[k].data()),
        absl::StrCat(where, ": cannot read the chunk at row ", offset[0]));
    if (!s.ok()) return Corrupt(s.message());
  }
  return rows;
}

absl::Status ValidateRows(const Columns& c, TileData& tile) {
  const int k = tile.grid.chunk_depth;
  const size_t n = c.key.size();
  tile.leaves.resize(n);
  uint64_t prev_end = 0;
  for (size_t i = 0; i < n; ++i) {
    const int d = c.depth[i];
    if (d > k) {
      return Corrupt(absl::StrCat("/leaves/depth[", i, "]: ", d, " > chunk_depth ", k));
    }
    if (c.key[i] >= (uint64_t{1} << (3 * d))) {
      return Corrupt(absl::StrCat("/leaves/key[", i, "]: ", c.key[i], " outside 8^", d));
    }
    const uint64_t start = FinestStart(k, c.key[i], d);
    if (i > 0 && start < prev_end) {
      return Corrupt(absl::StrCat("/leaves/key[", i, "]: leaves not sorted or overlapping"));
    }
    prev_end = start + FinestSpan(k, d);
    LeafStats s;
    s.sum_w = c.weight[i];
    s.sum_wp = c.sum_wp[i];
    s.sum_wp2 = c.sum_wp2[i];
    s.count = c.count[i];
    s.points = c.points[i];
    if (!std::isfinite(s.sum_w) || s.sum_w < 0) {
      return Corrupt(absl::StrCat("/leaves/weight[", i, "]: ", s.sum_w, " not finite and >= 0"));
    }
    if (!std::isfinite(s.sum_wp)) return Corrupt(absl::StrCat("/leaves/sum_wp[", i, "]: not finite"));
    if (!std::isfinite(s.sum_wp2)) {
      return Corrupt(absl::StrCat("/leaves/sum_wp2[", i, "]: not finite"));
    }
    const double p = c.p[i];
    if (!(p >= 0.0 && p <= 1.0)) {
      return Corrupt(absl::StrCat("/leaves/p[", i, "]: ", p, " outside [0, 1]"));
    }
    // p is derived from the sums (and stored as f32), so a mismatch means a damaged file.
    if (std::abs(p - s.p()) > 1e-6) {
      return Corrupt(absl::StrCat("/leaves/p[", i, "]: ", p, " disagrees with sum_wp / weight = ",
                                  s.p()));
    }
    const double v = c.variance[i];
    if (!std::isfinite(v) || v < 0 || std::abs(v - s.variance()) > 1e-6 + 1e-6 * v) {
      return Corrupt(absl::StrCat("/leaves/variance[", i, "]: ", v,
                                  " negative, not finite or disagreeing with the sums"));
    }
    tile.leaves[i].node.depth = d;
    tile.leaves[i].node.local = MortonDecode(c.key[i]);
    tile.leaves[i].stats = s;
  }
  return absl::OkStatus();
}

absl::StatusOr<RawTile> ReadRawFile(const std::string& path) {
  const htri_t is_hdf5 = H5Fis_hdf5(path.c_str());
  if (is_hdf5 <= 0) return h5::Error(absl::StatusCode::kDataLoss, "not a readable HDF5 file");
  auto file = h5::CheckId(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT),
                          "cannot open (truncated or corrupt?)");
  if (!file.ok()) return file.status();
  Hid root(H5Gopen2(file->get(), "/", H5P_DEFAULT));
  if (!root.valid()) return h5::Error(absl::StatusCode::kDataLoss, "cannot open the root group");
  RawTile raw;
  raw.path = path;
  int64_t version = 0;
  absl::Status s = ReadAttributes(root.get(), raw.header, version);
  if (!s.ok()) return s;
  if (!h5::Exists(file->get(), "/leaves")) return Corrupt("/leaves: missing group");
  auto group = h5::CheckId(H5Gopen2(file->get(), kLeavesGroup, H5P_DEFAULT),
                           "/leaves: cannot open group");
  if (!group.ok()) return group.status();
  size_t n = SIZE_MAX;
  const auto specs = ColumnSpecs();
  const size_t num_columns = version >= 2 ? specs.size() : specs.size() - 1;
  raw.columns.resize(num_columns);
  for (size_t j = 0; j < num_columns; ++j) {
    auto rows =
        ReadColumn(group->get(), specs[j], kColumnLayouts[j].element_bytes, n, raw.columns[j]);
    if (!rows.ok()) return rows.status();
    n = *rows;
  }
  auto num_leaves = h5::ReadIntAttr(root.get(), "num_leaves");
  if (!num_leaves.ok()) return Corrupt(absl::StrCat("/: ", num_leaves.status().message()));
  if (*num_leaves != static_cast<int64_t>(n)) {
    return Corrupt(absl::StrCat("/: num_leaves ", *num_leaves, " but the columns hold ", n, " rows"));
  }
  raw.rows = n;
  return raw;
}

// The leaves' columns out of `raw`'s stored chunks or HDF5-read values.
absl::Status DecodeColumns(const RawTile& raw, Columns& c) {
  ResizeColumns(c, raw.rows);
  const auto data = ColumnData(c);
  for (size_t j = 0; j < raw.columns.size() && j < data.size(); ++j) {
    const RawTile::Column& col = raw.columns[j];
    const size_t eb = kColumnLayouts[j].element_bytes;
    auto* out = static_cast<unsigned char*>(data[j]);
    if (col.chunks.empty()) {
      if (col.decoded.size() != raw.rows * eb) {
        return Corrupt(absl::StrCat("/leaves/", kColumnLayouts[j].name, ": ", col.decoded.size(),
                                    " bytes read for ", raw.rows, " rows"));
      }
      if (raw.rows > 0) std::memcpy(out, col.decoded.data(), col.decoded.size());
      continue;
    }
    if (col.chunk_rows == 0 ||
        col.chunks.size() != (raw.rows + col.chunk_rows - 1) / col.chunk_rows ||
        col.masks.size() != col.chunks.size()) {
      return Corrupt(absl::StrCat("/leaves/", kColumnLayouts[j].name, ": chunks do not cover ",
                                  raw.rows, " rows"));
    }
    for (size_t k = 0; k < col.chunks.size(); ++k) {
      const size_t first = k * col.chunk_rows;
      const size_t rows = std::min<size_t>(col.chunk_rows, raw.rows - first);
      absl::Status s =
          InflateUnshuffle(col.chunks[k], col.masks[k], col.chunk_rows, eb, rows, out + first * eb);
      if (!s.ok()) {
        return Corrupt(absl::StrCat("/leaves/", kColumnLayouts[j].name, ": the chunk at row ",
                                    first, " ", s.message()));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace

void SortTileLeaves(const OctreeGrid& grid, std::vector<TileLeaf>& leaves) {
  const int k = grid.chunk_depth;
  std::vector<std::pair<std::pair<uint64_t, int>, size_t>> order(leaves.size());
  for (size_t i = 0; i < leaves.size(); ++i) {
    const int d = leaves[i].node.depth;
    const uint64_t code = MortonCode(leaves[i].node.local);
    order[i] = {{d >= 0 && d <= k ? FinestStart(k, code, d) : code, d}, i};
  }
  // Stable on ties (equal start and depth = duplicates), so the outcome never depends on the
  // sort algorithm; WriteTile rejects duplicates as overlaps anyway.
  std::stable_sort(order.begin(), order.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<TileLeaf> sorted;
  sorted.reserve(leaves.size());
  for (const auto& o : order) sorted.push_back(leaves[o.second]);
  leaves = std::move(sorted);
}

std::string TileFileName(const ChunkKey& chunk) {
  return absl::StrCat("c_", chunk.x(), "_", chunk.y(), "_", chunk.z(), ".h5");
}

absl::StatusOr<EncodedTile> EncodeTile(const std::string& dir, const TileData& tile) {
  EncodedTile out;
  out.path = (std::filesystem::path(dir) / TileFileName(tile.chunk)).string();
  std::vector<TileLeaf> leaves = tile.leaves;
  if (ValidGrid(tile.grid)) SortTileLeaves(tile.grid, leaves);
  TileData sorted_view{tile.chunk, tile.grid, tile.params, {}};
  sorted_view.leaves = std::move(leaves);
  absl::Status valid = ValidateForWrite(sorted_view);
  if (!valid.ok()) return h5::Prefixed(out.path, valid);
  const std::vector<TileLeaf>& sorted = sorted_view.leaves;
  const size_t n = sorted.size();
  Columns c;
  ResizeColumns(c, n);
  for (size_t i = 0; i < n; ++i) {
    const LeafStats& s = sorted[i].stats;
    c.key[i] = MortonCode(sorted[i].node.local);
    c.depth[i] = static_cast<uint8_t>(sorted[i].node.depth);
    c.p[i] = static_cast<float>(s.p());
    c.weight[i] = s.sum_w;
    c.variance[i] = static_cast<float>(s.variance());
    c.count[i] = s.count;
    c.sum_wp[i] = s.sum_wp;
    c.sum_wp2[i] = s.sum_wp2;
    c.points[i] = s.points;
  }
  out.header = TileData{tile.chunk, tile.grid, tile.params, {}};
  out.num_leaves = n;
  out.chunk_rows = std::min<uint64_t>(n, kChunkRows);
  const auto data = ColumnData(c);
  out.columns.resize(data.size());
  for (size_t j = 0; j < data.size() && n > 0; ++j) {
    const size_t eb = kColumnLayouts[j].element_bytes;
    const auto* column = static_cast<const unsigned char*>(data[j]);
    for (size_t first = 0; first < n; first += out.chunk_rows) {
      const size_t rows = std::min<size_t>(out.chunk_rows, n - first);
      absl::StatusOr<std::string> stored =
          ShuffleDeflate(column + first * eb, rows, out.chunk_rows, eb);
      if (!stored.ok()) return h5::Prefixed(out.path, stored.status());
      out.columns[j].push_back(*std::move(stored));
    }
  }
  return out;
}

absl::StatusOr<std::string> WriteEncodedTile(const EncodedTile& tile) {
  const std::string& path = tile.path;
  const std::string partial = path + ".partial";
  absl::Status s;
  {
    std::lock_guard<std::mutex> lock(TileMutex());
    h5::Init();
    s = WriteFile(partial, tile);
  }
  // The fsyncs below run outside the HDF5 lock: other threads' reads need not wait for the disk.
  std::error_code error;
  if (!s.ok()) {
    std::filesystem::remove(partial, error);
    // Write failures (disk full, permissions) are I/O, not corrupt data.
    return absl::Status(absl::StatusCode::kInternal, absl::StrCat(partial, ": ", s.message()));
  }
  // Durable before the caller reports the chunk done (atomic_file.h).
  if (absl::Status renamed = RenameDurably(partial, path); !renamed.ok()) {
    std::filesystem::remove(partial, error);
    return renamed;
  }
  return path;
}

absl::StatusOr<std::string> WriteTile(const std::string& dir, const TileData& tile) {
  absl::StatusOr<EncodedTile> encoded = EncodeTile(dir, tile);
  if (!encoded.ok()) return encoded.status();
  return WriteEncodedTile(*encoded);
}

absl::StatusOr<RawTile> ReadRawTile(const std::string& path) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    return absl::NotFoundError(absl::StrCat(path, ": no such tile"));
  }
  std::lock_guard<std::mutex> lock(TileMutex());
  h5::Init();
  auto raw = ReadRawFile(path);
  if (!raw.ok()) {
    H5Eclear2(H5E_DEFAULT);
    return absl::Status(raw.status().code(), absl::StrCat(path, ": ", raw.status().message()));
  }
  return raw;
}

absl::StatusOr<TileData> DecodeTile(RawTile raw) {
  Columns c;
  TileData tile = std::move(raw.header);
  absl::Status s = DecodeColumns(raw, c);
  if (s.ok()) {
    raw.columns.clear();  // the stored chunks are not needed past here
    s = ValidateRows(c, tile);
  }
  if (!s.ok()) return absl::Status(s.code(), absl::StrCat(raw.path, ": ", s.message()));
  return tile;
}

absl::StatusOr<TileData> ReadTile(const std::string& path) {
  absl::StatusOr<RawTile> raw = ReadRawTile(path);
  if (!raw.ok()) return raw.status();
  return DecodeTile(*std::move(raw));
}

}  // namespace carvemap
