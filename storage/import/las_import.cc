#include "storage/import/las_import.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <span>
#include <utility>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "storage/import/las_reader.h"

namespace carvemap {

absl::Status LasImportOptions::Validate() const {
  if (trajectory.empty()) {
    return absl::InvalidArgumentError("import las: a trajectory file is required (--trajectory)");
  }
  if (!(frame_seconds > 0) || !std::isfinite(frame_seconds)) {
    return absl::InvalidArgumentError(
        absl::StrCat("import las: --frame-seconds ", frame_seconds, " (need > 0)"));
  }
  return ValidateCloudOptions("import las", max_range_m, range_sigma, shift);
}

absl::StatusOr<std::vector<TimedPose>> ReadTrajectoryText(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  std::vector<TimedPose> poses;
  std::string line;
  for (uint64_t n = 1; std::getline(in, line); ++n) {
    const absl::string_view l = absl::StripAsciiWhitespace(line);
    if (l.empty() || l.front() == '#') continue;
    std::vector<absl::string_view> cols =
        absl::StrSplit(l, absl::ByAnyChar(" \t,"), absl::SkipEmpty());
    double v[8];
    bool numbers = cols.size() >= 8;
    for (int i = 0; numbers && i < 8; ++i) numbers = absl::SimpleAtod(cols[i], &v[i]);
    if (!numbers) {
      if (poses.empty() && n == 1) continue;  // a header line
      return absl::InvalidArgumentError(absl::StrCat(
          path, ": line ", n, ": not eight numbers (time x y z qx qy qz qw): \"", l, "\""));
    }
    absl::StatusOr<Eigen::Vector4d> q = CheckedUnitQuaternion(v[7], v[4], v[5], v[6]);
    if (!q.ok() || !std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]) ||
        !std::isfinite(v[3])) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": line ", n, ": not finite, or (qx qy qz qw) not a unit quaternion"));
    }
    if (!poses.empty() && !(v[0] > poses.back().t)) {
      return absl::InvalidArgumentError(absl::StrCat(
          path, ": line ", n, ": time ", v[0], " is not after the previous ", poses.back().t));
    }
    TimedPose p;
    p.t = v[0];
    p.pose.translation = Eigen::Vector3d(v[1], v[2], v[3]);
    p.pose.rotation = Eigen::Quaterniond((*q)[0], (*q)[1], (*q)[2], (*q)[3]);
    poses.push_back(p);
  }
  if (poses.size() < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": ", poses.size(), " poses; a trajectory needs at least two"));
  }
  return poses;
}

struct LasImport::State {
  std::string file;
  LasImportOptions options;
  std::vector<TimedPose> trajectory;  // shifted
  SensorInfo sensor;
  LasReport report;
};

namespace {

// One pass over the points: frames of `frame_seconds` in time order, each point in the sensor
// frame of its frame's pose. `emit` (when set) receives each frame with its pose; the pass
// returns the farthest range.
using FrameFn =
    std::function<absl::Status(double t, const Pose& pose, std::span<const Eigen::Vector3f>)>;

absl::StatusOr<double> Walk(const LasImport::State& st, LasReport& rep, const FrameFn& emit) {
  absl::StatusOr<LasReader> reader = LasReader::Open(st.file);
  if (!reader.ok()) return reader.status();
  const double t0 = st.trajectory.front().t, t1 = st.trajectory.back().t;
  const Eigen::Vector3d shift = rep.shift;
  std::vector<LasPoint> batch;
  std::vector<Eigen::Vector3f> frame;
  double frame_t = 0, last_t = -std::numeric_limits<double>::infinity(), farthest = 0;
  bool open = false;
  Pose pose, inverse;
  auto flush = [&]() -> absl::Status {
    if (!open) return absl::OkStatus();
    open = false;
    return emit ? emit(frame_t, pose, frame) : absl::OkStatus();
  };
  while (true) {
    const uint64_t first = reader->next_index();
    if (absl::Status s = reader->Next(batch); !s.ok()) return s;
    if (batch.empty()) break;
    for (size_t i = 0; i < batch.size(); ++i) {
      const LasPoint& p = batch[i];
      const uint64_t index = first + i;
      if (!std::isfinite(p.t)) {
        return absl::InvalidArgumentError(
            absl::StrCat(st.file, ": point ", index, " has a GPS time that is not a number"));
      }
      if (p.t < last_t) {
        return absl::InvalidArgumentError(
            absl::StrCat(st.file, ": point ", index, " at GPS time ", p.t, " s comes before point ",
                         index - 1, " at ", last_t, " s: the points are not in time order"));
      }
      last_t = p.t;
      if (p.t < t0 || p.t > t1) {
        if (st.options.skip_outside_trajectory) {
          ++rep.skipped_outside_trajectory;
          continue;
        }
        return absl::OutOfRangeError(
            absl::StrCat(st.file, ": point ", index, " at GPS time ", p.t,
                         " s lies outside the trajectory ", st.options.trajectory, " (", t0, " to ",
                         t1, " s; --skip-outside-trajectory drops such points)"));
      }
      // p.t > frame_t too: at times so large that frame_seconds is below their resolution,
      // t + frame_seconds == t, and every point would open a frame at the same time.
      if (!open || (p.t >= frame_t + st.options.frame_seconds && p.t > frame_t)) {
        if (absl::Status s = flush(); !s.ok()) return s;
        open = true;
        frame_t = p.t;
        frame.clear();
        pose = PoseAtTime(st.trajectory, frame_t);
        inverse = pose.Inverse();
      }
      const Eigen::Vector3d local = inverse * (p.p - shift);
      // No scanner reaches 100 km: farther, the trajectory or the coordinates are wrong (and
      // float32 would lose the point).
      if (!(local.norm() < 1e5)) {
        return absl::InvalidArgumentError(absl::StrCat(
            st.file, ": point ", index, " lies ", local.norm(),
            " m from the trajectory's pose at its time (is the trajectory in the LAS frame?)"));
      }
      farthest = std::max(farthest, local.norm());
      frame.push_back(local.cast<float>());
    }
  }
  if (absl::Status s = flush(); !s.ok()) return s;
  return farthest;
}

}  // namespace

LasImport::LasImport(std::unique_ptr<State> state) : state_(std::move(state)) {}
LasImport::LasImport(LasImport&&) noexcept = default;
LasImport& LasImport::operator=(LasImport&&) noexcept = default;
LasImport::~LasImport() = default;

const SensorInfo& LasImport::sensor() const { return state_->sensor; }

absl::StatusOr<LasImport> LasImport::Open(const std::string& file,
                                          const LasImportOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  absl::StatusOr<LasReader> reader = LasReader::Open(file);
  if (!reader.ok()) return reader.status();
  const LasHeader& h = reader->header();
  if (!h.has_gps_time()) {
    return absl::InvalidArgumentError(absl::StrCat(
        file, ": point data format ", int(h.point_format),
        " carries no GPS time, so the trajectory cannot place the points' origins (formats 1 and "
        "3–10 carry it)"));
  }
  auto st = std::make_unique<State>();
  st->file = file;
  st->options = options;
  absl::StatusOr<std::vector<TimedPose>> trajectory = ReadTrajectoryText(options.trajectory);
  if (!trajectory.ok()) return trajectory.status();
  LasReport& rep = st->report;
  rep.version_minor = h.version_minor;
  rep.point_format = h.point_format;
  rep.points = h.point_count;
  const Eigen::Vector3d first = trajectory->front().pose.translation;
  rep.shift = CloudShift(options.shift, first);
  st->trajectory = *std::move(trajectory);
  for (TimedPose& p : st->trajectory) p.pose.translation -= rep.shift;

  LasReport first_pass = rep;
  uint64_t frames = 0;
  absl::StatusOr<double> farthest =
      Walk(*st, first_pass, [&](double, const Pose&, std::span<const Eigen::Vector3f>) {
        ++frames;
        return absl::OkStatus();
      });
  if (!farthest.ok()) return farthest.status();
  if (frames == 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        file, ": no points",
        first_pass.skipped_outside_trajectory > 0 ? " within the trajectory" : "", " to import"));
  }
  SensorInfo& s = st->sensor;
  s.name = "las";
  s.kind = SensorKind::kPoints;
  s.R_s2c = Eigen::Matrix3d::Identity();
  s.T_s2c = Eigen::Vector3d::Zero();
  s.sigma_t_s = options.sigma_t_s;
  s.range_sigma = options.range_sigma;
  s.max_range_m = options.max_range_m > 0 ? options.max_range_m
                                          : std::max(0.01, std::ceil(*farthest * 100) / 100);
  return LasImport(std::move(st));
}

absl::StatusOr<ImportedScan> LasImport::Run(const FrameSink& sink, LasReport* report) const {
  const State& st = *state_;
  LasReport rep = st.report;
  ImportedScan scan;
  scan.sensor = st.sensor;
  const double max_range = st.sensor.max_range_m;
  std::vector<Eigen::Vector3f> pts;
  absl::StatusOr<double> walked =
      Walk(st, rep, [&](double t, const Pose& pose, std::span<const Eigen::Vector3f> frame) {
        pts.assign(frame.begin(), frame.end());
        for (Eigen::Vector3f& p : pts) {
          if (p.norm() > max_range) p.setConstant(std::numeric_limits<float>::quiet_NaN());
        }
        const Eigen::Quaterniond& q = pose.rotation;
        const Eigen::Vector3d& o = pose.translation;
        scan.path.push_back({t, o.x(), o.y(), o.z(), q.w(), q.x(), q.y(), q.z()});
        return EmitFrame(sink, t, pts, scan);
      });
  if (!walked.ok()) return walked.status();
  if (report) *report = rep;
  return scan;
}

}  // namespace carvemap
