#include "storage/import/e57_import.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <span>
#include <utility>

#include "absl/strings/str_cat.h"
#include "storage/import/e57_reader.h"
#include "storage/import/scan_import.h"

namespace carvemap {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
// A frame's ray count is a u32 in /frames (docs/DESIGN.md §3).
constexpr uint64_t kMaxFrameRays = std::numeric_limits<uint32_t>::max();
constexpr double kFarthest = 1e5;              // m
constexpr double kMaxIndex = 1099511627776.0;  // 2⁴⁰

// How one scan's records become rays: which prototype fields hold what.
struct ScanPlan {
  int coord[3] = {-1, -1, -1};  // cartesianX/Y/Z, or sphericalRange/Azimuth/Elevation
  bool spherical = false;
  int invalid_state = -1, row = -1, column = -1, return_index = -1;
  // A grid scan's pixels, once known: the sensor it is a frame of, its first row and column.
  bool structured = false;
  int sensor = -1;
  int64_t row_min = 0, col_min = 0;
  uint32_t rows = 0, cols = 0;
};

absl::StatusOr<ScanPlan> PlanScan(const E57Reader& reader, size_t i) {
  const E57Scan& scan = reader.scans()[i];
  ScanPlan plan;
  const char* cartesian[3] = {"cartesianX", "cartesianY", "cartesianZ"};
  const char* spherical[3] = {"sphericalRange", "sphericalAzimuth", "sphericalElevation"};
  for (int k = 0; k < 3; ++k) plan.coord[k] = scan.FieldIndex(cartesian[k]);
  if (std::find(plan.coord, plan.coord + 3, -1) != plan.coord + 3) {
    plan.spherical = true;
    for (int k = 0; k < 3; ++k) plan.coord[k] = scan.FieldIndex(spherical[k]);
    if (std::find(plan.coord, plan.coord + 3, -1) != plan.coord + 3) {
      return absl::InvalidArgumentError(
          absl::StrCat(reader.Where(i),
                       ": its points have neither cartesianX/Y/Z nor sphericalRange/"
                       "Azimuth/Elevation"));
    }
  }
  plan.invalid_state =
      scan.FieldIndex(plan.spherical ? "sphericalInvalidState" : "cartesianInvalidState");
  plan.row = scan.FieldIndex("rowIndex");
  plan.column = scan.FieldIndex("columnIndex");
  plan.return_index = scan.FieldIndex("returnIndex");
  plan.structured = plan.row >= 0 && plan.column >= 0;
  return plan;
}

// One record as the importer sees it.
struct Record {
  uint64_t index = 0;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();  // in the scan's frame
  bool valid = false;                           // a return (invalid state 0, not the origin)
  bool later_return = false;
  int64_t row = 0, col = 0;
};

// Calls `f(record)` for every record of scan `i`, in file order.
template <typename F>
absl::Status ForEachRecord(const E57Reader& reader, size_t i, const ScanPlan& plan, F&& f) {
  std::vector<int> fields(plan.coord, plan.coord + 3);
  const int optional[4] = {plan.invalid_state, plan.row, plan.column, plan.return_index};
  int slot[4];
  for (int k = 0; k < 4; ++k) {
    slot[k] = optional[k] < 0 ? -1 : static_cast<int>(fields.size());
    if (optional[k] >= 0) fields.push_back(optional[k]);
  }
  uint64_t next = 0;
  return reader.ReadRecords(
      static_cast<int>(i), fields,
      [&](std::span<const std::vector<double>> c, size_t n) -> absl::Status {
        for (size_t j = 0; j < n; ++j, ++next) {
          Record r;
          r.index = next;
          const double a = c[0][j], b = c[1][j], e = c[2][j];
          if (plan.spherical) {
            r.p = Eigen::Vector3d(a * std::cos(e) * std::cos(b), a * std::cos(e) * std::sin(b),
                                  a * std::sin(e));
          } else {
            r.p = Eigen::Vector3d(a, b, e);
          }
          // Invalid state 1 (a direction without a range) and 2 (nothing) carve nothing; many
          // drivers also mark a missing return as the origin.
          r.valid = (slot[0] < 0 || c[slot[0]][j] == 0) && r.p.allFinite() && !r.p.isZero();
          // No scanner reaches 100 km: farther, the record is damaged (and float32 would lose
          // the point).
          if (r.valid && !(r.p.norm() < kFarthest)) {
            return absl::InvalidArgumentError(absl::StrCat(
                reader.Where(i), ": record ", next, " lies ", r.p.norm(), " m from the scanner"));
          }
          for (int k = 1; k <= 2; ++k) {
            if (slot[k] < 0) continue;
            // A grid index beyond ±2⁴⁰ is damage, and kept small it cannot overflow below.
            const double v = c[slot[k]][j];
            if (!(std::abs(v) <= kMaxIndex)) {
              return absl::InvalidArgumentError(
                  absl::StrCat(reader.Where(i), ": record ", next, ": ",
                               k == 1 ? "rowIndex " : "columnIndex ", v, " is out of range"));
            }
            (k == 1 ? r.row : r.col) = static_cast<int64_t>(v);
          }
          r.later_return = slot[3] >= 0 && c[slot[3]][j] > 0;
          if (absl::Status s = f(r); !s.ok()) return s;
        }
        return absl::OkStatus();
      });
}

// Pass 1 over scan `i`: its grid's bounds (when the file has no indexBounds) and its farthest
// return.
absl::Status SurveyScan(const E57Reader& reader, size_t i, ScanPlan& plan, double& max_range) {
  const E57Scan& scan = reader.scans()[i];
  int64_t row_lo = std::numeric_limits<int64_t>::max(),
          row_hi = std::numeric_limits<int64_t>::min();
  int64_t col_lo = row_lo, col_hi = row_hi;
  absl::Status s = ForEachRecord(reader, i, plan, [&](const Record& r) {
    if (r.valid && !r.later_return) max_range = std::max(max_range, r.p.norm());
    row_lo = std::min(row_lo, r.row);
    row_hi = std::max(row_hi, r.row);
    col_lo = std::min(col_lo, r.col);
    col_hi = std::max(col_hi, r.col);
    return absl::OkStatus();
  });
  if (!s.ok() || !plan.structured) return s;
  if (scan.index_bounds) {
    row_lo = scan.index_bounds->row_min;
    row_hi = scan.index_bounds->row_max;
    col_lo = scan.index_bounds->col_min;
    col_hi = scan.index_bounds->col_max;
  } else if (scan.record_count == 0) {
    plan.structured = false;  // no pixels, no grid: an empty frame of `points`
    return absl::OkStatus();
  }
  const double rows = static_cast<double>(row_hi) - static_cast<double>(row_lo) + 1;
  const double cols = static_cast<double>(col_hi) - static_cast<double>(col_lo) + 1;
  if (rows * cols > static_cast<double>(kMaxFrameRays)) {
    return absl::InvalidArgumentError(
        absl::StrCat(reader.Where(i), ": a grid of ", rows, " × ", cols,
                     " pixels is more than one frame holds (2³² − 1 rays)"));
  }
  // Scanners record most pixels, even those with no return; a grid far larger than its records
  // means damaged indices or bounds, and would take memory the file does not justify.
  const double pixel_limit = std::max(16.0 * static_cast<double>(scan.record_count), 1048576.0);
  if (rows * cols > pixel_limit) {
    return absl::InvalidArgumentError(absl::StrCat(
        reader.Where(i), ": rows ", row_lo, "–", row_hi, " and columns ", col_lo, "–", col_hi,
        " make ", rows * cols, " pixels for ", scan.record_count,
        " records (more than 16 pixels a record): are its indices or indexBounds damaged?"));
  }
  plan.row_min = row_lo;
  plan.col_min = col_lo;
  plan.rows = static_cast<uint32_t>(rows);
  plan.cols = static_cast<uint32_t>(cols);
  return absl::OkStatus();
}

}  // namespace

absl::Status E57ImportOptions::Validate() const {
  return ValidateCloudOptions("import e57", max_range_m, range_sigma, shift);
}

struct E57Import::State {
  E57Reader reader;
  std::vector<ScanPlan> plans;
  std::vector<SensorInfo> sensors;
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
};

E57Import::E57Import(std::unique_ptr<State> state) : state_(std::move(state)) {}
E57Import::E57Import(E57Import&&) noexcept = default;
E57Import& E57Import::operator=(E57Import&&) noexcept = default;
E57Import::~E57Import() = default;
const std::vector<SensorInfo>& E57Import::sensors() const { return state_->sensors; }

absl::StatusOr<E57Import> E57Import::Open(const std::string& file,
                                          const E57ImportOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  auto reader = E57Reader::Open(file);
  if (!reader.ok()) return reader.status();
  if (reader->scans().empty()) {
    return absl::InvalidArgumentError(absl::StrCat(file, ": no scans (data3D is empty)"));
  }
  auto st = std::make_unique<State>(State{std::move(*reader), {}, {}, {}});
  const E57Reader& r = st->reader;
  double farthest = 0;
  for (size_t i = 0; i < r.scans().size(); ++i) {
    auto plan = PlanScan(r, i);
    if (!plan.ok()) return plan.status();
    if (absl::Status s = SurveyScan(r, i, *plan, farthest); !s.ok()) return s;
    st->plans.push_back(*plan);
  }

  SensorInfo base;
  base.range_sigma = options.range_sigma;
  base.max_range_m = options.max_range_m > 0 ? options.max_range_m
                                             : std::max(0.01, std::ceil(farthest * 100) / 100);
  std::map<std::pair<uint32_t, uint32_t>, int> grid_sensor;
  int points_sensor = -1;
  for (ScanPlan& plan : st->plans) {
    if (plan.structured) {
      auto [it, added] =
          grid_sensor.try_emplace({plan.rows, plan.cols}, static_cast<int>(st->sensors.size()));
      if (added) {
        SensorInfo s = base;
        s.name = absl::StrCat("grid_", plan.rows, "x", plan.cols);
        s.kind = SensorKind::kGrid;
        s.rows = plan.rows;
        s.cols = plan.cols;
        st->sensors.push_back(s);
      }
      plan.sensor = it->second;
    } else {
      if (points_sensor < 0) {
        points_sensor = static_cast<int>(st->sensors.size());
        SensorInfo s = base;
        s.name = "points";
        s.kind = SensorKind::kPoints;
        st->sensors.push_back(s);
      }
      plan.sensor = points_sensor;
    }
  }
  st->shift = CloudShift(options.shift, r.scans().front().translation);
  for (size_t i = 0; i < r.scans().size(); ++i) {
    const double from_origin = (r.scans()[i].translation - st->shift).norm();
    if (!(from_origin < kFarthest)) {
      return absl::InvalidArgumentError(absl::StrCat(
          r.Where(i), ": its pose lies ", from_origin, " m from the shifted origin (",
          st->shift.x(), ", ", st->shift.y(), ", ", st->shift.z(), "); give --shift near it"));
    }
  }
  return E57Import(std::move(st));
}

absl::StatusOr<std::vector<PathRecord>> E57Import::Run(const SensorFrameSink& sink,
                                                       E57Report* report) const {
  const State& st = *state_;
  const E57Reader& reader = st.reader;
  E57Report rep;
  rep.shift = st.shift;
  std::vector<PathRecord> path;
  std::vector<Eigen::Vector3f> frame;
  std::vector<bool> seen;
  for (size_t i = 0; i < reader.scans().size(); ++i) {
    const E57Scan& scan = reader.scans()[i];
    const ScanPlan& plan = st.plans[i];
    const SensorInfo& sensor = st.sensors[static_cast<size_t>(plan.sensor)];
    frame.clear();
    if (plan.structured) {
      frame.assign(static_cast<size_t>(plan.rows) * plan.cols, Eigen::Vector3f::Constant(kNaN));
      seen.assign(frame.size(), false);
    }
    absl::Status s = ForEachRecord(reader, i, plan, [&](const Record& r) -> absl::Status {
      ++rep.records;
      if (r.later_return) {
        ++rep.later_returns;
        return absl::OkStatus();
      }
      const bool in_range = r.valid && r.p.norm() <= sensor.max_range_m;
      const Eigen::Vector3f p =
          in_range ? Eigen::Vector3f(r.p.cast<float>()) : Eigen::Vector3f::Constant(kNaN);
      if (!plan.structured) {
        if (frame.size() == kMaxFrameRays) {
          return absl::InvalidArgumentError(
              absl::StrCat(reader.Where(i), ": more records than one frame holds (2³² − 1 rays)"));
        }
        frame.push_back(p);
        return absl::OkStatus();
      }
      const int64_t row = r.row - plan.row_min, col = r.col - plan.col_min;
      if (row < 0 || col < 0 || row >= int64_t{plan.rows} || col >= int64_t{plan.cols}) {
        return absl::InvalidArgumentError(absl::StrCat(
            reader.Where(i), ": record ", r.index, ": row ", r.row, ", column ", r.col,
            " lie outside indexBounds (rows ", plan.row_min, "–", plan.row_min + plan.rows - 1,
            ", columns ", plan.col_min, "–", plan.col_min + plan.cols - 1, ")"));
      }
      const size_t pixel = static_cast<size_t>(row) * plan.cols + static_cast<size_t>(col);
      if (seen[pixel]) {
        return absl::InvalidArgumentError(absl::StrCat(reader.Where(i), ": record ", r.index,
                                                       ": row ", r.row, ", column ", r.col,
                                                       " has a record already"));
      }
      seen[pixel] = true;
      frame[pixel] = p;
      return absl::OkStatus();
    });
    if (!s.ok()) return s;
    const double t = static_cast<double>(i);
    if (sink) {
      if (absl::Status w = sink(plan.sensor, t, frame); !w.ok()) return w;
    }
    rep.rays += frame.size();
    rep.no_return += static_cast<uint64_t>(std::count_if(
        frame.begin(), frame.end(), [](const Eigen::Vector3f& p) { return std::isnan(p.x()); }));
    ++rep.scans;
    if (plan.structured) ++rep.structured_scans;
    const Eigen::Vector3d x = scan.translation - st.shift;
    const Eigen::Quaterniond& q = scan.rotation;
    path.push_back(PathRecord{t, x.x(), x.y(), x.z(), q.w(), q.x(), q.y(), q.z()});
  }
  if (report) *report = rep;
  return path;
}

}  // namespace carvemap
