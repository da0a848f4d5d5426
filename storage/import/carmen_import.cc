#include "storage/import/carmen_import.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"

namespace carvemap {
namespace {

// A log line longer than this is not a CARMEN message (the longest, a ROBOTLASER with 1081
// readings and remissions, is about 20 kB); the bound keeps a corrupt file from filling memory.
constexpr size_t kMaxLineBytes = size_t{1} << 20;

// Lines of a plain or gzip-compressed text file (zlib reads plain files as they are).
class LineReader {
 public:
  explicit LineReader(std::string path) : path_(std::move(path)) {}
  ~LineReader() {
    if (file_) gzclose(file_);
  }
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  absl::Status Open() {
    file_ = gzopen(path_.c_str(), "rb");
    if (!file_) return absl::NotFoundError(absl::StrCat(path_, ": cannot open"));
    return absl::OkStatus();
  }

  // The next line without its end of line; false at the end of the file.
  absl::StatusOr<bool> Next(std::string& line) {
    line.clear();
    for (;;) {
      if (pos_ == buffer_.size()) {
        if (eof_) {
          if (line.empty()) return false;
          ++line_number_;
          return true;
        }
        buffer_.resize(1 << 16);
        const int n = gzread(file_, buffer_.data(), static_cast<unsigned>(buffer_.size()));
        if (n < 0) return Corrupt();
        buffer_.resize(static_cast<size_t>(n));
        pos_ = 0;
        if (n == 0) {
          // gzread returns 0 both at the true end and where compressed data stops early.
          int error = Z_OK;
          gzerror(file_, &error);
          if (error != Z_OK && error != Z_STREAM_END) return Corrupt();
          eof_ = true;
        }
        continue;
      }
      const size_t newline = buffer_.find('\n', pos_);
      const size_t end = newline == std::string::npos ? buffer_.size() : newline;
      line.append(buffer_, pos_, end - pos_);
      pos_ = newline == std::string::npos ? buffer_.size() : newline + 1;
      if (line.size() > kMaxLineBytes) {
        return absl::InvalidArgumentError(absl::StrCat(path_, ": line ", line_number_ + 1,
                                                       ": longer than ", kMaxLineBytes,
                                                       " bytes: not a CARMEN log"));
      }
      if (newline != std::string::npos) {
        ++line_number_;
        return true;
      }
    }
  }

  [[nodiscard]] int line_number() const { return line_number_; }

 private:
  absl::Status Corrupt() {
    int error = Z_OK;
    const char* message = gzerror(file_, &error);
    return absl::DataLossError(absl::StrCat(path_, ": after line ", line_number_,
                                            ": compressed data is corrupt or cut short (",
                                            message ? message : "zlib error", ")"));
  }

  std::string path_;
  gzFile file_ = nullptr;
  std::string buffer_;
  size_t pos_ = 0;
  bool eof_ = false;
  int line_number_ = 0;
};

enum class Kind { kOther, kOldPosed, kRobotLaser, kRawLaser, kOdom };

struct MessageType {
  Kind kind = Kind::kOther;
  int laser = 0;  // 1..4 for laser messages
};

MessageType Classify(absl::string_view word) {
  if (word == "FLASER") return {Kind::kOldPosed, 1};
  if (word == "RLASER") return {Kind::kOldPosed, 2};
  if (word == "ODOM") return {Kind::kOdom, 0};
  for (const auto& [prefix, kind] : {std::pair{absl::string_view("ROBOTLASER"), Kind::kRobotLaser},
                                     std::pair{absl::string_view("RAWLASER"), Kind::kRawLaser}}) {
    if (word.size() == prefix.size() + 1 && absl::StartsWith(word, prefix)) {
      const char id = word.back();
      if (id >= '1' && id <= '4') return {kind, id - '0'};
    }
  }
  return {};
}

// One parsed laser line: beam angles relative to the laser's heading, and its pose if the
// message carries one.
struct LaserLine {
  double t = 0;
  double start_angle = 0, step = 0;
  double max_range = 0;  // the line's own; 0 = none given
  std::vector<double> ranges;
  bool has_pose = false;
  double x = 0, y = 0, theta = 0;
};

class LineParser {
 public:
  LineParser(const std::string& file, int line, std::vector<absl::string_view> tokens)
      : where_(absl::StrCat(file, ": line ", line, ": ")), tok_(std::move(tokens)) {}

  absl::Status Error(absl::string_view what) const {
    return absl::InvalidArgumentError(absl::StrCat(where_, tok_[0], ": ", what));
  }

  absl::StatusOr<double> Number(size_t i) const {
    double v = 0;
    if (!absl::SimpleAtod(tok_[i], &v) || !std::isfinite(v)) {
      return Error(
          absl::StrCat("field ", i + 1, " '", tok_[i].substr(0, 40), "' is not a finite number"));
    }
    return v;
  }

  // A count field; it must be small enough that its items could fit in the line at all.
  absl::StatusOr<size_t> Count(size_t i, absl::string_view what) const {
    int64_t v = 0;
    if (!absl::SimpleAtoi(tok_[i], &v) || v < 0) {
      return Error(absl::StrCat("field ", i + 1, " (", what, ") '", tok_[i].substr(0, 40),
                                "' is not a count"));
    }
    if (static_cast<uint64_t>(v) > tok_.size()) {
      return Error(absl::StrCat("says ", v, " ", what, " but the line has only ", tok_.size(),
                                " fields: cut short or wrong count"));
    }
    return static_cast<size_t>(v);
  }

  absl::StatusOr<LaserLine> Parse(Kind kind) const {
    switch (kind) {
      case Kind::kOldPosed:
        return ParseOld();
      case Kind::kRobotLaser:
        return ParseNew(/*tail=*/14, /*has_pose=*/true);
      case Kind::kRawLaser:
        return ParseNew(/*tail=*/3, /*has_pose=*/false);
      default:
        return Error("not a laser message");
    }
  }

  // ODOM x y theta tv rv accel timestamp host logger_timestamp (logger_timestamp may be
  // missing in old logs).
  absl::StatusOr<PathRecord> ParseOdom() const {
    if (tok_.size() != 10 && tok_.size() != 9) {
      return Error(
          absl::StrCat("expected 'ODOM x y theta tv rv accel timestamp host "
                       "logger_timestamp' (10 fields), found ",
                       tok_.size()));
    }
    double v[7];
    for (size_t i = 0; i < 7; ++i) {
      auto n = Number(i + 1);
      if (!n.ok()) return n.status();
      v[i] = *n;
    }
    return Pose(v[6], v[0], v[1], v[2]);
  }

  static PathRecord Pose(double t, double x, double y, double theta) {
    return PathRecord{t, x, y, 0.0, std::cos(theta / 2), 0.0, 0.0, std::sin(theta / 2)};
  }

 private:
  absl::Status ReadRanges(size_t first, size_t n, LaserLine& out) const {
    out.ranges.resize(n);
    for (size_t i = 0; i < n; ++i) {
      auto r = Number(first + i);
      if (!r.ok()) return r.status();
      if (*r < 0) return Error(absl::StrCat("reading ", i + 1, " is negative (", *r, ")"));
      out.ranges[i] = *r;
    }
    return absl::OkStatus();
  }

  absl::StatusOr<LaserLine> ParseOld() const {
    if (tok_.size() < 2) return Error("cut short: no count of readings");
    auto n = Count(1, "readings");
    if (!n.ok()) return n.status();
    // n readings, 6 pose values, timestamp, host and (in all but the oldest logs)
    // logger_timestamp.
    const size_t full = *n + 11;
    // Without logger_timestamp the line ends with the host, which is a name: a line one
    // reading short of its count would otherwise pass as one.
    double number;
    const bool short_form = tok_.size() == full - 1 && !absl::SimpleAtod(tok_.back(), &number);
    if (tok_.size() != full && !short_form) {
      return Error(absl::StrCat("says ", *n, " readings, so the line should have ", full,
                                " fields (", full - 1, " without logger_timestamp); it has ",
                                tok_.size(), ": cut short or wrong count of readings"));
    }
    LaserLine out;
    if (*n == 180 || *n == 360) {
      out.step = std::numbers::pi / double(*n);
    } else if (*n == 181 || *n == 361) {
      out.step = std::numbers::pi / double(*n - 1);
    } else {
      return Error(absl::StrCat(*n,
                                " readings: the beam angles of the old format are known "
                                "only for 180, 181, 360 or 361 readings"));
    }
    out.start_angle = -std::numbers::pi / 2;
    if (absl::Status s = ReadRanges(2, *n, out); !s.ok()) return s;
    double v[7];
    for (size_t i = 0; i < 7; ++i) {
      // x y theta odom_x odom_y odom_theta timestamp: all checked, the odometry unused.
      auto x = Number(2 + *n + i);
      if (!x.ok()) return x.status();
      v[i] = *x;
    }
    out.has_pose = true;
    out.x = v[0], out.y = v[1], out.theta = v[2];
    out.t = v[6];
    return out;
  }

  // RAWLASER / ROBOTLASER: `tail` fields follow the remissions (ROBOTLASER: 6 pose values,
  // 5 motion values, then timestamp host logger_timestamp; RAWLASER: the last 3).
  absl::StatusOr<LaserLine> ParseNew(size_t tail, bool has_pose) const {
    // The newer loggers write 7 configuration fields (with remission_mode), older ones 6; the
    // layout whose counts add up to the line's length is the line's.
    std::optional<absl::Status> first_error;
    for (size_t config : {size_t{7}, size_t{6}}) {
      const size_t n_at = 1 + config;
      if (tok_.size() <= n_at) continue;
      auto n = Count(n_at, "readings");
      if (!n.ok()) {
        if (!first_error) first_error = n.status();
        continue;
      }
      const size_t m_at = n_at + 1 + *n;
      if (tok_.size() <= m_at) {
        if (!first_error) {
          first_error = Error(absl::StrCat("says ", *n, " readings but the line ends after ",
                                           tok_.size(), " fields: cut short or wrong count"));
        }
        continue;
      }
      auto m = Count(m_at, "remissions");
      if (!m.ok()) {
        if (!first_error) first_error = m.status();
        continue;
      }
      const size_t expected = m_at + 1 + *m + tail;
      if (tok_.size() != expected) {
        if (!first_error) {
          first_error = Error(absl::StrCat(
              "says ", *n, " readings and ", *m, " remissions, so the line should have ", expected,
              " fields; it has ", tok_.size(), ": cut short or wrong count"));
        }
        continue;
      }
      return ParseNewLayout(config, *n, *m, has_pose);
    }
    return first_error ? *first_error : Error("cut short: no count of readings");
  }

  absl::StatusOr<LaserLine> ParseNewLayout(size_t config, size_t n, size_t m, bool has_pose) const {
    LaserLine out;
    double c[5];  // start_angle fov resolution max_range accuracy
    for (size_t i = 0; i < 5; ++i) {
      auto v = Number(2 + i);
      if (!v.ok()) return v.status();
      c[i] = *v;
    }
    if (n == 0) return Error("no readings");
    out.start_angle = c[0];
    out.step = c[2];
    out.max_range = c[3];
    if (!(std::abs(out.step) > 0)) return Error("angular resolution is 0");
    const size_t first = 2 + config;
    if (absl::Status s = ReadRanges(first, n, out); !s.ok()) return s;
    for (size_t i = 0; i < m; ++i) {
      if (auto v = Number(first + n + 1 + i); !v.ok()) return v.status();
    }
    const size_t after = first + n + 1 + m;
    if (has_pose) {
      double v[11];
      for (size_t i = 0; i < 11; ++i) {
        auto x = Number(after + i);
        if (!x.ok()) return x.status();
        v[i] = *x;
      }
      out.has_pose = true;
      out.x = v[0], out.y = v[1], out.theta = v[2];  // the laser's pose
    }
    auto t = Number(tok_.size() - 3);
    if (!t.ok()) return t.status();
    out.t = *t;
    return out;
  }

  std::string where_;
  std::vector<absl::string_view> tok_;
};

std::vector<absl::string_view> Tokens(const std::string& text) {
  return absl::StrSplit(text, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
}

const char* LaserName(int laser) {
  switch (laser) {
    case 1:
      return "front";
    case 2:
      return "rear";
    case 3:
      return "laser3";
    default:
      return "laser4";
  }
}

// The message types that carry laser `laser`, for error messages.
std::string LaserTypes(int laser) {
  const char* old = laser == 1 ? "FLASER, " : laser == 2 ? "RLASER, " : "";
  return absl::StrCat(LaserName(laser), ": ", old, "ROBOTLASER", laser, " or RAWLASER", laser);
}

struct PendingFrame {
  double t;
  std::vector<Eigen::Vector3f> points;
};

}  // namespace

absl::Status CarmenOptions::Validate() const {
  if (laser < 1 || laser > 4) return absl::InvalidArgumentError("carmen: laser must be 1..4");
  if (!std::isfinite(height_m)) return absl::InvalidArgumentError("carmen: height must be finite");
  if (!(max_range_m > 0) || !std::isfinite(max_range_m)) {
    return absl::InvalidArgumentError("carmen: max_range must be positive");
  }
  if (!(range_sigma[0] >= 0 && range_sigma[1] >= 0 && sigma_t_s >= 0)) {
    return absl::InvalidArgumentError("carmen: noise parameters must be >= 0");
  }
  return absl::OkStatus();
}

SensorInfo CarmenSensor(const CarmenOptions& options) {
  SensorInfo info;
  info.name = LaserName(options.laser);
  info.kind = SensorKind::kLine;
  info.T_s2c = Eigen::Vector3d(0, 0, options.height_m);
  info.sigma_t_s = options.sigma_t_s;
  info.range_sigma = options.range_sigma;
  info.max_range_m = options.max_range_m;
  return info;
}

absl::StatusOr<ImportedScan> ImportCarmen(const std::string& file, const CarmenOptions& options,
                                          const FrameSink& sink, CarmenReport* report) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  CarmenReport local_report;
  CarmenReport& rep = report ? *report : local_report;
  rep = CarmenReport{};

  // First pass: which message types carry this laser. A log may hold the same scans twice
  // (RAWLASER and ROBOTLASER), so the frames come from one type.
  std::string text;
  std::optional<std::string> posed_type, raw_type;
  std::vector<std::string> other_lasers;
  {
    LineReader reader(file);
    if (absl::Status s = reader.Open(); !s.ok()) return s;
    for (;;) {
      auto more = reader.Next(text);
      if (!more.ok()) return more.status();
      if (!*more) break;
      // The first word, found as the second pass's tokens find it.
      const size_t begin = std::min(text.find_first_not_of(" \t\r"), text.size());
      const size_t end = std::min(text.find_first_of(" \t\r", begin), text.size());
      const absl::string_view word = absl::string_view(text).substr(begin, end - begin);
      const MessageType type = Classify(word);
      if (type.kind == Kind::kOther || type.kind == Kind::kOdom) continue;
      if (type.laser != options.laser) {
        if (other_lasers.size() < 8 &&
            std::find(other_lasers.begin(), other_lasers.end(), word) == other_lasers.end()) {
          other_lasers.emplace_back(word);
        }
        continue;
      }
      if (type.kind == Kind::kRawLaser) {
        if (!raw_type) raw_type = std::string(word);
      } else if (!posed_type) {
        posed_type = std::string(word);
      }
    }
  }
  if (!posed_type && !raw_type) {
    std::string others;
    for (const std::string& o : other_lasers)
      absl::StrAppend(&others, others.empty() ? "" : " ", o);
    return absl::InvalidArgumentError(absl::StrCat(
        file, ": no lines of laser ", options.laser, " (", LaserTypes(options.laser), ")",
        others.empty() ? std::string(" and no other laser lines")
                       : absl::StrCat("; the log has ", others)));
  }
  const bool posed = posed_type.has_value();
  const std::string& laser_type = posed ? *posed_type : *raw_type;
  rep.laser_message = laser_type;
  rep.pose_message = posed ? laser_type : "ODOM";

  ImportedScan scan;
  scan.sensor = CarmenSensor(options);
  LineReader reader(file);
  if (absl::Status s = reader.Open(); !s.ok()) return s;

  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::optional<size_t> beams;
  double last_laser_t = 0, last_odom_t = 0;
  int last_laser_line = 0, last_odom_line = 0;
  std::deque<PendingFrame> pending;  // RAWLASER frames waiting for an ODOM pose after them
  std::vector<Eigen::Vector3f> points;

  // A time must come after the previous one of its kind; otherwise an error, or the line is
  // skipped if the options say so.
  auto check_time = [&](double t, double& last_t, int& last_line, int line,
                        absl::string_view what) -> absl::StatusOr<bool> {
    if (last_line == 0 || t > last_t) {
      last_t = t;
      last_line = line;
      return true;
    }
    if (options.skip_backward_times) {
      if (rep.skipped_backward++ == 0) rep.first_skipped_line = line;
      return false;
    }
    return absl::InvalidArgumentError(
        absl::StrCat(file, ": line ", line, ": ", what, " time ", t,
                     " is not after the previous one's ", last_t, " (line ", last_line,
                     "); times must increase (--skip-backward-times skips "
                     "such lines)"));
  };

  auto emit = [&](double t, std::span<const Eigen::Vector3f> frame) {
    return EmitFrame(sink, t, frame, scan);
  };

  for (;;) {
    auto more = reader.Next(text);
    if (!more.ok()) return more.status();
    if (!*more) break;
    const int line = reader.line_number();
    std::vector<absl::string_view> tok = Tokens(text);
    if (tok.empty() || tok[0][0] == '#') continue;
    const MessageType type = Classify(tok[0]);
    if (type.kind == Kind::kOther) continue;
    const LineParser parser(file, line, tok);

    if (type.kind == Kind::kOdom) {
      if (posed) continue;
      auto pose = parser.ParseOdom();
      if (!pose.ok()) return pose.status();
      auto keep = check_time(pose->t, last_odom_t, last_odom_line, line, "ODOM");
      if (!keep.ok()) return keep.status();
      if (!*keep) continue;
      scan.path.push_back(*pose);
      while (!pending.empty() && pending.front().t <= pose->t) {
        if (absl::Status s = emit(pending.front().t, pending.front().points); !s.ok()) return s;
        pending.pop_front();
      }
      continue;
    }
    if (type.laser != options.laser) continue;
    if (tok[0] != laser_type) {
      ++rep.ignored_laser_lines;
      continue;
    }

    auto laser = parser.Parse(type.kind);
    if (!laser.ok()) return laser.status();
    if (beams && laser->ranges.size() != *beams) {
      return parser.Error(absl::StrCat(laser->ranges.size(),
                                       " readings, but the earlier lines "
                                       "of this laser have ",
                                       *beams));
    }
    beams = laser->ranges.size();
    auto keep = check_time(laser->t, last_laser_t, last_laser_line, line, laser_type);
    if (!keep.ok()) return keep.status();
    if (!*keep) continue;

    const double max_range = laser->max_range > 0 ? std::min(laser->max_range, options.max_range_m)
                                                  : options.max_range_m;
    points.resize(laser->ranges.size());
    for (size_t i = 0; i < laser->ranges.size(); ++i) {
      const double r = laser->ranges[i];
      if (r <= 0 || r >= max_range) {
        points[i].setConstant(nan);
        ++rep.no_return_rays;
        continue;
      }
      const double a = laser->start_angle + double(i) * laser->step;
      points[i] = Eigen::Vector3f(float(r * std::cos(a)), float(r * std::sin(a)), 0.0f);
    }

    if (posed) {
      scan.path.push_back(LineParser::Pose(laser->t, laser->x, laser->y, laser->theta));
      if (absl::Status s = emit(laser->t, points); !s.ok()) return s;
    } else if (scan.path.empty() || laser->t < scan.path.front().t) {
      ++rep.skipped_outside_poses;
    } else if (laser->t <= scan.path.back().t) {
      if (absl::Status s = emit(laser->t, points); !s.ok()) return s;
    } else {
      pending.push_back(PendingFrame{laser->t, points});
    }
  }
  rep.skipped_outside_poses += pending.size();

  if (!posed && scan.path.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(file, ": ", laser_type,
                     " lines carry no pose and there are no ODOM lines to take one from"));
  }
  if (scan.frame_count == 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(file, ": no ", laser_type, " scan was kept",
                     posed ? "" : " (none lies within the ODOM lines' time span)"));
  }
  return scan;
}

}  // namespace carvemap
