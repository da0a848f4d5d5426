#include "storage/scan_types.h"

namespace carvemap {

std::string_view SensorKindName(SensorKind kind) {
  switch (kind) {
    case SensorKind::kLine:
      return "line";
    case SensorKind::kGrid:
      return "grid";
    case SensorKind::kPoints:
      return "points";
  }
  return "unknown";
}

}  // namespace carvemap
