#include "storage/import/octomap_graph_import.h"

#include <cmath>
#include <cstdint>
#include <unordered_set>
#include <vector>

#include "absl/strings/str_cat.h"
#include "storage/import/byte_reader.h"

namespace carvemap {
namespace {

using import_internal::ByteReader;

// Smallest encodings, to bound counts read from the file by the bytes left.
constexpr uint64_t kPointBytes = 4 + 3 * 8;
constexpr uint64_t kPoseBytes = (4 + 3 * 8) + (4 + 4 * 8);
constexpr uint64_t kNodeMinBytes = 4 + kPoseBytes + 4;
constexpr uint64_t kEdgeBytes = 4 + 4 + kPoseBytes + 8;

struct GraphPose {
  double t[3];
  double q[4];  // w x y z
};

// Reads and errors with "<file>: <where> at byte <offset>: <what>".
class GraphParser {
 public:
  GraphParser(const std::string& file, ByteReader reader)
      : file_(file), reader_(std::move(reader)) {}

  absl::Status Error(const std::string& where, const std::string& what, uint64_t offset) const {
    return absl::DataLossError(absl::StrCat(file_, ": ", where, " at byte ", offset, ": ", what));
  }

  absl::Status ReadU32(const std::string& where, const char* what, uint32_t& v) {
    const uint64_t at = reader_.offset();
    if (!reader_.Read(v)) return Error(where, absl::StrCat("file ends inside ", what), at);
    return absl::OkStatus();
  }

  // {int32 n; f64 × n}: OctoMap writes the vector length before its components.
  absl::Status ReadVector(const std::string& where, const char* what, int32_t n, double* out) {
    const uint64_t at = reader_.offset();
    int32_t marker = 0;
    if (!reader_.Read(marker)) return Error(where, absl::StrCat("file ends inside ", what), at);
    if (marker != n) {
      return Error(where, absl::StrCat(what, ": length marker is ", marker, ", expected ", n),
                   at);
    }
    for (int32_t i = 0; i < n; ++i) {
      if (!reader_.Read(out[i])) {
        return Error(where, absl::StrCat("file ends inside ", what), at);
      }
    }
    return absl::OkStatus();
  }

  absl::Status ReadPose(const std::string& where, GraphPose& pose) {
    const uint64_t at = reader_.offset();
    if (absl::Status s = ReadVector(where, "pose translation", 3, pose.t); !s.ok()) return s;
    if (absl::Status s = ReadVector(where, "pose rotation", 4, pose.q); !s.ok()) return s;
    if (!std::isfinite(pose.t[0]) || !std::isfinite(pose.t[1]) || !std::isfinite(pose.t[2])) {
      return Error(where, "non-finite pose translation", at);
    }
    auto q = CheckedUnitQuaternion(pose.q[0], pose.q[1], pose.q[2], pose.q[3]);
    if (!q.ok()) return Error(where, std::string(q.status().message()), at);
    for (int i = 0; i < 4; ++i) pose.q[i] = (*q)[i];
    return absl::OkStatus();
  }

  ByteReader& reader() { return reader_; }

 private:
  const std::string& file_;
  ByteReader reader_;
};

}  // namespace

SensorInfo OctomapGraphSensor(const OctomapGraphOptions& options) {
  SensorInfo info;
  info.name = "graph";
  info.kind = SensorKind::kPoints;
  info.sigma_t_s = options.sigma_t_s;
  info.range_sigma = options.range_sigma;
  info.max_range_m = options.max_range_m;
  return info;
}

absl::StatusOr<ImportedScan> ImportOctomapGraph(const std::string& file,
                                                const OctomapGraphOptions& options,
                                                const FrameSink& sink) {
  auto opened = ByteReader::Open(file);
  if (!opened.ok()) return opened.status();
  GraphParser p(file, *std::move(opened));
  ByteReader& r = p.reader();

  ImportedScan scan;
  scan.sensor = OctomapGraphSensor(options);

  uint32_t n_nodes = 0;
  if (absl::Status s = p.ReadU32("header", "the node count", n_nodes); !s.ok()) return s;
  // A scan needs poses (docs/DESIGN.md §3: /path is never empty).
  if (n_nodes == 0) return p.Error("header", "the graph has no nodes", 0);
  if (n_nodes > r.remaining() / kNodeMinBytes) {
    return p.Error("header",
                   absl::StrCat("node count ", n_nodes, " cannot fit in the ", r.remaining(),
                                " bytes left"),
                   0);
  }
  scan.path.reserve(n_nodes);

  std::unordered_set<uint32_t> ids;
  std::vector<Eigen::Vector3f> points;
  for (uint32_t k = 0; k < n_nodes; ++k) {
    const std::string where = absl::StrCat("node ", k);
    const uint64_t count_at = r.offset();
    uint32_t n_pts = 0;
    if (absl::Status s = p.ReadU32(where, "the point count", n_pts); !s.ok()) return s;
    // The rest of this node (pose, id) must fit too.
    if (r.remaining() < kPoseBytes + 4 ||
        n_pts > (r.remaining() - kPoseBytes - 4) / kPointBytes) {
      return p.Error(where,
                     absl::StrCat("point count ", n_pts, " cannot fit in the ", r.remaining(),
                                  " bytes left"),
                     count_at);
    }
    points.resize(n_pts);
    for (uint32_t i = 0; i < n_pts; ++i) {
      const uint64_t at = r.offset();
      double xyz[3];
      if (absl::Status s = p.ReadVector(where, "a point", 3, xyz); !s.ok()) return s;
      const bool all_nan = std::isnan(xyz[0]) && std::isnan(xyz[1]) && std::isnan(xyz[2]);
      if (!all_nan &&
          !(std::isfinite(xyz[0]) && std::isfinite(xyz[1]) && std::isfinite(xyz[2]))) {
        return p.Error(absl::StrCat(where, " point ", i), "non-finite coordinate", at);
      }
      points[i] = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]).cast<float>();
      // scan.h5 stores points as f32: a finite double can still overflow it.
      if (!all_nan && !points[i].allFinite()) {
        return p.Error(absl::StrCat(where, " point ", i), "coordinate beyond float range", at);
      }
    }
    GraphPose pose;
    if (absl::Status s = p.ReadPose(where, pose); !s.ok()) return s;
    const uint64_t id_at = r.offset();
    uint32_t id = 0;
    if (absl::Status s = p.ReadU32(where, "the node id", id); !s.ok()) return s;
    if (!ids.insert(id).second) {
      return p.Error(where, absl::StrCat("node id ", id, " repeats"), id_at);
    }
    const double t = static_cast<double>(k);  // synthetic: graphs have no time stamps
    scan.path.push_back(
        PathRecord{t, pose.t[0], pose.t[1], pose.t[2], pose.q[0], pose.q[1], pose.q[2], pose.q[3]});
    if (absl::Status s = EmitFrame(sink, t, points, scan); !s.ok()) return s;
  }

  // Edges: constraints between nodes. We have no use for them, but a graph whose edges do not
  // parse is not the file its writer meant.
  uint32_t n_edges = 0;
  if (absl::Status s = p.ReadU32("edge list", "the edge count", n_edges); !s.ok()) return s;
  if (n_edges > r.remaining() / kEdgeBytes) {
    return p.Error("edge list",
                   absl::StrCat("edge count ", n_edges, " cannot fit in the ", r.remaining(),
                                " bytes left"),
                   r.offset() - 4);
  }
  for (uint32_t e = 0; e < n_edges; ++e) {
    const std::string where = absl::StrCat("edge ", e);
    const uint64_t at = r.offset();
    uint32_t id1 = 0, id2 = 0;
    if (absl::Status s = p.ReadU32(where, "the first node id", id1); !s.ok()) return s;
    if (absl::Status s = p.ReadU32(where, "the second node id", id2); !s.ok()) return s;
    if (!ids.contains(id1) || !ids.contains(id2)) {
      return p.Error(where, absl::StrCat("links unknown node ids ", id1, " and ", id2), at);
    }
    GraphPose pose;
    if (absl::Status s = p.ReadPose(where, pose); !s.ok()) return s;
    const uint64_t weight_at = r.offset();
    double weight = 0;
    if (!r.Read(weight)) return p.Error(where, "file ends inside the weight", weight_at);
    if (!std::isfinite(weight)) return p.Error(where, "non-finite weight", weight_at);
  }
  if (r.remaining() != 0) {
    return p.Error("end", absl::StrCat(r.remaining(), " unexpected bytes after the last edge"),
                   r.offset());
  }
  return scan;
}

}  // namespace carvemap
