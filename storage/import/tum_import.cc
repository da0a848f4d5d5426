#include "storage/import/tum_import.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"
#include "storage/png_io.h"

namespace carvemap {
namespace {

// "depth/1311877813.991479.png" ➜ 1311877813.991479: TUM names files by their time stamp.
bool TimeFromName(absl::string_view name, double& t) {
  const size_t slash = name.find_last_of('/');
  if (slash != absl::string_view::npos) name.remove_prefix(slash + 1);
  if (name.size() <= 4 || name.substr(name.size() - 4) != ".png") return false;
  name.remove_suffix(4);
  return absl::SimpleAtod(name, &t) && std::isfinite(t);
}

struct PoseLine {
  PathRecord pose;
  int line;
};

struct DepthLine {
  double t;
  std::string relative_path;
  int line;
};

}  // namespace

absl::Status TumOptions::Validate() const {
  if (!(fx > 0 && fy > 0 && std::isfinite(fx) && std::isfinite(fy))) {
    return absl::InvalidArgumentError("tum: fx and fy must be positive");
  }
  if (!std::isfinite(cx) || !std::isfinite(cy)) {
    return absl::InvalidArgumentError("tum: cx and cy must be finite");
  }
  if (width <= 0 || height <= 0) {
    return absl::InvalidArgumentError("tum: image width and height must be positive");
  }
  if (!(depth_scale > 0)) return absl::InvalidArgumentError("tum: depth_scale must be positive");
  if (stride < 1) return absl::InvalidArgumentError("tum: stride must be >= 1");
  if (!(max_range_m > 0)) return absl::InvalidArgumentError("tum: max_range must be positive");
  if (!(range_sigma[0] >= 0 && range_sigma[1] >= 0 && sigma_t_s >= 0)) {
    return absl::InvalidArgumentError("tum: noise parameters must be >= 0");
  }
  return absl::OkStatus();
}

SensorInfo TumSensor(const TumOptions& options) {
  SensorInfo info;
  info.name = "depth";
  info.kind = SensorKind::kGrid;
  const int stride = std::max(options.stride, 1);
  info.rows = static_cast<uint32_t>((options.height + stride - 1) / stride);
  info.cols = static_cast<uint32_t>((options.width + stride - 1) / stride);
  info.sigma_t_s = options.sigma_t_s;
  info.range_sigma = options.range_sigma;
  info.max_range_m = options.max_range_m;
  return info;
}

absl::StatusOr<ImportedScan> ImportTum(const std::string& dir, const TumOptions& options,
                                       const FrameSink& sink) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  namespace fs = std::filesystem;
  const std::string assoc = options.association_file.empty()
                                ? (fs::path(dir) / "my_association.txt").string()
                                : options.association_file;
  std::ifstream in(assoc);
  if (!in) return absl::NotFoundError(absl::StrCat(assoc, ": cannot open association file"));

  ImportedScan scan;
  scan.sensor = TumSensor(options);

  std::vector<PoseLine> poses;
  std::map<std::string, DepthLine> depth_by_path;  // each depth image once
  std::string text;
  for (int line = 1; std::getline(in, text); ++line) {
    std::vector<absl::string_view> tok =
        absl::StrSplit(text, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (tok.empty() || tok[0][0] == '#') continue;
    const std::string where = absl::StrCat(assoc, ": line ", line, ": ");
    if (tok.size() != 9) {
      return absl::InvalidArgumentError(absl::StrCat(
          where, "expected 'rgb/<t>.png depth/<t>.png tx ty tz qx qy qz qw', found ",
          tok.size(), " fields"));
    }
    double t_rgb = 0, t_depth = 0;
    if (!TimeFromName(tok[0], t_rgb) || !TimeFromName(tok[1], t_depth)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "image names must be <time>.png, found ", tok[0], " ", tok[1]));
    }
    double v[7];
    for (int i = 0; i < 7; ++i) {
      if (!absl::SimpleAtod(tok[2 + i], &v[i]) || !std::isfinite(v[i])) {
        return absl::InvalidArgumentError(
            absl::StrCat(where, "field ", 3 + i, " '", tok[2 + i], "' is not a finite number"));
      }
    }
    // The file's order is qx qy qz qw; ours is qw qx qy qz. Four decimals leave |q| ≈ 1 ± 2e-4.
    auto q = CheckedUnitQuaternion(v[6], v[3], v[4], v[5]);
    if (!q.ok()) return absl::InvalidArgumentError(absl::StrCat(where, q.status().message()));
    poses.push_back(
        PoseLine{PathRecord{t_rgb, v[0], v[1], v[2], (*q)[0], (*q)[1], (*q)[2], (*q)[3]}, line});
    depth_by_path.try_emplace(std::string(tok[1]), DepthLine{t_depth, std::string(tok[1]), line});
  }
  if (poses.empty()) return absl::InvalidArgumentError(assoc + ": no pose lines");

  std::stable_sort(poses.begin(), poses.end(),
                   [](const PoseLine& a, const PoseLine& b) { return a.pose.t < b.pose.t; });
  scan.path.reserve(poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    const PathRecord& p = poses[i].pose;
    if (i > 0 && p.t == poses[i - 1].pose.t) {
      const PathRecord& q = poses[i - 1].pose;
      // The sample association repeats its last line verbatim; that is harmless. Two different
      // poses at one time are not: the path would be ambiguous.
      if (p.x == q.x && p.y == q.y && p.z == q.z && p.qw == q.qw && p.qx == q.qx &&
          p.qy == q.qy && p.qz == q.qz) {
        continue;
      }
      return absl::InvalidArgumentError(absl::StrCat(assoc, ": lines ", poses[i - 1].line,
                                                     " and ", poses[i].line,
                                                     " give different poses for time ", p.t));
    }
    scan.path.push_back(p);
  }
  const double t_begin = scan.path.front().t, t_end = scan.path.back().t;

  std::vector<DepthLine> depths;
  for (auto& [path, d] : depth_by_path) {
    // The non-throwing overload: a name the system cannot look up (too long, a directory we
    // may not read) is an error on its line, not an exception.
    std::error_code error;
    const bool exists = fs::exists(fs::path(dir) / path, error);
    if (error) {
      return absl::InvalidArgumentError(absl::StrCat(assoc, ": line ", d.line, ": depth image ",
                                                     path.substr(0, 80), ": ", error.message()));
    }
    if (exists) depths.push_back(std::move(d));
  }
  std::sort(depths.begin(), depths.end(),
            [](const DepthLine& a, const DepthLine& b) { return a.t < b.t; });

  const int stride = options.stride;
  const SensorInfo& sensor = scan.sensor;
  // Per-column and per-row factors (u − cx)/fx and (v − cy)/fy of the kept pixels.
  std::vector<float> kx(sensor.cols), ky(sensor.rows);
  for (uint32_t c = 0; c < sensor.cols; ++c) kx[c] = float((c * stride - options.cx) / options.fx);
  for (uint32_t r = 0; r < sensor.rows; ++r) ky[r] = float((r * stride - options.cy) / options.fy);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const double max_range_sq = options.max_range_m * options.max_range_m;

  std::vector<Eigen::Vector3f> points(size_t(sensor.rows) * sensor.cols);
  for (size_t i = 0; i < depths.size(); ++i) {
    const DepthLine& d = depths[i];
    const std::string file = (fs::path(dir) / d.relative_path).string();
    if (i > 0 && d.t == depths[i - 1].t) {
      return absl::InvalidArgumentError(absl::StrCat(assoc, ": lines ", depths[i - 1].line,
                                                     " and ", d.line,
                                                     " name two depth images of time ", d.t));
    }
    if (d.t < t_begin || d.t > t_end) {
      return absl::InvalidArgumentError(absl::StrCat(
          file, ": time ", d.t, " lies outside the poses' span [", t_begin, ", ", t_end, "]"));
    }
    auto image = ReadPngGray16(file);
    if (!image.ok()) return image.status();  // names the file and what is wrong
    if (image->width != options.width || image->height != options.height) {
      return absl::InvalidArgumentError(absl::StrCat(file, ": image is ", image->width, "×",
                                                     image->height, ", expected ", options.width,
                                                     "×", options.height));
    }
    for (uint32_t r = 0; r < sensor.rows; ++r) {
      for (uint32_t c = 0; c < sensor.cols; ++c) {
        const uint16_t raw = image->at(int(r) * stride, int(c) * stride);
        Eigen::Vector3f& p = points[size_t(r) * sensor.cols + c];
        const float z = float(raw / options.depth_scale);
        p = Eigen::Vector3f(kx[c] * z, ky[r] * z, z);
        if (raw == 0 || p.squaredNorm() > max_range_sq) p.setConstant(nan);
      }
    }
    if (absl::Status s = EmitFrame(sink, d.t, points, scan); !s.ok()) return s;
  }
  return scan;
}

}  // namespace carvemap
