#include "storage/import/rosbag_import.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "storage/import/ros2_bag_reader.h"
#include "storage/import/rosbag_reader.h"

namespace carvemap {

absl::Status RosbagOptions::Validate() const {
  if (topics.empty()) return absl::InvalidArgumentError("rosbag import: no topic given");
  for (size_t i = 0; i < topics.size(); ++i) {
    if (topics[i].empty()) return absl::InvalidArgumentError("rosbag import: an empty topic");
    if (std::find(topics.begin(), topics.begin() + i, topics[i]) != topics.begin() + i) {
      return absl::InvalidArgumentError(
          absl::StrCat("rosbag import: topic ", topics[i], " given twice"));
    }
  }
  if (fixed_frame.empty()) return absl::InvalidArgumentError("rosbag import: no fixed frame");
  if (!(max_range_m >= 0) || !std::isfinite(max_range_m)) {
    return absl::InvalidArgumentError("rosbag import: max_range_m must be finite and >= 0");
  }
  if (!(range_sigma[0] >= 0) || !(range_sigma[1] >= 0) || !(sigma_t_s >= 0)) {
    return absl::InvalidArgumentError("rosbag import: noise figures must be >= 0");
  }
  return absl::OkStatus();
}

namespace {

// A child frame's pose in its parent (child ➜ parent).
struct Pose {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
};

// a: B in A, b: C in B ➜ C in A.
Pose Compose(const Pose& a, const Pose& b) { return {a.q * b.q, a.p + a.q * b.p}; }

// The transform tree of /tf and /tf_static: each child frame has one parent.
class TfTree {
 public:
  absl::Status Add(const RosTransform& t, bool is_static) {
    if (t.child_frame_id.empty() || t.header.frame_id.empty() ||
        t.child_frame_id == t.header.frame_id) {
      return absl::InvalidArgumentError(absl::StrCat("a transform from \"", t.header.frame_id,
                                                     "\" to \"", t.child_frame_id, "\""));
    }
    Link& link = links_[t.child_frame_id];
    if (!link.parent.empty() && link.parent != t.header.frame_id) {
      return absl::InvalidArgumentError(absl::StrCat("frame \"", t.child_frame_id,
                                                     "\" has two parents, \"", link.parent,
                                                     "\" and \"", t.header.frame_id, "\""));
    }
    link.parent = t.header.frame_id;
    const Pose pose{t.rotation, t.translation};
    if (is_static) {
      link.fixed = pose;  // the latest publication wins, as in tf2
      link.has_static = true;
    } else {
      link.samples.emplace_back(t.header.stamp, pose);
    }
    return absl::OkStatus();
  }

  // Samples in time order; a link with any /tf samples is dynamic.
  void Finish() {
    for (auto& [child, link] : links_) {
      std::stable_sort(link.samples.begin(), link.samples.end(),
                       [](const auto& a, const auto& b) { return a.first < b.first; });
    }
  }

  // `frame`'s parent; it must have one (IsStatic).
  [[nodiscard]] const std::string& Parent(const std::string& frame) const {
    return links_.at(frame).parent;
  }

  [[nodiscard]] bool IsStatic(const std::string& frame) const {
    auto it = links_.find(frame);
    return it != links_.end() && it->second.samples.empty();
  }

  // The frames from `frame` up to `ancestor`, or why there is no such chain.
  absl::StatusOr<std::vector<std::string>> Chain(const std::string& frame,
                                                 const std::string& ancestor) const {
    std::vector<std::string> chain{frame};
    while (chain.back() != ancestor) {
      auto it = links_.find(chain.back());
      if (it == links_.end()) {
        return absl::NotFoundError(absl::StrCat(
            "no /tf chain from frame \"", frame, "\" to \"", ancestor, "\": \"", chain.back(),
            "\" has no parent in /tf or /tf_static (frames with one: ", Frames(), ")"));
      }
      if (chain.size() > links_.size()) {
        return absl::InvalidArgumentError(
            absl::StrCat("the /tf frames above \"", frame, "\" form a loop"));
      }
      chain.push_back(it->second.parent);
    }
    return chain;
  }

  // `frame`'s pose in `ancestor` at time t along `chain` (from Chain); nullopt when t lies
  // outside a /tf link's samples.
  [[nodiscard]] std::optional<Pose> PoseAt(const std::vector<std::string>& chain, double t) const {
    Pose pose;
    for (size_t i = 0; i + 1 < chain.size(); ++i) {
      const Link& link = links_.at(chain[i]);
      std::optional<Pose> step = link.At(t);
      if (!step) return std::nullopt;
      pose = Compose(*step, pose);
    }
    return pose;
  }

 private:
  struct Link {
    std::string parent;
    bool has_static = false;
    Pose fixed;
    std::vector<std::pair<double, Pose>> samples;

    [[nodiscard]] std::optional<Pose> At(double t) const {
      if (samples.empty()) return fixed;
      if (t < samples.front().first || t > samples.back().first) return std::nullopt;
      auto hi = std::upper_bound(samples.begin(), samples.end(), t,
                                 [](double v, const auto& s) { return v < s.first; });
      if (hi == samples.end()) return samples.back().second;
      const auto& [t1, b] = *hi;
      const auto& [t0, a] = *(hi - 1);
      const double s = t1 > t0 ? (t - t0) / (t1 - t0) : 1.0;
      return Pose{a.q.slerp(s, b.q), a.p + s * (b.p - a.p)};
    }
  };

  [[nodiscard]] std::string Frames() const {
    std::vector<std::string> names;
    for (const auto& [child, link] : links_) names.push_back(child);
    return names.empty() ? std::string("none") : absl::StrJoin(names, ", ");
  }

  std::map<std::string, Link> links_;
};

// An error of message `m` of `file`, named by its place and topic.
absl::Status InMessage(const std::string& file, const BagMessage& m, const absl::Status& s) {
  return absl::Status(s.code(), absl::StrCat(file, ": message ", m.index, " (on ",
                                             m.connection->topic, "): ", s.message()));
}

bool IsTf(const BagConnection& c) { return c.topic == "/tf" || c.topic == "/tf_static"; }

// ROS 1 names a type "pkg/Type", ROS 2 "pkg/msg/Type".
bool IsType(const BagConnection& c, absl::string_view ros1_name) {
  if (c.type == ros1_name) return true;
  const size_t slash = ros1_name.find('/');
  return c.type == absl::StrCat(ros1_name.substr(0, slash), "/msg", ros1_name.substr(slash));
}

// A ROS 1 bag, or a ROS 2 bag in either storage.
absl::Status ReadAnyBag(const std::string& file, const BagMessageFn& fn,
                        std::vector<BagConnection>* connections = nullptr) {
  return IsRos2Bag(file) ? ReadRos2Bag(file, fn, connections) : ReadBag(file, fn, connections);
}

std::string SensorName(const std::string& topic) {
  std::string name = topic;
  while (!name.empty() && name.front() == '/') name.erase(name.begin());
  std::replace(name.begin(), name.end(), '/', '_');
  return name.empty() ? std::string("scan") : name;
}

// A message's points in the sensor frame (NaN rows: no return), beyond `max_range` too.
std::vector<Eigen::Vector3f> LaserPoints(const RosLaserScan& s, double max_range) {
  std::vector<Eigen::Vector3f> pts(s.ranges.size());
  for (size_t i = 0; i < s.ranges.size(); ++i) {
    const double r = s.ranges[i];
    if (!std::isfinite(r) || r < s.range_min || r > s.range_max || r > max_range) {
      pts[i].setConstant(std::numeric_limits<float>::quiet_NaN());
      continue;
    }
    const double a = double(s.angle_min) + double(i) * s.angle_increment;
    pts[i] = Eigen::Vector3f(float(r * std::cos(a)), float(r * std::sin(a)), 0.f);
  }
  return pts;
}

// What the first read learns of one topic.
struct TopicScan {
  bool laser = false;
  uint32_t rows = 0, cols = 0;
  double max_range = 0;  // the LaserScans' largest range_max, or the farthest point
  double last_stamp = -std::numeric_limits<double>::infinity();
};

// The index of `topic` in `topics`, or topics.size() when it is not one of them.
size_t TopicIndex(const std::vector<std::string>& topics, const std::string& topic) {
  return static_cast<size_t>(std::find(topics.begin(), topics.end(), topic) - topics.begin());
}

// A topic's sensor in scan.h5, from what the first read learnt and its static mounting.
SensorInfo TopicSensor(const std::string& topic, const TopicScan& ts, const Pose& extrinsics,
                       const RosbagOptions& options) {
  SensorInfo s;
  s.name = SensorName(topic);
  s.kind = ts.laser ? SensorKind::kLine : ts.rows > 1 ? SensorKind::kGrid : SensorKind::kPoints;
  if (s.kind == SensorKind::kGrid) {
    s.rows = ts.rows;
    s.cols = ts.cols;
  }
  s.R_s2c = extrinsics.q.toRotationMatrix();
  s.T_s2c = extrinsics.p;
  s.sigma_t_s = options.sigma_t_s;
  s.range_sigma = options.range_sigma;
  s.max_range_m = options.max_range_m > 0 ? options.max_range_m
                  : ts.max_range > 0      ? std::ceil(ts.max_range * 100) / 100
                                          : 1.0;
  return s;
}

}  // namespace

struct RosbagImport::State {
  std::string file;
  RosbagOptions options;
  std::vector<SensorInfo> sensors;  // by topic
  TfTree tf;
  std::vector<std::string> chain;  // the system frame up to the fixed frame
  RosbagReport report;             // what the first read found
};

RosbagImport::RosbagImport(std::unique_ptr<State> state) : state_(std::move(state)) {}
RosbagImport::RosbagImport(RosbagImport&&) noexcept = default;
RosbagImport& RosbagImport::operator=(RosbagImport&&) noexcept = default;
RosbagImport::~RosbagImport() = default;

const std::vector<SensorInfo>& RosbagImport::sensors() const { return state_->sensors; }

absl::StatusOr<RosbagImport> RosbagImport::Open(const std::string& file,
                                                const RosbagOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  auto st = std::make_unique<State>();
  st->file = file;
  st->options = options;
  RosbagReport& rep = st->report;
  const std::vector<std::string>& topics = options.topics;
  std::vector<TopicScan> scans(topics.size());
  for (const std::string& t : topics) rep.topics.push_back(RosbagTopicReport{t});
  std::vector<BagConnection> connections;
  absl::Status read = ReadAnyBag(
      file,
      [&](const BagMessage& m) -> absl::Status {
        const BagConnection& c = *m.connection;
        const size_t k = TopicIndex(topics, c.topic);
        const bool wanted = k < topics.size();
        if (wanted && !IsType(c, kLaserScanType) && !IsType(c, kPointCloud2Type)) {
          return absl::InvalidArgumentError(
              absl::StrCat(file, ": topic ", c.topic, " carries ", c.type,
                           "; sensor_msgs/LaserScan or sensor_msgs/PointCloud2 can be imported"));
        }
        if (!wanted && !IsTf(c)) return absl::OkStatus();
        if (c.encoding == RosEncoding::kUnknown) {
          return absl::InvalidArgumentError(absl::StrCat(
              file, ": topic ", c.topic, " is encoded neither as ROS 1 messages nor as CDR"));
        }
        // A type of the same name but another definition would be misread (ROS 1 bags say
        // which definition; ROS 2's types have not changed these fields).
        const char* md5 = c.type == kLaserScanType     ? kLaserScanMd5
                          : c.type == kPointCloud2Type ? kPointCloud2Md5
                          : c.type == kTfMessageType   ? kTfMessageMd5
                                                       : nullptr;
        if (md5 && !c.md5sum.empty() && c.md5sum != md5 && c.md5sum != "*") {
          return absl::InvalidArgumentError(absl::StrCat(file, ": topic ", c.topic, " says ",
                                                         c.type, " with definition MD5 ", c.md5sum,
                                                         ", not the ", md5, " this reader knows"));
        }
        if (IsTf(c)) {
          if (!IsType(c, kTfMessageType)) return absl::OkStatus();
          absl::StatusOr<std::vector<RosTransform>> tfs = DecodeTfMessage(m.data, c.encoding);
          if (!tfs.ok()) return InMessage(file, m, tfs.status());
          for (const RosTransform& t : *tfs) {
            if (absl::Status s = st->tf.Add(t, c.topic == "/tf_static"); !s.ok()) {
              return InMessage(file, m, s);
            }
            ++rep.transforms;
          }
          return absl::OkStatus();
        }
        TopicScan& ts = scans[k];
        RosbagTopicReport& tr = rep.topics[k];
        const bool laser = IsType(c, kLaserScanType);
        tr.message_type = c.type;
        RosHeader header;
        uint32_t r = 0, n = 0;
        if (laser) {
          absl::StatusOr<RosLaserScan> s = DecodeLaserScan(m.data, c.encoding);
          if (!s.ok()) return InMessage(file, m, s.status());
          header = s->header;
          r = 1;
          n = static_cast<uint32_t>(s->ranges.size());
          if (std::isfinite(s->range_max))
            ts.max_range = std::max<double>(ts.max_range, s->range_max);
        } else {
          // The points are read here only to find the farthest when no range is given.
          absl::StatusOr<RosPointCloud> s =
              DecodePointCloud2(m.data, c.encoding, options.max_range_m <= 0);
          if (!s.ok()) return InMessage(file, m, s.status());
          header = s->header;
          r = s->height;
          n = s->width;
          for (const Eigen::Vector3f& p : s->points) {
            if (!p.allFinite()) continue;
            const double range = p.cast<double>().norm();
            // No scanner reaches 100 km: such a point is garbage, and would make every ray of
            // the sensor that long.
            if (!(range < 1e5)) {
              return InMessage(file, m,
                               absl::InvalidArgumentError(absl::StrCat(
                                   "a point lies ", range,
                                   " m from the sensor; give "
                                   "--max-range to take farther points as no return")));
            }
            ts.max_range = std::max(ts.max_range, range);
          }
        }
        if (tr.messages == 0) {
          tr.sensor_frame = header.frame_id;
          ts.laser = laser;
          ts.rows = r;
          ts.cols = n;
        } else if (header.frame_id != tr.sensor_frame) {
          return InMessage(file, m,
                           absl::InvalidArgumentError(absl::StrCat(
                               "frame \"", header.frame_id, "\" where the first message had \"",
                               tr.sensor_frame, "\"")));
        } else if ((laser || ts.rows > 1 || r > 1) && (r != ts.rows || n != ts.cols)) {
          return InMessage(file, m,
                           absl::InvalidArgumentError(absl::StrCat(
                               r, " × ", n, " rays where the first message had ", ts.rows, " × ",
                               ts.cols, " (every frame of a line or grid sensor has the same)")));
        }
        if (!(header.stamp > ts.last_stamp)) {
          return InMessage(
              file, m,
              absl::InvalidArgumentError(absl::StrCat(
                  "stamp ", header.stamp, " s is not after the previous ", ts.last_stamp, " s")));
        }
        ts.last_stamp = header.stamp;
        ++tr.messages;
        return absl::OkStatus();
      },
      &connections);
  if (!read.ok()) return read;
  for (const RosbagTopicReport& tr : rep.topics) {
    if (tr.messages > 0) continue;
    std::vector<std::string> listed;
    for (const BagConnection& c : connections) {
      listed.push_back(absl::StrCat(c.topic, " (", c.type, ")"));
    }
    return absl::NotFoundError(absl::StrCat(
        file, ": no messages on topic ", tr.topic,
        "; the bag's topics: ", listed.empty() ? "none" : absl::StrJoin(listed, ", ")));
  }
  st->tf.Finish();
  // The system frame: the highest frame above a sensor's joined to it by /tf_static only, the
  // same for every topic (one body carries them all).
  std::string base = options.base_frame;
  if (base.empty()) {
    for (const RosbagTopicReport& tr : rep.topics) {
      std::string up = tr.sensor_frame;
      for (size_t n = 0; up != options.fixed_frame && st->tf.IsStatic(up) && n < rep.transforms;
           ++n) {
        up = st->tf.Parent(up);
      }
      if (base.empty()) {
        base = up;
      } else if (up != base) {
        return absl::InvalidArgumentError(
            absl::StrCat(file, ": topic ", rep.topics.front().topic, " hangs from \"", base,
                         "\" and topic ", tr.topic, " from \"", up,
                         "\" by /tf_static: name the system frame that carries "
                         "them all (--base-frame)"));
      }
    }
  }
  rep.base_frame = base;
  for (size_t k = 0; k < topics.size(); ++k) {
    const std::string& frame = rep.topics[k].sensor_frame;
    absl::StatusOr<std::vector<std::string>> mount = st->tf.Chain(frame, base);
    if (!mount.ok()) {
      return absl::Status(mount.status().code(),
                          absl::StrCat(file, ": ", mount.status().message()));
    }
    for (size_t i = 0; i + 1 < mount->size(); ++i) {
      if (!st->tf.IsStatic((*mount)[i])) {
        return absl::InvalidArgumentError(absl::StrCat(
            file, ": the system frame \"", base, "\" is not joined to the sensor's frame \"", frame,
            "\" by /tf_static only (\"", (*mount)[i], "\" moves in /tf)"));
      }
    }
    st->sensors.push_back(TopicSensor(topics[k], scans[k], *st->tf.PoseAt(*mount, 0.0), options));
  }
  absl::StatusOr<std::vector<std::string>> path = st->tf.Chain(base, options.fixed_frame);
  if (!path.ok()) {
    return absl::Status(path.status().code(), absl::StrCat(file, ": ", path.status().message()));
  }
  st->chain = *std::move(path);
  return RosbagImport(std::move(st));
}

absl::StatusOr<std::vector<PathRecord>> RosbagImport::Run(const SensorFrameSink& sink,
                                                          RosbagReport* report) const {
  const State& st = *state_;
  const std::vector<std::string>& topics = st.options.topics;
  RosbagReport rep = st.report;
  std::vector<PathRecord> path;
  std::vector<uint64_t> frames(topics.size(), 0);
  absl::Status read = ReadAnyBag(st.file, [&](const BagMessage& m) -> absl::Status {
    const size_t k = TopicIndex(topics, m.connection->topic);
    if (k == topics.size()) return absl::OkStatus();
    const SensorInfo& sensor = st.sensors[k];
    RosbagTopicReport& tr = rep.topics[k];
    RosHeader header;
    std::vector<Eigen::Vector3f> pts;
    if (sensor.kind == SensorKind::kLine) {
      absl::StatusOr<RosLaserScan> s = DecodeLaserScan(m.data, m.connection->encoding);
      if (!s.ok()) return InMessage(st.file, m, s.status());
      header = s->header;
      pts = LaserPoints(*s, sensor.max_range_m);
    } else {
      absl::StatusOr<RosPointCloud> s = DecodePointCloud2(m.data, m.connection->encoding);
      if (!s.ok()) return InMessage(st.file, m, s.status());
      header = s->header;
      pts = std::move(s->points);
      for (Eigen::Vector3f& p : pts) {
        if (p.allFinite() && p.norm() > sensor.max_range_m) {
          p.setConstant(std::numeric_limits<float>::quiet_NaN());
        }
      }
    }
    const std::optional<Pose> pose = st.tf.PoseAt(st.chain, header.stamp);
    if (!pose) {
      ++tr.skipped_outside_tf;
      return absl::OkStatus();
    }
    for (const Eigen::Vector3f& p : pts) tr.no_return_rays += !p.allFinite();
    path.push_back({header.stamp, pose->p.x(), pose->p.y(), pose->p.z(), pose->q.w(), pose->q.x(),
                    pose->q.y(), pose->q.z()});
    ++frames[k];
    return sink ? sink(static_cast<int>(k), header.stamp, pts) : absl::OkStatus();
  });
  if (!read.ok()) return read;
  for (size_t k = 0; k < topics.size(); ++k) {
    if (frames[k] > 0) continue;
    return absl::OutOfRangeError(
        absl::StrCat(st.file, ": all ", rep.topics[k].messages, " messages on ", topics[k],
                     " lie outside the time spans of the /tf links from \"", rep.base_frame,
                     "\" to \"", st.options.fixed_frame, "\""));
  }
  // One row per distinct frame time: topics interleave in the bag by arrival, not by stamp,
  // and frames of two topics at one stamp share the system's pose there.
  std::stable_sort(path.begin(), path.end(),
                   [](const PathRecord& a, const PathRecord& b) { return a.t < b.t; });
  path.erase(std::unique(path.begin(), path.end(),
                         [](const PathRecord& a, const PathRecord& b) { return a.t == b.t; }),
             path.end());
  if (report) *report = rep;
  return path;
}

}  // namespace carvemap
