// Writes the seed corpora of the fuzz targets (corpus/<target>/) from the real fixtures in
// tests/data, cut small so that each execution stays fast (libFuzzer's max_len follows the
// largest seed). Run by hand when a format changes; the seeds are committed:
//   cmake --build <fuzz build> --target make_seeds
//   <fuzz build>/make_seeds tests/data tests/fuzz/corpus
// HDF5: the structure-aware targets (scan_reader, tile_reader) get scripts (h5_script.h)
// decompiled from files our writers wrote (ScanWriter, WriteTile) and from a "foreign" scan
// with contiguous datasets and fixed-length strings (as h5py and others may write, docs/DESIGN.md
// §3); the *_raw targets get files: the foreign scans (10 KiB; ScanWriter's 100–200 KiB chunks
// make 400 KiB files) and WriteTile's tiles.
#include <png.h>
#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include "absl/strings/str_cat.h"
#include "storage/h5_util.h"
#include "storage/import/octomap_graph_import.h"
#include "storage/ply_io.h"
#include "storage/png_io.h"
#include "storage/scan_writer.h"
#include "storage/tile_store.h"
#include "storage/partial_sums.h"
#include "tests/fuzz/h5_script.h"

namespace carvemap {
namespace {

namespace fs = std::filesystem;
using h5::Hid;

[[noreturn]] void Die(const std::string& what) {
  std::fprintf(stderr, "make_seeds: %s\n", what.c_str());
  std::exit(1);
}

template <typename T>
T Check(absl::StatusOr<T> v) {
  if (!v.ok()) Die(v.status().ToString());
  return *std::move(v);
}
void Check(const absl::Status& s) {
  if (!s.ok()) Die(s.ToString());
}

void WriteBytes(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
  if (!out) Die("cannot write " + path.string());
  std::printf("%7zu %s\n", bytes.size(), path.c_str());
}

template <typename T>
void Put(std::string& s, T v, bool big = false) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big) std::reverse(b, b + sizeof(T));
  s.append(b, sizeof(T));
}

// --- Real points: OctoMap's spherical_scan.graph -------------------------------------------

struct Node {
  PathRecord pose;
  std::vector<Eigen::Vector3f> points;  // sensor frame
};

// The fixture is one node of 10201 points. Seeds with several nodes take `points` of them
// each, spread over the sweep, at its pose moved 0.5 m along x per node (a short walk).
std::vector<Node> GraphNodes(const std::string& data_dir, size_t nodes, size_t points) {
  const ImportedScan scan =
      Check(ImportOctomapGraph(data_dir + "/octomap/spherical_scan.graph"));
  if (scan.frames.empty()) Die("spherical_scan.graph has no nodes");
  const auto& all = scan.frames[0].points_sensor;
  const size_t step = std::max<size_t>(1, all.size() / (nodes * points));
  std::vector<Node> out;
  for (size_t k = 0; k < nodes; ++k) {
    Node n{scan.path[0], {}};
    n.pose.x += 0.5 * k;
    n.pose.t = double(k);
    for (size_t i = 0; i < points; ++i) n.points.push_back(all[((i * nodes + k) * step) % all.size()]);
    out.push_back(std::move(n));
  }
  return out;
}

Eigen::Vector3d World(const PathRecord& p, const Eigen::Vector3f& x) {
  const Eigen::Quaterniond q(p.qw, p.qx, p.qy, p.qz);
  return q * x.cast<double>() + Eigen::Vector3d(p.x, p.y, p.z);
}

// OctoMap's ScanGraph::writeBinary layout (storage/import/octomap_graph_import.h).
std::string GraphBytes(const std::vector<Node>& nodes, bool with_edge) {
  std::string s;
  Put<uint32_t>(s, nodes.size());
  auto pose = [&s](const PathRecord& p) {
    Put<int32_t>(s, 3);
    for (double v : {p.x, p.y, p.z}) Put<double>(s, v);
    Put<int32_t>(s, 4);
    for (double v : {p.qw, p.qx, p.qy, p.qz}) Put<double>(s, v);
  };
  for (size_t k = 0; k < nodes.size(); ++k) {
    Put<uint32_t>(s, nodes[k].points.size());
    for (const Eigen::Vector3f& x : nodes[k].points) {
      Put<int32_t>(s, 3);
      for (int a = 0; a < 3; ++a) Put<double>(s, x[a]);
    }
    pose(nodes[k].pose);
    Put<uint32_t>(s, static_cast<uint32_t>(k));
  }
  Put<uint32_t>(s, with_edge && nodes.size() > 1 ? 1 : 0);
  if (with_edge && nodes.size() > 1) {
    Put<uint32_t>(s, 0);
    Put<uint32_t>(s, 1);
    pose(nodes[1].pose);
    Put<double>(s, 1.0);
  }
  return s;
}

// --- PLY clouds with sensor origins (storage/import/ply_import.h) --------------------------

std::string AsciiPly(const std::vector<Node>& nodes) {
  std::ostringstream v;
  size_t n = 0;
  for (size_t k = 0; k < nodes.size(); ++k) {
    for (const Eigen::Vector3f& x : nodes[k].points) {
      const Eigen::Vector3d w = World(nodes[k].pose, x);
      v << w.x() << " " << w.y() << " " << w.z() << " 200 " << nodes[k].pose.x << " "
        << nodes[k].pose.y << " " << nodes[k].pose.z << " " << 0.5 + k << "\n";
      ++n;
    }
  }
  return absl::StrCat("ply\nformat ascii 1.0\ncomment cut of OctoMap spherical_scan.graph\n",
                      "element vertex ", n,
                      "\nproperty float x\nproperty float y\nproperty float z\n"
                      "property uchar intensity\nproperty double sensor_x\n"
                      "property double sensor_y\nproperty double sensor_z\n"
                      "property double time\nend_header\n",
                      v.str());
}

// A face element before the vertices (skipped by the importer), then vertices with vp_*.
std::string BinaryPly(const std::vector<Node>& nodes, bool big) {
  std::string body;
  Put<uint8_t>(body, 3, big);
  for (int32_t i : {0, 1, 2}) Put<int32_t>(body, i, big);
  size_t n = 0;
  for (const Node& node : nodes) {
    for (const Eigen::Vector3f& x : node.points) {
      const Eigen::Vector3d w = World(node.pose, x);
      for (double c : {w.x(), w.y(), w.z()}) Put<float>(body, float(c), big);
      for (double c : {node.pose.x, node.pose.y, node.pose.z}) Put<double>(body, c, big);
      ++n;
    }
  }
  return absl::StrCat("ply\nformat ", big ? "binary_big_endian" : "binary_little_endian",
                      " 1.0\nelement face 1\nproperty list uchar int vertex_indices\n",
                      "element vertex ", n,
                      "\nproperty float x\nproperty float y\nproperty float z\n"
                      "property double vp_x\nproperty double vp_y\nproperty double vp_z\n"
                      "end_header\n",
                      body);
}

// --- scan.h5 (docs/DESIGN.md §3) with contiguous datasets
// -------------------------------------------

Hid Contiguous(hid_t loc, const char* name, hid_t file_type, hsize_t rows, hsize_t cols) {
  const hsize_t dims[2] = {rows, cols};
  Hid space(H5Screate_simple(cols > 0 ? 2 : 1, dims, nullptr));
  Hid dcpl(H5Pcreate(H5P_DATASET_CREATE));
  H5Pset_obj_track_times(dcpl.get(), 0);
  Hid d(H5Dcreate2(loc, name, file_type, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT));
  if (!d.valid()) Die(absl::StrCat("cannot create ", name, ": ", h5::TakeErrorStack()));
  return d;
}

void WriteAll(hid_t dataset, hid_t mem_type, const void* data) {
  if (H5Dwrite(dataset, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0) {
    Die("H5Dwrite: " + h5::TakeErrorStack());
  }
}

// A fixed-length string attribute (h5_util writes variable-length ones, as h5py does; a
// foreign writer may use either).
void FixedStringAttr(hid_t obj, const char* name, const std::string& value) {
  Hid type(H5Tcopy(H5T_C_S1));
  H5Tset_size(type.get(), value.size());
  H5Tset_strpad(type.get(), H5T_STR_NULLPAD);
  Hid space(H5Screate(H5S_SCALAR));
  Hid attr(H5Acreate2(obj, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT));
  H5Awrite(attr.get(), type.get(), value.data());
}

struct SeedSensor {
  SensorInfo info;
  std::vector<FrameRecord> frames;
  std::vector<Eigen::Vector3f> points;
};

void WriteSensor(hid_t sensors, const SeedSensor& s, bool fixed_strings) {
  Hid gcpl = h5::GroupCreatePlist(false);
  Hid g(H5Gcreate2(sensors, s.info.name.c_str(), H5P_DEFAULT, gcpl.get(), H5P_DEFAULT));
  const std::string kind(SensorKindName(s.info.kind));
  if (fixed_strings) {
    FixedStringAttr(g.get(), "kind", kind);
  } else {
    Check(h5::WriteStringAttr(g.get(), "kind", kind));
  }
  if (s.info.kind == SensorKind::kGrid) {
    Check(h5::WriteIntAttr(g.get(), "rows", s.info.rows));
    Check(h5::WriteIntAttr(g.get(), "cols", s.info.cols));
  }
  std::vector<double> r(9);
  for (int i = 0; i < 9; ++i) r[i] = s.info.R_s2c(i / 3, i % 3);
  Check(h5::WriteDoublesAttr(g.get(), "R_s2c", r));
  Check(h5::WriteDoublesAttr(g.get(), "T_s2c", {s.info.T_s2c.data(), 3}));
  Check(h5::WriteDoubleAttr(g.get(), "sigma_t", s.info.sigma_t_s));
  Check(h5::WriteDoublesAttr(g.get(), "range_sigma", s.info.range_sigma));
  Check(h5::WriteDoubleAttr(g.get(), "max_range", s.info.max_range_m));
  Hid frame_file = h5::FrameFileType(), frame_mem = h5::FrameMemType();
  Hid frames = Contiguous(g.get(), "frames", frame_file.get(), s.frames.size(), 0);
  WriteAll(frames.get(), frame_mem.get(), s.frames.data());
  Hid points = Contiguous(g.get(), "points", H5T_IEEE_F32LE, s.points.size(), 3);
  WriteAll(points.get(), H5T_NATIVE_FLOAT, s.points.data());
}

struct SeedScan {
  std::vector<PathRecord> path;
  std::vector<PathCovariance> cov;
  std::vector<MagnetometerRecord> magnetometer;
  std::vector<SeedSensor> sensors;
};

std::string ScanBytes(const fs::path& tmp, const SeedScan& scan, bool fixed_strings) {
  h5::Init();
  fs::create_directories(tmp.parent_path());
  Hid fcpl(H5Pcreate(H5P_FILE_CREATE));
  H5Pset_obj_track_times(fcpl.get(), 0);
  {
    Hid f(H5Fcreate(tmp.c_str(), H5F_ACC_TRUNC, fcpl.get(), H5P_DEFAULT));
    if (!f.valid()) Die("cannot create " + tmp.string());
    Hid root(H5Gopen2(f.get(), "/", H5P_DEFAULT));
    if (fixed_strings) {
      FixedStringAttr(root.get(), "format", "carvemap-scan");
    } else {
      Check(h5::WriteStringAttr(root.get(), "format", "carvemap-scan"));
    }
    Check(h5::WriteIntAttr(root.get(), "version", 1));
    Hid path_file = h5::PathFileType(), path_mem = h5::PathMemType();
    Hid path = Contiguous(f.get(), "path", path_file.get(), scan.path.size(), 0);
    WriteAll(path.get(), path_mem.get(), scan.path.data());
    if (!scan.cov.empty()) {
      Hid cov = Contiguous(f.get(), "path_cov", H5T_IEEE_F32LE, scan.cov.size(), 12);
      WriteAll(cov.get(), H5T_NATIVE_FLOAT, scan.cov.data());
    }
    if (!scan.magnetometer.empty()) {
      Hid mag_file = h5::MagnetometerFileType(), mag_mem = h5::MagnetometerMemType();
      Hid mag = Contiguous(f.get(), "magnetometer", mag_file.get(), scan.magnetometer.size(), 0);
      WriteAll(mag.get(), mag_mem.get(), scan.magnetometer.data());
    }
    Hid gcpl = h5::GroupCreatePlist(/*track_link_order=*/true);
    Hid sensors(H5Gcreate2(f.get(), "sensors", H5P_DEFAULT, gcpl.get(), H5P_DEFAULT));
    for (const SeedSensor& s : scan.sensors) WriteSensor(sensors.get(), s, fixed_strings);
  }
  std::ifstream in(tmp, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  fs::remove(tmp);
  return bytes;
}

// The same scan through ScanWriter (chunked datasets, link order tracked).
void WriteWithScanWriter(const fs::path& path, const SeedScan& scan) {
  auto writer = Check(ScanWriter::Create(path.string()));
  Check(writer->AppendPath(scan.path, scan.cov));
  for (const SeedSensor& s : scan.sensors) {
    const int index = Check(writer->AddSensor(s.info));
    for (const FrameRecord& f : s.frames) {
      Check(writer->AppendFrame(index, f.t, {s.points.data() + f.first, f.count}));
    }
  }
  if (!scan.magnetometer.empty()) Check(writer->AppendMagnetometer(scan.magnetometer));
  Check(writer->Close());
}

std::string ReadFileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Seeds of both HDF5 scan targets: the foreign file's bytes (raw) and its script, and the
// script of the file ScanWriter writes.
void WriteScanSeeds(const SeedScan& scan, const std::string& name, bool fixed_strings,
                    const fs::path& corpus) {
  const fs::path tmp = corpus / "tmp.h5";
  const std::string foreign = ScanBytes(tmp, scan, fixed_strings);
  WriteBytes(corpus / "scan_reader_raw" / (name + ".h5"), foreign);
  WriteBytes(tmp, foreign);
  WriteBytes(corpus / "scan_reader" / (name + "_foreign"), Check(fuzz::ScriptFromH5(tmp)));
  WriteWithScanWriter(tmp, scan);
  WriteBytes(corpus / "scan_reader" / (name + "_scan_writer"), Check(fuzz::ScriptFromH5(tmp)));
  fs::remove(tmp);
}

// Two scans from the graph's first nodes: one `points` sensor (as `carvemap import graph`
// makes), and a line + grid + points scan with covariances and a magnetometer.
void ScanSeeds(const std::vector<Node>& nodes, const fs::path& corpus) {
  SeedScan a;
  SeedSensor graph;
  graph.info.name = "graph";
  graph.info.kind = SensorKind::kPoints;
  graph.info.range_sigma = {0.02, 0.0};
  for (size_t k = 0; k < nodes.size(); ++k) {
    PathRecord p = nodes[k].pose;
    p.t = double(k);
    a.path.push_back(p);
    graph.frames.push_back({double(k), graph.points.size(), uint32_t(nodes[k].points.size())});
    graph.points.insert(graph.points.end(), nodes[k].points.begin(), nodes[k].points.end());
  }
  a.sensors.push_back(graph);
  WriteScanSeeds(a, "graph_points", false, corpus);

  SeedScan b;
  for (size_t k = 0; k < nodes.size(); ++k) {
    PathRecord p = nodes[k].pose;
    p.t = 10.0 * k;
    b.path.push_back(p);
    PathCovariance c{};
    for (int d : {0, 3, 5}) c[d] = 1e-4f;
    for (int d : {6, 9, 11}) c[d] = 1e-5f;
    b.cov.push_back(c);
    b.magnetometer.push_back({10.0 * k, 0.2, 0.0, -0.4});
  }
  const double t_end = b.path.back().t;
  SeedSensor line, grid, points;
  line.info.name = "h0";
  line.info.kind = SensorKind::kLine;
  line.info.sigma_t_s = 1e-3;
  line.info.range_sigma = {0.01, 0.001};
  grid.info.name = "cam";
  grid.info.kind = SensorKind::kGrid;
  grid.info.rows = 2;
  grid.info.cols = 2;
  grid.info.R_s2c << 0, 0, 1, -1, 0, 0, 0, -1, 0;  // optical frame: z forward
  grid.info.T_s2c = {0.1, 0.0, 0.3};
  points.info.name = "cloud";
  points.info.kind = SensorKind::kPoints;
  const auto& src = nodes.front().points;
  for (int f = 0; f < 3; ++f) {
    line.frames.push_back({t_end * (f + 1) / 4, line.points.size(), 3});
    for (int i = 0; i < 3; ++i) line.points.push_back(src[(3 * f + i) % src.size()]);
  }
  line.points[4] = Eigen::Vector3f::Constant(std::nanf(""));  // a beam with no return
  for (int f = 0; f < 2; ++f) {
    grid.frames.push_back({t_end * (2 * f + 1) / 5, grid.points.size(), 4});
    for (int i = 0; i < 4; ++i) grid.points.push_back(src[(4 * f + i + 1) % src.size()]);
  }
  points.frames.push_back({t_end / 2, 0, 2});
  points.points = {src[0], src.back()};
  b.sensors = {line, grid, points};
  WriteScanSeeds(b, "line_grid_points", true, corpus);
}

// --- Tiles, from WriteTile -----------------------------------------------------------------

void TileSeeds(const fs::path& out) {
  const fs::path tmp = out / "tmp";
  fs::create_directories(tmp);
  // Leaves of a chunk at depth 5 (6.25 cm): a coarse exterior node, a few interior leaves at
  // finer depths, as a simplified carve leaves them (§4.3.2), with fused sums (eq 4.8).
  TileData tile;
  tile.chunk = ChunkKey(-1, 2, 0);
  tile.grid.chunk_depth = 5;
  tile.params.job_id = "seed";
  tile.params.num_wedges = 42;
  auto leaf = [](int depth, Eigen::Vector3i local, std::initializer_list<std::pair<double, double>> pw) {
    TileLeaf l;
    l.node.depth = depth;
    l.node.local = local;
    for (const auto& [p, w] : pw) l.stats.Add(p, w);
    return l;
  };
  tile.leaves = {leaf(1, {1, 1, 1}, {{0.1, 0.5}, {0.2, 0.25}}),
                 leaf(3, {0, 0, 0}, {{0.9, 1.0}}),
                 leaf(5, {8, 0, 0}, {{0.7, 0.3}, {0.95, 0.8}, {0.6, 0.1}}),
                 leaf(4, {2, 2, 0}, {{0.5, 0.0}})};
  TileData empty;
  empty.chunk = ChunkKey(0, 0, 0);
  empty.grid.chunk_depth = 7;
  for (const auto& [name, t] : {std::pair{"leaves_d5", tile}, std::pair{"empty_d7", empty}}) {
    const std::string path = Check(WriteTile(tmp.string(), t));
    WriteBytes(out / "tile_reader_raw" / (std::string(name) + ".h5"), ReadFileBytes(path));
    WriteBytes(out / "tile_reader" / name, Check(fuzz::ScriptFromH5(path)));
  }
  fs::remove_all(tmp);
}

// --- PNG -------------------------------------------------------------------------------------

std::string PngBytes(png_uint_32 width, png_uint_32 height, png_uint_32 format,
                     const void* pixels, const void* colormap = nullptr) {
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  image.width = width;
  image.height = height;
  image.format = format;
  if (colormap) image.colormap_entries = 256;
  png_alloc_size_t size = 0;
  if (!png_image_write_to_memory(&image, nullptr, &size, 0, pixels, 0, colormap)) {
    Die(absl::StrCat("png size: ", image.message));
  }
  std::string bytes(size, '\0');
  if (!png_image_write_to_memory(&image, bytes.data(), &size, 0, pixels, 0, colormap)) {
    Die(absl::StrCat("png write: ", image.message));
  }
  bytes.resize(size);
  return bytes;
}

// A real TUM depth image, every 40th pixel: 16 × 12, 16-bit gray.
std::string DepthPng(const std::string& data_dir) {
  const Image<uint16_t> depth = Check(
      ReadPngGray16(data_dir + "/tum_fr2_pioneer_slam2/depth/1311877813.991479.png"));
  std::vector<uint16_t> small;
  for (int r = 0; r < 12; ++r) {
    for (int c = 0; c < 16; ++c) small.push_back(depth.at(r * 40 + 20, c * 40 + 20));
  }
  return PngBytes(16, 12, PNG_FORMAT_LINEAR_Y, small.data());
}

// A 24 × 16 crop of a real floor map, in the colour types the maps come in (SOURCES.md).
void PngSeeds(const std::string& data_dir, const fs::path& out) {
  const Image<uint8_t> map = Check(ReadPngGray8(data_dir + "/floormaps/lab_c_scan.png"));
  const int w = 24, h = 16, r0 = 200, c0 = 300;
  std::vector<uint8_t> gray, ga, rgb;
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      const uint8_t v = map.at(r0 + r, c0 + c);
      gray.push_back(v);
      ga.insert(ga.end(), {v, uint8_t(v == 205 ? 0 : 255)});  // unknown grey as transparent
      rgb.insert(rgb.end(), {v, v, v});
    }
  }
  std::vector<uint8_t> colormap(256 * 3);
  for (int i = 0; i < 256; ++i) colormap[3 * i] = colormap[3 * i + 1] = colormap[3 * i + 2] = i;
  WriteBytes(out / "map_gray.png", PngBytes(w, h, PNG_FORMAT_GRAY, gray.data()));
  WriteBytes(out / "map_gray_alpha.png", PngBytes(w, h, PNG_FORMAT_GA, ga.data()));
  WriteBytes(out / "map_rgb.png", PngBytes(w, h, PNG_FORMAT_RGB, rgb.data()));
  WriteBytes(out / "map_palette.png",
             PngBytes(w, h, PNG_FORMAT_RGB_COLORMAP, gray.data(), colormap.data()));
  WriteBytes(out / "depth16.png", DepthPng(data_dir));
}

// Two real association lines (those of the first two depth images), renamed to the images
// the fuzz target writes (depth/1.png, depth/2.png), then a NUL and the depth image.
void TumSeeds(const std::string& data_dir, const fs::path& out) {
  const std::string assoc = data_dir + "/tum_fr2_pioneer_slam2/my_association.txt";
  std::ifstream in(assoc);
  std::string line, header, poses[2];
  const char* depth_names[2] = {"depth/1311877813.991479.png", "depth/1311877815.324132.png"};
  while (std::getline(in, line)) {
    if (line.rfind("#", 0) == 0) header += line + "\n";
    for (int i = 0; i < 2; ++i) {
      if (line.find(depth_names[i]) != std::string::npos) {
        poses[i] = line.substr(line.find(".png", line.find(".png") + 4) + 5);
      }
    }
  }
  if (poses[0].empty() || poses[1].empty()) Die("association lines not found in " + assoc);
  const std::string text = absl::StrCat(header, "rgb/1.png depth/1.png ", poses[0], "\n",
                                        "rgb/2.png depth/2.png ", poses[1], "\n");
  WriteBytes(out / "fr2_two_frames", text + std::string(1, '\0') + DepthPng(data_dir));
  WriteBytes(out / "fr2_poses_only", text);
}

// --- CARMEN logs (storage/import/carmen_import.h) ------------------------------------------

// The decompressed text of a real log slice in tests/data/carmen.
std::string Gunzip(const std::string& path) {
  gzFile f = gzopen(path.c_str(), "rb");
  if (!f) Die("cannot open " + path);
  std::string text;
  char buf[1 << 14];
  int n;
  while ((n = gzread(f, buf, sizeof buf)) > 0) text.append(buf, static_cast<size_t>(n));
  gzclose(f);
  if (n < 0) Die("cannot decompress " + path);
  return text;
}

// The log's lines up to its `scans`-th FLASER, leaving out PARAM lines (the Freiburg log has
// 168 of them, which the importer skips unread).
std::string FirstScans(const std::string& text, int scans) {
  std::istringstream in(text);
  std::string line, out;
  int seen = 0;
  while (seen < scans && std::getline(in, line)) {
    if (line.rfind("PARAM", 0) == 0) continue;
    out += line + "\n";
    if (line.rfind("FLASER", 0) == 0) ++seen;
  }
  return out;
}

void CarmenSeeds(const std::string& data_dir, const fs::path& out) {
  const std::string intel = FirstScans(Gunzip(data_dir + "/carmen/intel-first100.log.gz"), 3);
  WriteBytes(out / "intel_3_scans.log", intel);
  WriteBytes(out / "freiburg_2_scans.log",
             FirstScans(Gunzip(data_dir + "/carmen/freiburg101-first20.log.gz"), 2));
  // The same three scans gzip-compressed, deterministically (no name or time in the header).
  std::string gz(compressBound(intel.size()) + 64, '\0');
  z_stream z{};
  if (deflateInit2(&z, 9, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) Die("deflate");
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(intel.data()));
  z.avail_in = static_cast<uInt>(intel.size());
  z.next_out = reinterpret_cast<Bytef*>(gz.data());
  z.avail_out = static_cast<uInt>(gz.size());
  if (deflate(&z, Z_FINISH) != Z_STREAM_END) Die("deflate");
  gz.resize(z.total_out);
  deflateEnd(&z);
  WriteBytes(out / "intel_3_scans.log.gz", gz);
  // The newer messages, in both layouts (with and without remission_mode), and odometry.
  WriteBytes(out / "robot_raw.log",
             "ODOM 0 0 0 0 0 0 1.0 host 1.0\n"
             "RAWLASER1 0 -1.5708 3.14159 1.5708 50 0.01 0 3 1.0 2.0 81.0 0 1.5 host 1.5\n"
             "ODOM 1 0 0.5 0 0 0 2.0 host 2.0\n"
             "RAWLASER1 0 -1.5708 3.14159 1.5708 50 0.01 3 1.0 2.0 3.0 1 7 1.8 host 1.8\n"
             "ROBOTLASER2 0 -1.0 1.0 0.25 4.0 0.01 0 5 1.0 2.0 4.0 3.5 0 2 0.5 0.5 10 20 1.2 9.8 "
             "20 1.2 0.1 0 0.5 0.3 0 2.1 host 2.1\n");
}

// --- Meshes, walks, partial sums ----------------------------------------------------------------

void MeshSeeds(const fs::path& out) {
  TriangleMesh cube;
  for (int i = 0; i < 8; ++i) cube.vertices.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  const int faces[12][3] = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                            {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  std::vector<int> labels;
  for (int f = 0; f < 12; ++f) {
    cube.triangles.emplace_back(faces[f][0], faces[f][1], faces[f][2]);
    labels.push_back(f / 2);
  }
  const fs::path tmp = out / "tmp.ply";
  fs::create_directories(out);
  Check(WritePly(tmp.string(), cube, &labels, "room"));
  std::ifstream in(tmp, std::ios::binary);
  WriteBytes(out / "cube_labels.ply", std::string(std::istreambuf_iterator<char>(in), {}));
  fs::remove(tmp);
  // A quad and a pentagon (fanned into triangles), an extra vertex property, a short face
  // property.
  std::string body;
  for (int i = 0; i < 5; ++i) {
    for (float v : {float(std::cos(i * 1.2566)), float(std::sin(i * 1.2566)), 0.0f}) {
      Put<float>(body, v);
    }
    Put<uint8_t>(body, 255);
  }
  Put<uint8_t>(body, 4);
  for (int32_t i : {0, 1, 2, 3}) Put<int32_t>(body, i);
  Put<int16_t>(body, 7);
  Put<uint8_t>(body, 5);
  for (int32_t i : {0, 1, 2, 3, 4}) Put<int32_t>(body, i);
  Put<int16_t>(body, -3);
  WriteBytes(out / "polygons.ply",
             "ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\n"
             "property float y\nproperty float z\nproperty uchar red\nelement face 2\n"
             "property list uchar int vertex_indices\nproperty short object\nend_header\n" +
                 body);
}

void PathSeeds(const std::vector<Node>& nodes, const fs::path& out) {
  std::string csv = "x,y\n", spaced = "# walk from spherical_scan.graph\n\n";
  for (const Node& n : nodes) {
    absl::StrAppend(&csv, n.pose.x, ",", n.pose.y, "\n");
    absl::StrAppend(&spaced, n.pose.x, " ", n.pose.y, "\t", n.pose.z, "\r\n");
  }
  WriteBytes(out / "walk.csv", csv);
  WriteBytes(out / "walk_spaces.txt", spaced);
}

// A slice's partial sums of two chunks (one flushed twice) from real points (the leaves holding
// the scan's points, with sums), and a regions file.
void PartialSumsSeeds(const std::vector<Node>& nodes, const fs::path& out) {
  fs::create_directories(out);
  OctreeGrid grid;
  grid.chunk_depth = 5;
  std::map<ChunkKey, std::map<std::tuple<int, int, int>, LeafStats>, ChunkKeyLess> leaves;
  for (const Node& n : nodes) {
    for (size_t i = 0; i < n.points.size(); i += 7) {
      const Eigen::Vector3d p = World(n.pose, n.points[i]);
      const LeafKey key = LeafOf(grid, p);
      const ChunkKey chunk = ChunkOfLeaf(grid, key);
      const Eigen::Vector3i local = key - chunk * grid.leaves_per_side();
      LeafStats& s = leaves[chunk][{local.x(), local.y(), local.z()}];
      s.Add(0.25, 0.75);
      ++s.points;
    }
  }
  const fs::path path = out / "two_chunks.part";
  auto writer = PartialSumsWriter::Create(path.string(), grid.chunk_depth, 3);
  Check(writer.status());
  int written = 0;
  std::vector<RecarveChunk> regions;
  for (const auto& [chunk, cells] : leaves) {
    if (written++ == 2) break;
    std::vector<TileLeaf> list;
    for (const auto& [xyz, stats] : cells) {
      TileLeaf l;
      l.node.depth = grid.chunk_depth;
      l.node.local = Eigen::Vector3i(std::get<0>(xyz), std::get<1>(xyz), std::get<2>(xyz));
      l.stats = stats;
      list.push_back(l);
    }
    Check((*writer)->AddSection(chunk, 40, list));
    Check((*writer)->AddSection(chunk, 1, std::span(list).first(list.size() / 2)));
    regions.push_back(RecarveChunk::Of(chunk, ChunkRegion(2, {{0, 0, 0}, {3, 1, 2}})));
  }
  Check((*writer)->Finish().status());
  Check(WriteRegionsFile((out / "regions.bin").string(), regions));
}

}  // namespace
}  // namespace carvemap

int main(int argc, char** argv) {
  using namespace carvemap;
  if (argc != 3) Die("usage: make_seeds <test data dir> <corpus dir>");
  const std::string data = argv[1];
  const fs::path out = argv[2];
  const std::vector<Node> nodes = GraphNodes(data, 3, 12);
  WriteBytes(out / "graph_import/spherical_3_nodes.graph", GraphBytes(nodes, true));
  WriteBytes(out / "graph_import/spherical_1_node.graph",
             GraphBytes({nodes.begin(), nodes.begin() + 1}, false));
  WriteBytes(out / "ply_import/ascii_sensor_time.ply", AsciiPly(nodes));
  WriteBytes(out / "ply_import/binary_le_vp.ply", BinaryPly(nodes, false));
  WriteBytes(out / "ply_import/binary_be_vp.ply", BinaryPly(nodes, true));
  ScanSeeds(nodes, out);
  TileSeeds(out);
  PngSeeds(data, out / "png");
  TumSeeds(data, out / "tum_import");
  CarmenSeeds(data, out / "carmen_import");
  MeshSeeds(out / "ply_mesh");
  PathSeeds(nodes, out / "path_csv");
  PartialSumsSeeds(nodes, out / "partial_sums");
  return 0;
}
