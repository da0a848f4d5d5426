#include "services/building/building_presets.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <queue>
#include <random>

#include "absl/strings/str_cat.h"

namespace carvemap {
namespace {

using Eigen::AlignedBox2d;
using Eigen::Vector2d;

// Dimensions of an ordinary office building (docs/DESIGN.md §4).
constexpr double kWallT = 0.15;  // wall thickness, m
constexpr double kHalfT = kWallT / 2;
constexpr double kSlabT = 0.3;                   // floor slab thickness, m
constexpr double kDoorHead = 2.1;                // top of a door opening above the floor
constexpr double kSill = 0.9;                    // window sill above the floor
constexpr double kWindowHead = 2.1;              // window head above the floor
constexpr double kTread = 0.28;                  // stair tread, m
constexpr double kNavRes = 0.1;                  // nav grid cell, m
constexpr double kClearance = 0.25;              // walker half-width, m
constexpr double kBandLo = 0.05, kBandHi = 1.9;  // body height band above the floor, m

// ---------------------------------------------------------------- layout description

enum class Kind { kHall, kOffice, kMeeting, kOpen, kStorage, kLobby, kStair, kSingle };
// Which wall of a room: also the "back" wall that furniture stands against.
enum class Side { kSouth, kNorth, kWest, kEast };

struct ColumnSpec {
  Vector2d center;
  bool round = false;
  double size = 0.4;  // side or diameter, m
};

struct RoomSpec {
  std::string name;
  int level = 0;
  Kind kind = Kind::kOffice;
  AlignedBox2d rect;       // wall centre lines; the free space is this shrunk by kHalfT
  double ceiling_h = 2.7;  // above the level's floor
  bool entered = true;
  Side back = Side::kSouth;     // the wall opposite the door
  double east_arc_sagitta = 0;  // > 0: the east wall is an arc bulging outwards by this
  std::vector<ColumnSpec> columns;
  bool open_to_level_above = false;  // stairwell: no ceiling slab, the next floor has an opening
};

RoomSpec NewRoom(std::string name, int level, Kind kind, const AlignedBox2d& rect,
                 double ceiling_h) {
  RoomSpec r;
  r.name = std::move(name);
  r.level = level;
  r.kind = kind;
  r.rect = rect;
  r.ceiling_h = ceiling_h;
  return r;
}

struct DoorSpec {
  int a = 0, b = 0;  // room indices sharing a wall
  double at = 0;     // centre of the opening along the shared wall (x or y), m
  double width = 0.9;
};

struct WindowSpec {
  int room = 0;
  Side side = Side::kSouth;  // an exterior wall of the room
  double at = 0, width = 1.2;
};

// A straight flight rising towards +x along the back wall of `room_bottom`.
struct StairSpec {
  int room_bottom = 0, room_top = 0;
  double x_start = 0;  // the first riser
  double y0 = 0, y1 = 0;
  int risers = 20;
};

struct LevelSpec {
  double floor_z = 0, height = 3.5;  // floor-to-floor
};

struct Layout {
  std::vector<LevelSpec> levels;
  std::vector<RoomSpec> rooms;
  std::vector<DoorSpec> doors;
  std::vector<WindowSpec> windows;
  std::vector<StairSpec> stairs;
};

// ---------------------------------------------------------------- small geometry

Prism Box(const AlignedBox2d& r, double z0, double z1) {
  Prism p;
  p.footprint = {r.min(), {r.max().x(), r.min().y()}, r.max(), {r.min().x(), r.max().y()}};
  p.z0 = z0;
  p.z1 = z1;
  return p;
}

AlignedBox2d Rect(double x0, double y0, double x1, double y1) {
  return AlignedBox2d(Vector2d(std::min(x0, x1), std::min(y0, y1)),
                      Vector2d(std::max(x0, x1), std::max(y0, y1)));
}

AlignedBox2d Interior(const RoomSpec& r) {
  return Rect(r.rect.min().x() + kHalfT, r.rect.min().y() + kHalfT, r.rect.max().x() - kHalfT,
              r.rect.max().y() - kHalfT);
}

std::vector<Vector2d> ColumnFootprint(const ColumnSpec& c) {
  if (!c.round) {
    const double h = c.size / 2;
    return Box(Rect(c.center.x() - h, c.center.y() - h, c.center.x() + h, c.center.y() + h), 0, 1)
        .footprint;
  }
  std::vector<Vector2d> ring;
  constexpr int kSides = 16;
  for (int i = 0; i < kSides; ++i) {
    const double a = 2 * std::numbers::pi * i / kSides;
    ring.push_back(c.center + c.size / 2 * Vector2d(std::cos(a), std::sin(a)));
  }
  return ring;
}

// The circle of a room's curved east wall (centre-line radius) through its two east corners.
struct Arc {
  Vector2d center;
  double radius = 0;
  double half_angle = 0;  // of the wall's centre line
};

Arc EastArc(const RoomSpec& r) {
  const double c = r.rect.sizes().y() / 2, s = r.east_arc_sagitta;
  Arc arc;
  arc.radius = (c * c + s * s) / (2 * s);
  arc.center = Vector2d(r.rect.max().x() + s - arc.radius, r.rect.center().y());
  arc.half_angle = std::asin(c / arc.radius);
  return arc;
}

constexpr int kArcSegments = 32;

// The room's free-space outline: the rectangle shrunk by half a wall, with the curved east
// side following the wall's inner face when there is one.
std::vector<Vector2d> RoomOutline(const RoomSpec& r) {
  const AlignedBox2d in = Interior(r);
  if (r.east_arc_sagitta <= 0) return Box(in, 0, 1).footprint;
  const Arc arc = EastArc(r);
  const double inner = arc.radius - kHalfT;
  const double phi = std::asin((in.sizes().y() / 2) / inner);
  std::vector<Vector2d> ring = {in.min()};
  for (int i = 0; i <= kArcSegments; ++i) {
    const double a = -phi + 2 * phi * i / kArcSegments;
    ring.push_back(arc.center + inner * Vector2d(std::cos(a), std::sin(a)));
  }
  ring.emplace_back(in.min().x(), in.max().y());
  return ring;
}

// ---------------------------------------------------------------- walls

struct Opening {
  double lo = 0, hi = 0;      // along the wall line
  double z_lo = 0, z_hi = 0;  // above the level's floor
};

// All wall segments on one straight line (horizontal: y = c, spans in x; vertical: x = c).
struct WallLine {
  bool horizontal = true;
  double c = 0;
  std::vector<std::pair<double, double>> spans;
  std::vector<Opening> openings;
};

using WallLines = std::map<std::pair<bool, long long>, WallLine>;

WallLine& LineAt(WallLines& lines, bool horizontal, double c) {
  WallLine& line = lines[{horizontal, std::llround(c * 1000)}];
  line.horizontal = horizontal;
  line.c = c;
  return line;
}

// A door's opening: the shared wall of two rooms and its extent along it.
struct DoorGeom {
  bool horizontal = true;
  double c = 0, lo = 0, hi = 0;
};

absl::StatusOr<DoorGeom> SharedWallOpening(const RoomSpec& a, const RoomSpec& b,
                                           const DoorSpec& d) {
  constexpr double kEps = 1e-6;
  const auto overlap = [&](double a0, double a1, double b0, double b1, bool horizontal,
                           double c) -> absl::StatusOr<DoorGeom> {
    const double lo = std::max(a0, b0) + kHalfT + 0.05, hi = std::min(a1, b1) - kHalfT - 0.05;
    DoorGeom g{horizontal, c, d.at - d.width / 2, d.at + d.width / 2};
    if (g.lo < lo || g.hi > hi) {
      return absl::InvalidArgumentError(
          absl::StrCat("door ", a.name, "–", b.name, " does not fit their shared wall"));
    }
    return g;
  };
  const AlignedBox2d &ra = a.rect, &rb = b.rect;
  for (int k = 0; k < 2; ++k) {
    const AlignedBox2d& p = k == 0 ? ra : rb;
    const AlignedBox2d& q = k == 0 ? rb : ra;
    if (std::abs(p.max().y() - q.min().y()) < kEps) {
      return overlap(p.min().x(), p.max().x(), q.min().x(), q.max().x(), true, p.max().y());
    }
    if (std::abs(p.max().x() - q.min().x()) < kEps) {
      return overlap(p.min().y(), p.max().y(), q.min().y(), q.max().y(), false, p.max().x());
    }
  }
  return absl::InvalidArgumentError(
      absl::StrCat("rooms ", a.name, " and ", b.name, " share no wall for a door"));
}

// The exterior wall line of a room's side.
DoorGeom SideLine(const RoomSpec& r, Side side, double at, double width) {
  const bool horizontal = side == Side::kSouth || side == Side::kNorth;
  const double c = side == Side::kSouth   ? r.rect.min().y()
                   : side == Side::kNorth ? r.rect.max().y()
                   : side == Side::kWest  ? r.rect.min().x()
                                          : r.rect.max().x();
  return {horizontal, c, at - width / 2, at + width / 2};
}

Prism WallPiece(const WallLine& line, double s0, double s1, double z0, double z1) {
  return line.horizontal ? Box(Rect(s0, line.c - kHalfT, s1, line.c + kHalfT), z0, z1)
                         : Box(Rect(line.c - kHalfT, s0, line.c + kHalfT, s1), z0, z1);
}

// Solid wall prisms of one line: the union of its spans (extended by half a wall at the ends so
// corners close), cut by the openings, with a lintel above doors and a sill wall and lintel
// around windows.
void EmitWallLine(WallLine line, double floor_z, double top_z, std::vector<Prism>& out) {
  std::sort(line.spans.begin(), line.spans.end());
  std::sort(line.openings.begin(), line.openings.end(),
            [](const Opening& a, const Opening& b) { return a.lo < b.lo; });
  std::vector<std::pair<double, double>> merged;
  for (const auto& s : line.spans) {
    if (!merged.empty() && s.first <= merged.back().second + 1e-9) {
      merged.back().second = std::max(merged.back().second, s.second);
    } else {
      merged.push_back(s);
    }
  }
  for (const auto& [a, b] : merged) {
    double cursor = a - kHalfT;
    for (const Opening& o : line.openings) {
      if (o.lo < a || o.hi > b) continue;
      if (o.lo > cursor) out.push_back(WallPiece(line, cursor, o.lo, floor_z, top_z));
      if (o.z_lo > 0) out.push_back(WallPiece(line, o.lo, o.hi, floor_z, floor_z + o.z_lo));
      out.push_back(WallPiece(line, o.lo, o.hi, floor_z + o.z_hi, top_z));
      cursor = o.hi;
    }
    out.push_back(WallPiece(line, cursor, b + kHalfT, floor_z, top_z));
  }
}

// The curved wall: short wall prisms between the inner and outer arcs, each a convex quad, so
// consecutive pieces share their radial faces exactly and nothing leaks between them. The arc
// reaches half a wall's angle past the corners so it overlaps the straight walls it meets.
void EmitArcWall(const RoomSpec& r, double floor_z, double top_z, std::vector<Prism>& out) {
  const Arc arc = EastArc(r);
  const double a0 = -arc.half_angle - kHalfT / arc.radius;
  const double a1 = arc.half_angle + kHalfT / arc.radius;
  const double ri = arc.radius - kHalfT, ro = arc.radius + kHalfT;
  for (int i = 0; i < kArcSegments; ++i) {
    const double t0 = a0 + (a1 - a0) * i / kArcSegments;
    const double t1 = a0 + (a1 - a0) * (i + 1) / kArcSegments;
    const Vector2d u0(std::cos(t0), std::sin(t0)), u1(std::cos(t1), std::sin(t1));
    Prism p;
    p.footprint = {arc.center + ri * u0, arc.center + ro * u0, arc.center + ro * u1,
                   arc.center + ri * u1};
    p.z0 = floor_z;
    p.z1 = top_z;
    out.push_back(p);
  }
}

// ---------------------------------------------------------------- furniture

// A room's free rectangle seen from its back wall: u runs along the back wall, v away from it.
struct RoomFrame {
  AlignedBox2d in;
  Side back = Side::kSouth;
  [[nodiscard]] double Lu() const {
    return back == Side::kSouth || back == Side::kNorth ? in.sizes().x() : in.sizes().y();
  }
  [[nodiscard]] double Lv() const {
    return back == Side::kSouth || back == Side::kNorth ? in.sizes().y() : in.sizes().x();
  }
  [[nodiscard]] Vector2d World(double u, double v) const {
    switch (back) {
      case Side::kSouth:
        return {in.min().x() + u, in.min().y() + v};
      case Side::kNorth:
        return {in.max().x() - u, in.max().y() - v};
      case Side::kWest:
        return {in.min().x() + v, in.max().y() - u};
      case Side::kEast:
        return {in.max().x() - v, in.min().y() + u};
    }
    return {};
  }
  [[nodiscard]] Prism Part(double u0, double v0, double u1, double v1, double z0, double z1) const {
    const Vector2d a = World(u0, v0), b = World(u1, v1);
    return Box(Rect(a.x(), a.y(), b.x(), b.y()), z0, z1);
  }
};

class Furnisher {
 public:
  Furnisher(Building& b, uint64_t seed) : b_(b), rng_(seed) {}

  double Jitter(double amount) {
    return std::uniform_real_distribution<double>(-amount, amount)(rng_);
  }

  // Table-like: a top on four legs.
  void Table(const RoomFrame& f, int level, double z, const std::string& kind, double u0, double v0,
             double len, double depth, double height) {
    ObjectTruth& o = New(kind, level);
    o.parts.push_back(f.Part(u0, v0, u0 + len, v0 + depth, z + height - 0.03, z + height));
    constexpr double kLeg = 0.05, kInset = 0.03;
    for (double u : {u0 + kInset, u0 + len - kInset - kLeg}) {
      for (double v : {v0 + kInset, v0 + depth - kInset - kLeg}) {
        o.parts.push_back(f.Part(u, v, u + kLeg, v + kLeg, z, z + height - 0.03));
      }
    }
  }

  // Seat + legs + back; the back is on the high-v side when `back_high_v`.
  void Chair(const RoomFrame& f, int level, double z, double cu, double cv, bool back_high_v) {
    ObjectTruth& o = New("chair", level);
    constexpr double kS = 0.45, kLeg = 0.03;
    const double u0 = cu - kS / 2, v0 = cv - kS / 2, u1 = u0 + kS, v1 = v0 + kS;
    o.parts.push_back(f.Part(u0, v0, u1, v1, z + 0.42, z + 0.46));
    for (double u : {u0, u1 - kLeg}) {
      for (double v : {v0, v1 - kLeg})
        o.parts.push_back(f.Part(u, v, u + kLeg, v + kLeg, z, z + 0.42));
    }
    const double bv = back_high_v ? v1 - 0.04 : v0;
    o.parts.push_back(f.Part(u0, bv, u1, bv + 0.04, z + 0.46, z + 0.92));
  }

  // Against the back wall: a back panel, two sides and boards (it hides the wall behind it).
  void Shelf(const RoomFrame& f, int level, double z, double u0, double len) {
    ObjectTruth& o = New("shelf", level);
    constexpr double kDepth = 0.35, kHeight = 1.9, kBoard = 0.02, kGap = 0.01;
    o.parts.push_back(f.Part(u0, kGap, u0 + len, kGap + kBoard, z, z + kHeight));
    o.parts.push_back(f.Part(u0, kGap + kBoard, u0 + kBoard, kDepth, z, z + kHeight));
    o.parts.push_back(f.Part(u0 + len - kBoard, kGap + kBoard, u0 + len, kDepth, z, z + kHeight));
    for (double h : {0.05, 0.45, 0.85, 1.25, 1.65, kHeight - kBoard}) {
      o.parts.push_back(
          f.Part(u0 + kBoard, kGap + kBoard, u0 + len - kBoard, kDepth, z + h, z + h + kBoard));
    }
  }

  void Cabinet(const RoomFrame& f, int level, double z, double u0, double width) {
    ObjectTruth& o = New("cabinet", level);
    o.parts.push_back(f.Part(u0, 0.01, u0 + width, 0.46, z, z + 1.05));
  }

  // A light box hanging 0.27 m below the ceiling on a thin rod.
  void CeilingLight(const Vector2d& c, int level, double ceiling_z) {
    ObjectTruth& o = New("ceiling_light", level);
    o.parts.push_back(Box(Rect(c.x() - 0.3, c.y() - 0.3, c.x() + 0.3, c.y() + 0.3),
                          ceiling_z - 0.35, ceiling_z - 0.27));
    o.parts.push_back(Box(Rect(c.x() - 0.01, c.y() - 0.01, c.x() + 0.01, c.y() + 0.01),
                          ceiling_z - 0.27, ceiling_z));
  }

 private:
  ObjectTruth& New(const std::string& kind, int level) {
    ObjectTruth& o = b_.objects.emplace_back();
    o.id = static_cast<int>(b_.objects.size()) - 1;
    o.kind = kind;
    o.level = level;
    return o;
  }

  Building& b_;
  std::mt19937_64 rng_;
};

// Furniture by room kind, placed in the room's back-wall frame so doors (on the front wall)
// stay clear.
void Furnish(const RoomSpec& r, double floor_z, Furnisher& fu) {
  const RoomFrame f{Interior(r), r.back};
  const double Lu = f.Lu(), Lv = f.Lv(), z = floor_z;
  const int lv = r.level;
  const double ceil = floor_z + r.ceiling_h;
  switch (r.kind) {
    case Kind::kOffice: {
      fu.Shelf(f, lv, z, 0.05, 1.0);
      const double du = std::clamp(Lu / 2 - 0.6 + fu.Jitter(0.15), 1.2, Lu - 2.05);
      fu.Table(f, lv, z, "desk", du, 0.02, 1.4, 0.7, 0.75);
      fu.Chair(f, lv, z, du + 0.7 + fu.Jitter(0.2), 1.05 + fu.Jitter(0.08), true);
      fu.Cabinet(f, lv, z, Lu - 0.55, 0.5);
      fu.CeilingLight(f.World(Lu / 2, Lv / 2), lv, ceil);
      break;
    }
    case Kind::kMeeting: {
      fu.Shelf(f, lv, z, 0.1, 1.2);
      fu.Cabinet(f, lv, z, Lu - 0.6, 0.5);
      const double cu = Lu / 2 + fu.Jitter(0.1), cv = Lv / 2 + 0.2;
      fu.Table(f, lv, z, "table", cu - 1.0, cv - 0.5, 2.0, 1.0, 0.74);
      for (double du : {-0.5, 0.5}) {
        fu.Chair(f, lv, z, cu + du + fu.Jitter(0.05), cv - 0.85, false);
        fu.Chair(f, lv, z, cu + du + fu.Jitter(0.05), cv + 0.85, true);
      }
      fu.CeilingLight(f.World(Lu / 2, Lv / 2), lv, ceil);
      break;
    }
    case Kind::kOpen: {  // with two columns at mid-depth (see the layout)
      for (double u0 : {0.5, Lu - 1.9}) {
        const double du = u0 + fu.Jitter(0.1);
        fu.Table(f, lv, z, "desk", du, 0.02, 1.4, 0.7, 0.75);
        fu.Chair(f, lv, z, du + 0.7 + fu.Jitter(0.15), 1.05, true);
      }
      fu.Shelf(f, lv, z, Lu / 2 - 0.9, 1.8);
      fu.Table(f, lv, z, "table", Lu / 2 - 0.6, Lv / 2 - 0.35, 1.2, 0.6, 0.74);
      fu.CeilingLight(f.World(Lu / 4, Lv / 2), lv, ceil);
      fu.CeilingLight(f.World(3 * Lu / 4, Lv / 2), lv, ceil);
      break;
    }
    case Kind::kStorage:
      fu.Shelf(f, lv, z, 0.1, Lu / 2 - 0.15);
      fu.Shelf(f, lv, z, Lu / 2 + 0.05, Lu / 2 - 0.15);
      fu.CeilingLight(f.World(Lu / 2, Lv / 2), lv, ceil);
      break;
    case Kind::kHall: {
      // The west end wall has no door: a cabinet against it.
      const RoomFrame west{f.in, Side::kWest};
      fu.Cabinet(west, lv, z, 0.1, 0.6);
      for (double u = 2.0; u < Lu - 1.0; u += 4.0) fu.CeilingLight(f.World(u, Lv / 2), lv, ceil);
      break;
    }
    case Kind::kLobby: {
      fu.Shelf(f, lv, z, 0.3, 1.6);
      fu.Cabinet(f, lv, z, Lu - 0.7, 0.6);
      const double cv = Lv * 0.3 + fu.Jitter(0.2);
      fu.Table(f, lv, z, "table", Lu / 2 - 0.5, cv - 0.5, 1.0, 1.0, 0.74);
      fu.Chair(f, lv, z, Lu / 2, cv - 0.85, false);
      fu.Chair(f, lv, z, Lu / 2, cv + 0.85, true);
      for (double v : {Lv * 0.25, Lv * 0.75}) fu.CeilingLight(f.World(Lu / 2, v), lv, ceil);
      break;
    }
    case Kind::kStair:
      // Steps run along the back (north) wall; a cabinet in the front corner, a light.
      fu.Cabinet(RoomFrame{f.in, Side::kSouth}, lv, z, Lu * 0.4, 0.5);
      fu.CeilingLight(f.World(Lu * 0.75, Lv * 0.75), lv, ceil);
      break;
    case Kind::kSingle: {
      const double du = 1.0 + fu.Jitter(0.2);
      fu.Table(f, lv, z, "desk", du, 0.02, 1.4, 0.7, 0.75);
      fu.Chair(f, lv, z, du + 0.7 + fu.Jitter(0.15), 1.05, true);
      fu.Shelf(f, lv, z, 3.0, 1.2);
      fu.Cabinet(f, lv, z, Lu - 0.6, 0.55);
      const double tu = Lu / 2 - 0.8 + fu.Jitter(0.2);
      fu.Table(f, lv, z, "table", tu, Lv - 1.8, 1.6, 0.8, 0.74);
      fu.Chair(f, lv, z, tu + 0.8, Lv - 2.25, false);
      fu.CeilingLight(f.World(Lu / 2, Lv / 2), lv, ceil);
      break;
    }
  }
}

// ---------------------------------------------------------------- the builder

class PresetBuilder {
 public:
  PresetBuilder(const Layout& layout, uint64_t seed) : L_(layout), fu_(b_, seed) {}

  absl::StatusOr<Building> Build(std::string name) {
    b_.name = std::move(name);
    for (size_t i = 0; i < L_.levels.size(); ++i) {
      LevelTruth l;
      l.index = static_cast<int>(i);
      l.floor_z = L_.levels[i].floor_z;
      l.ceiling_z = l.floor_z;
      b_.levels.push_back(l);
    }
    AddRooms();
    if (absl::Status s = AddWalls(); !s.ok()) return s;
    AddSlabsAndColumns();
    AddStairs();
    for (const RoomSpec& r : L_.rooms) Furnish(r, L_.levels[r.level].floor_z, fu_);
    for (size_t level = 0; level < L_.levels.size(); ++level) b_.nav.push_back(MakeNav(level));
    ChooseVisitPoints();
    return std::move(b_);
  }

 private:
  double Top(int level) const { return L_.levels[level].floor_z + L_.levels[level].height; }

  void AddRooms() {
    for (size_t i = 0; i < L_.rooms.size(); ++i) {
      const RoomSpec& s = L_.rooms[i];
      RoomTruth r;
      r.id = static_cast<int>(i);
      r.level = s.level;
      r.polygon = RoomOutline(s);
      for (const ColumnSpec& c : s.columns) {
        std::vector<Vector2d> hole = ColumnFootprint(c);
        std::reverse(hole.begin(), hole.end());  // holes are clockwise (docs/DESIGN.md §4)
        r.holes.push_back(hole);
      }
      r.floor_z = L_.levels[s.level].floor_z;
      r.ceiling_z = r.floor_z + s.ceiling_h;
      r.entered = s.entered;
      b_.levels[s.level].ceiling_z = std::max(b_.levels[s.level].ceiling_z, r.ceiling_z);
      b_.rooms.push_back(r);
    }
  }

  absl::Status AddWalls() {
    std::vector<WallLines> lines(L_.levels.size());
    for (const RoomSpec& r : L_.rooms) {
      const AlignedBox2d& q = r.rect;
      WallLines& ls = lines[r.level];
      LineAt(ls, true, q.min().y()).spans.emplace_back(q.min().x(), q.max().x());
      LineAt(ls, true, q.max().y()).spans.emplace_back(q.min().x(), q.max().x());
      LineAt(ls, false, q.min().x()).spans.emplace_back(q.min().y(), q.max().y());
      if (r.east_arc_sagitta <= 0) {
        LineAt(ls, false, q.max().x()).spans.emplace_back(q.min().y(), q.max().y());
      }
    }
    for (size_t i = 0; i < L_.doors.size(); ++i) {
      const DoorSpec& d = L_.doors[i];
      const RoomSpec &a = L_.rooms[d.a], &b = L_.rooms[d.b];
      absl::StatusOr<DoorGeom> g = SharedWallOpening(a, b, d);
      if (!g.ok()) return g.status();
      LineAt(lines[a.level], g->horizontal, g->c).openings.push_back({g->lo, g->hi, 0, kDoorHead});
      door_geoms_.push_back(*g);
      DoorTruth t;
      t.id = static_cast<int>(i);
      t.level = a.level;
      t.room_a = d.a;
      t.room_b = d.b;
      t.p0 = g->horizontal ? Vector2d(g->lo, g->c) : Vector2d(g->c, g->lo);
      t.p1 = g->horizontal ? Vector2d(g->hi, g->c) : Vector2d(g->c, g->hi);
      t.width = d.width;
      b_.doors.push_back(t);
    }
    for (const WindowSpec& w : L_.windows) {
      const RoomSpec& r = L_.rooms[w.room];
      const DoorGeom g = SideLine(r, w.side, w.at, w.width);
      LineAt(lines[r.level], g.horizontal, g.c)
          .openings.push_back({g.lo, g.hi, kSill, kWindowHead});
    }
    for (size_t level = 0; level < lines.size(); ++level) {
      const double z0 = L_.levels[level].floor_z, z1 = Top(level);
      for (const auto& [key, line] : lines[level]) EmitWallLine(line, z0, z1, b_.structure);
      for (const RoomSpec& r : L_.rooms) {
        if (r.level == int(level) && r.east_arc_sagitta > 0) EmitArcWall(r, z0, z1, b_.structure);
      }
      AlignedBox2d extent;
      for (const Prism& p : b_.structure) {
        if (p.z0 >= z0 - 1e-9 && p.z1 <= z1 + 1e-9) {
          for (const Vector2d& v : p.footprint) extent.extend(v);
        }
      }
      extents_.push_back(extent);
    }
    return absl::OkStatus();
  }

  // The floor opening of a stair on its upper level.
  AlignedBox2d StairOpening(const StairSpec& s) const {
    return Rect(s.x_start, s.y0, s.x_start + (s.risers - 1) * kTread, s.y1);
  }

  void AddSlabsAndColumns() {
    for (size_t level = 0; level < L_.levels.size(); ++level) {
      const double z = L_.levels[level].floor_z;
      // Floor slab over the level's extent, cut around stairwell openings into rectangles.
      std::vector<AlignedBox2d> pieces = {extents_[level]};
      for (const StairSpec& s : L_.stairs) {
        if (L_.rooms[s.room_top].level != int(level)) continue;
        const AlignedBox2d hole = StairOpening(s);
        std::vector<AlignedBox2d> next;
        for (const AlignedBox2d& p : pieces) {
          if (!p.intersects(hole)) {
            next.push_back(p);
            continue;
          }
          const AlignedBox2d h = p.intersection(hole);
          next.push_back(Rect(p.min().x(), p.min().y(), p.max().x(), h.min().y()));
          next.push_back(Rect(p.min().x(), h.max().y(), p.max().x(), p.max().y()));
          next.push_back(Rect(p.min().x(), h.min().y(), h.min().x(), h.max().y()));
          next.push_back(Rect(h.max().x(), h.min().y(), p.max().x(), h.max().y()));
        }
        pieces.clear();
        for (const AlignedBox2d& p : next) {
          if (p.sizes().minCoeff() > 1e-9) pieces.push_back(p);
        }
      }
      for (const AlignedBox2d& p : pieces) b_.structure.push_back(Box(p, z - kSlabT, z));
    }
    for (const RoomSpec& r : L_.rooms) {
      const double top = Top(r.level), floor = L_.levels[r.level].floor_z;
      const double ceil = floor + r.ceiling_h;
      // Each room's own ceiling slab fills up to the next floor, so its ceiling height is exact.
      if (!r.open_to_level_above && ceil < top - 1e-9) {
        b_.structure.push_back(Box(r.rect, ceil, top));
        if (r.east_arc_sagitta > 0) {
          const Arc arc = EastArc(r);
          Prism seg;
          for (int i = 0; i <= kArcSegments; ++i) {
            const double a = -arc.half_angle + 2 * arc.half_angle * i / kArcSegments;
            seg.footprint.push_back(arc.center + arc.radius * Vector2d(std::cos(a), std::sin(a)));
          }
          seg.z0 = ceil;
          seg.z1 = top;
          b_.structure.push_back(seg);
        }
      }
      for (const ColumnSpec& c : r.columns) {
        Prism p;
        p.footprint = ColumnFootprint(c);
        p.z0 = floor;
        p.z1 = top;
        b_.structure.push_back(p);
      }
    }
  }

  void AddStairs() {
    for (const StairSpec& s : L_.stairs) {
      const int lo = L_.rooms[s.room_bottom].level, hi = L_.rooms[s.room_top].level;
      const double z0 = L_.levels[lo].floor_z, z1 = L_.levels[hi].floor_z;
      const double riser = (z1 - z0) / s.risers;
      const double ym = 0.5 * (s.y0 + s.y1);
      StairTruth t;
      t.from_level = lo;
      t.to_level = hi;
      t.centerline.emplace_back(s.x_start - 0.4, ym, z0);
      // Solid steps (filled to the floor, like a concrete flight); the last riser rises onto
      // the upper floor itself.
      for (int k = 1; k < s.risers; ++k) {
        const double x0 = s.x_start + (k - 1) * kTread;
        b_.structure.push_back(Box(Rect(x0, s.y0, x0 + kTread, s.y1), z0, z0 + k * riser));
        t.centerline.emplace_back(x0 + kTread / 2, ym, z0 + k * riser);
      }
      const AlignedBox2d hole = StairOpening(s);
      t.centerline.emplace_back(hole.max().x() + 0.6, ym, z1);
      b_.stairs.push_back(t);
      // A 1 m railing on the upper floor along the opening's open sides.
      const double rail = 0.05;
      b_.structure.push_back(
          Box(Rect(hole.min().x() - rail, hole.min().y() - rail, hole.max().x(), hole.min().y()),
              z1, z1 + 1.0));
      b_.structure.push_back(Box(Rect(hole.min().x() - rail, hole.min().y(), hole.min().x(),
                                      L_.rooms[s.room_top].rect.max().y() - kHalfT),
                                 z1, z1 + 1.0));
    }
  }

  // Walkable cells of a level: inside an entered room (or a door between two entered rooms),
  // no solid in the body band, 0.25 m from anything solid and from floor openings.
  NavGrid MakeNav(size_t level) const {
    NavGrid g;
    g.resolution_m = kNavRes;
    const AlignedBox2d& e = extents_[level];
    g.origin = e.min() - Vector2d(0.2, 0.2);
    g.width = static_cast<int>(std::ceil((e.sizes().x() + 0.4) / kNavRes));
    g.height = static_cast<int>(std::ceil((e.sizes().y() + 0.4) / kNavRes));
    const double floor = L_.levels[level].floor_z;
    std::vector<uint8_t> blocked = BlockedCells(g, b_, floor + kBandLo, floor + kBandHi);
    for (const StairSpec& s : L_.stairs) {
      if (L_.rooms[s.room_top].level != int(level)) continue;
      const AlignedBox2d hole = StairOpening(s);
      for (int iy = 0; iy < g.height; ++iy) {
        for (int ix = 0; ix < g.width; ++ix) {
          if (hole.contains(g.CellCenter(ix, iy))) blocked[size_t(iy) * g.width + ix] = 1;
        }
      }
    }
    const std::vector<float> dist = DistanceToBlocked(blocked, g.width, g.height);
    g.free.assign(size_t(g.width) * g.height, 0);
    for (int iy = 0; iy < g.height; ++iy) {
      for (int ix = 0; ix < g.width; ++ix) {
        const size_t i = size_t(iy) * g.width + ix;
        if (dist[i] * kNavRes < kClearance) continue;
        g.free[i] = Allowed(level, g.CellCenter(ix, iy));
      }
    }
    return g;
  }

  bool Allowed(size_t level, const Vector2d& p) const {
    for (const RoomTruth& r : b_.rooms) {
      if (r.level == int(level) && RoomContains(r, p)) return r.entered;
    }
    for (size_t i = 0; i < b_.doors.size(); ++i) {
      const DoorTruth& d = b_.doors[i];
      if (d.level != int(level) || !b_.rooms[d.room_a].entered || !b_.rooms[d.room_b].entered) {
        continue;
      }
      const DoorGeom& g = door_geoms_[i];
      const double along = g.horizontal ? p.x() : p.y(), across = g.horizontal ? p.y() : p.x();
      if (along > g.lo && along < g.hi && std::abs(across - g.c) <= kHalfT + 0.01) return true;
    }
    return false;
  }

  // Each entered room's visit point: its most open walkable cell among those reachable from
  // the start (rooms[0]), crossing levels at stair landings.
  void ChooseVisitPoints() {
    std::vector<std::vector<float>> dist;
    std::vector<std::vector<uint8_t>> reached;
    for (const NavGrid& g : b_.nav) {
      std::vector<uint8_t> blocked(g.free.size());
      for (size_t i = 0; i < g.free.size(); ++i) blocked[i] = !g.free[i];
      dist.push_back(DistanceToBlocked(blocked, g.width, g.height));
      reached.emplace_back(g.free.size(), 0);
    }
    const auto best_cell = [&](size_t room, bool need_reached) {
      const RoomTruth& r = b_.rooms[room];
      const NavGrid& g = b_.nav[r.level];
      long best = -1;
      for (int iy = 0; iy < g.height; ++iy) {
        for (int ix = 0; ix < g.width; ++ix) {
          const size_t i = size_t(iy) * g.width + ix;
          if (!g.free[i] || (need_reached && !reached[r.level][i])) continue;
          if (!RoomContains(r, g.CellCenter(ix, iy))) continue;
          if (best < 0 || dist[r.level][i] > dist[r.level][best]) best = long(i);
        }
      }
      return best;
    };
    const auto flood = [&](int level, long seed) {
      const NavGrid& g = b_.nav[level];
      if (seed < 0 || !g.free[seed] || reached[level][seed]) return;
      std::queue<long> q;
      q.push(seed);
      reached[level][seed] = 1;
      while (!q.empty()) {
        const long i = q.front();
        q.pop();
        const int ix = int(i % g.width), iy = int(i / g.width);
        const int nx[4] = {ix + 1, ix - 1, ix, ix}, ny[4] = {iy, iy, iy + 1, iy - 1};
        for (int k = 0; k < 4; ++k) {
          if (!g.IsFree(nx[k], ny[k])) continue;
          const long j = long(ny[k]) * g.width + nx[k];
          if (!reached[level][j]) {
            reached[level][j] = 1;
            q.push(j);
          }
        }
      }
    };
    const auto cell_index = [&](int level, const Eigen::Vector3d& p) -> long {
      const NavGrid& g = b_.nav[level];
      const Eigen::Vector2i c = g.CellOf(p.head<2>());
      return g.IsFree(c.x(), c.y()) ? long(c.y()) * g.width + c.x() : -1;
    };
    flood(b_.rooms[0].level, best_cell(0, false));
    for (size_t pass = 0; pass < b_.stairs.size(); ++pass) {
      for (const StairTruth& s : b_.stairs) {
        const long bottom = cell_index(s.from_level, s.centerline.front());
        const long top = cell_index(s.to_level, s.centerline.back());
        if (bottom >= 0 && reached[s.from_level][bottom]) flood(s.to_level, top);
        if (top >= 0 && reached[s.to_level][top]) flood(s.from_level, bottom);
      }
    }
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (size_t i = 0; i < b_.rooms.size(); ++i) {
      const long c = b_.rooms[i].entered ? best_cell(i, true) : -1;
      const NavGrid& g = b_.nav[b_.rooms[i].level];
      b_.visit_points.push_back(c < 0 ? Vector2d(nan, nan)
                                      : g.CellCenter(int(c % g.width), int(c / g.width)));
    }
  }

  const Layout& L_;
  Building b_;
  Furnisher fu_;
  std::vector<DoorGeom> door_geoms_;   // same index as b_.doors
  std::vector<AlignedBox2d> extents_;  // per level, of its walls
};

// ---------------------------------------------------------------- the presets' layouts

// One office floor: a hallway (y 5.5–7.9) with rooms south and north of it, a lobby at the
// east end whose east wall is curved, an open-plan room with two columns. `north` lists the
// x splits and kinds of the north rooms. A wing is such a floor moved north by `y0`.
struct FloorPlan {
  int level = 0;
  std::vector<double> north_x;
  std::vector<Kind> north_kinds;
  std::vector<double> ceilings;  // cycled over the rooms, m
  double y0 = 0;                 // the wing's south wall
  std::string wing;              // prefix of its room names
  bool stair_bottom = false;     // its stair room (if any) is a flight's foot, else its top
  bool south_window = true, north_window = true;  // in its exterior walls
};

FloorPlan Floor(int level, std::vector<double> north_x, std::vector<Kind> north_kinds,
                std::vector<double> ceilings) {
  FloorPlan plan;
  plan.level = level;
  plan.north_x = std::move(north_x);
  plan.north_kinds = std::move(north_kinds);
  plan.ceilings = std::move(ceilings);
  return plan;
}

// The floor's depth (south wall to north wall), m.
constexpr double kFloorDepth = 13.0;

void AddOfficeFloor(const FloorPlan& plan, Layout& L) {
  const int level = plan.level;
  const double y0 = plan.y0, kHallY0 = y0 + 5.5, kHallY1 = y0 + 7.9, kDepthN = y0 + kFloorDepth;
  const double kEnd = 32.0;
  const std::vector<double> south_x = {0, 4, 8, 16, 20, 24, 28, kEnd};
  const std::vector<Kind> south_kinds = {Kind::kOffice,  Kind::kOffice, Kind::kOpen,  Kind::kOffice,
                                         Kind::kMeeting, Kind::kOffice, Kind::kOffice};
  const std::vector<double> widths = {0.9, 0.8, 1.6, 1.0, 1.4, 0.85, 1.2, 1.1, 0.95};
  int cycle = 0;
  const auto ceiling = [&] { return plan.ceilings[cycle++ % plan.ceilings.size()]; };

  const int hall = static_cast<int>(L.rooms.size());
  const RoomSpec h = NewRoom(absl::StrCat(plan.wing, "hallway", level), level, Kind::kHall,
                             Rect(0, kHallY0, kEnd, kHallY1), 2.7);
  L.rooms.push_back(h);

  int w = 0;
  for (size_t i = 0; i + 1 < south_x.size(); ++i) {
    RoomSpec r = NewRoom(absl::StrCat(plan.wing, "s", level, "_", i), level, south_kinds[i],
                         Rect(south_x[i], y0, south_x[i + 1], kHallY0), ceiling());
    r.back = Side::kSouth;
    const double width = widths[w++ % widths.size()];
    // Doors alternate between the east and west ends of the hallway wall.
    double at = i % 2 ? south_x[i + 1] - 0.35 - width / 2 : south_x[i] + 0.35 + width / 2;
    if (r.kind == Kind::kOpen) {  // one square and one round column; a central door
      r.columns = {{{10.7, y0 + 2.75}, false, 0.4}, {{13.3, y0 + 2.75}, true, 0.4}};
      at = r.rect.center().x();
    }
    L.rooms.push_back(r);
    L.doors.push_back({hall, int(L.rooms.size()) - 1, at, width});
  }
  for (size_t i = 0; i + 1 < plan.north_x.size(); ++i) {
    RoomSpec r = NewRoom(absl::StrCat(plan.wing, "n", level, "_", i), level, plan.north_kinds[i],
                         Rect(plan.north_x[i], kHallY1, plan.north_x[i + 1], kDepthN), ceiling());
    r.back = Side::kNorth;
    double width = widths[w++ % widths.size()];
    double at = i % 2 ? plan.north_x[i] + 0.35 + width / 2 : plan.north_x[i + 1] - 0.35 - width / 2;
    if (r.kind == Kind::kStorage) r.entered = false;  // seen only through its open door
    if (r.kind == Kind::kStair) {
      r.back = Side::kNorth;
      if (plan.stair_bottom) {
        r.open_to_level_above = true;
        r.ceiling_h = L.levels[level].height - kSlabT;
        width = 1.0, at = plan.north_x[i] + 0.9;  // near the foot of the flight
      } else {
        width = 1.2, at = plan.north_x[i + 1] - 1.1;  // near the top landing
      }
    }
    L.rooms.push_back(r);
    L.doors.push_back({hall, int(L.rooms.size()) - 1, at, width});
  }
  RoomSpec lobby = NewRoom(absl::StrCat(plan.wing, "lobby", level), level, Kind::kLobby,
                           Rect(kEnd, y0, 36, kDepthN), 3.2);
  lobby.east_arc_sagitta = 1.5;  // the curved wall
  L.rooms.push_back(lobby);
  L.doors.push_back({hall, int(L.rooms.size()) - 1, 0.5 * (kHallY0 + kHallY1), 1.8});
  // Windows in the exterior walls of the first south and north rooms.
  if (plan.south_window) L.windows.push_back({hall + 1, Side::kSouth, 2.0, 1.2});
  if (plan.north_window) L.windows.push_back({hall + int(south_x.size()), Side::kNorth, 2.5, 1.5});
}

Layout RoomLayout() {
  Layout L;
  L.levels = {{0.0, 3.0}};
  L.rooms.push_back(NewRoom("room", 0, Kind::kSingle, Rect(0, 0, 6, 5), 2.7));
  L.windows.push_back({0, Side::kNorth, 3.0, 1.4});
  return L;
}

Layout OfficeLayout() {
  Layout L;
  L.levels = {{0.0, 3.5}};
  AddOfficeFloor(Floor(0, {0, 5, 9, 13, 17, 22, 27, 32},
                       {Kind::kOffice, Kind::kMeeting, Kind::kOffice, Kind::kStorage, Kind::kOffice,
                        Kind::kMeeting, Kind::kOffice},
                       {2.6, 2.8, 3.0, 2.7, 2.9}),
                 L);
  return L;
}

Layout Office2Layout() {
  Layout L;
  L.levels = {{0.0, 3.5}, {3.5, 3.5}};
  const std::vector<double> north_x = {0, 5, 9, 13, 18, 23, 32};
  const std::vector<Kind> north_kinds = {Kind::kOffice, Kind::kMeeting, Kind::kOffice,
                                         Kind::kOffice, Kind::kMeeting, Kind::kStair};
  FloorPlan ground = Floor(0, north_x, north_kinds, {2.5, 3.2, 2.8, 3.0, 2.6, 2.9});
  ground.stair_bottom = true;
  AddOfficeFloor(ground, L);
  const int bottom = static_cast<int>(L.rooms.size()) - 2;  // the stair room, before the lobby
  AddOfficeFloor(Floor(1, north_x, north_kinds, {3.1, 2.5, 2.7, 2.9, 2.6}), L);
  const int top = static_cast<int>(L.rooms.size()) - 2;
  // 20 risers of 0.175 m and 19 treads of 0.28 m along the stair room's north wall.
  L.stairs.push_back({bottom, top, 24.3, 11.5, 13.0 - kHalfT, 20});
  return L;
}

// Four levels of three wings side by side (south to north), 12 office floors: a survey of a
// large building, several times office2's walk. On each level the wings' lobbies open into
// each other; the flight from level k to k + 1 is in wing k, so the walk crosses the wings to
// climb.
Layout Office4Layout() {
  constexpr int kLevels = 4, kWings = 3;
  Layout L;
  for (int k = 0; k < kLevels; ++k) L.levels.push_back({3.5 * k, 3.5});
  // Each wing its own rooms (storage rooms are not entered); the last north room is a stair
  // room where a flight starts or ends, else an office.
  const std::vector<std::vector<double>> north_x = {
      {0, 5, 9, 13, 18, 23, 32}, {0, 4, 9, 14, 18, 23, 32}, {0, 6, 10, 14, 19, 23, 32}};
  const std::vector<std::vector<Kind>> north_kinds = {
      {Kind::kOffice, Kind::kMeeting, Kind::kOffice, Kind::kOffice, Kind::kMeeting},
      {Kind::kMeeting, Kind::kOffice, Kind::kStorage, Kind::kOffice, Kind::kOffice},
      {Kind::kOffice, Kind::kOffice, Kind::kMeeting, Kind::kOffice, Kind::kMeeting}};
  const std::vector<std::vector<double>> ceilings = {
      {2.5, 3.2, 2.8, 3.0, 2.6, 2.9}, {3.1, 2.5, 2.7, 2.9, 2.6}, {2.7, 3.0, 2.6, 2.8}};
  std::vector<int> foot(kLevels, -1), head(kLevels, -1);  // stair rooms of each flight
  for (int level = 0; level < kLevels; ++level) {
    int previous_lobby = -1;
    for (int w = 0; w < kWings; ++w) {
      FloorPlan plan =
          Floor(level, north_x[w], north_kinds[w], ceilings[(level + w) % ceilings.size()]);
      plan.y0 = w * kFloorDepth;
      plan.wing = absl::StrCat("w", w, "_");
      plan.south_window = w == 0;
      plan.north_window = w == kWings - 1;
      const bool flight_foot = w == level && level + 1 < kLevels;
      const bool flight_head = w == level - 1;
      plan.stair_bottom = flight_foot;
      plan.north_kinds.push_back(flight_foot || flight_head ? Kind::kStair : Kind::kOffice);
      AddOfficeFloor(plan, L);
      const int lobby = static_cast<int>(L.rooms.size()) - 1;
      if (flight_foot) foot[level] = lobby - 1;
      if (flight_head) head[level - 1] = lobby - 1;
      if (previous_lobby >= 0) L.doors.push_back({previous_lobby, lobby, 34.0, 1.8});
      previous_lobby = lobby;
    }
  }
  for (int k = 0; k + 1 < kLevels; ++k) {
    const double y0 = k * kFloorDepth;
    L.stairs.push_back({foot[k], head[k], 24.3, y0 + 11.5, y0 + kFloorDepth - kHalfT, 20});
  }
  return L;
}

}  // namespace

std::vector<std::string_view> PresetBuildingNames() {
  return {"room", "office", "office2", "office4"};
}

absl::StatusOr<Building> MakePresetBuilding(std::string_view name, uint64_t seed) {
  Layout layout;
  if (name == "room") {
    layout = RoomLayout();
  } else if (name == "office") {
    layout = OfficeLayout();
  } else if (name == "office2") {
    layout = Office2Layout();
  } else if (name == "office4") {
    layout = Office4Layout();
  } else {
    return absl::NotFoundError(absl::StrCat("building preset '", std::string(name),
                                            "': unknown (room, office, office2, office4)"));
  }
  return PresetBuilder(layout, seed).Build(std::string(name));
}

}  // namespace carvemap
