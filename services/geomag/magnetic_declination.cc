#include "services/geomag/magnetic_declination.h"

#include <GeographicLib/MagneticModel.hpp>
#include <stdlib.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <system_error>

#include "absl/strings/str_cat.h"

namespace carvemap {

extern const char kBuiltInWmmCof[];  // generated from data/wmm/WMM2025.COF (CMakeLists.txt)

namespace {

namespace fs = std::filesystem;

absl::Status Bad(std::string_view source, int line, std::string_view what) {
  return absl::InvalidArgumentError(
      absl::StrCat(std::string(source), " line ", line, ": ", std::string(what)));
}

void PutInt(std::ostream& o, int32_t v) {
  for (int k = 0; k < 4; ++k) o.put(char((uint32_t(v) >> (8 * k)) & 0xff));
}

void PutDouble(std::ostream& o, double v) {
  uint64_t bits;
  static_assert(sizeof(bits) == sizeof(v));
  std::memcpy(&bits, &v, sizeof(v));
  for (int k = 0; k < 8; ++k) o.put(char((bits >> (8 * k)) & 0xff));
}

// One set of GeographicLib coefficients: N, M, then C and S in column (m) major order.
void PutSet(std::ostream& o, int n_max, const std::vector<double>& c,
            const std::vector<double>& s) {
  PutInt(o, n_max);
  PutInt(o, n_max);
  for (int m = 0; m <= n_max; ++m) {
    for (int n = m; n <= n_max; ++n) PutDouble(o, n == 0 ? 0.0 : c[n * (n + 1) / 2 + m]);
  }
  for (int m = 1; m <= n_max; ++m) {
    for (int n = m; n <= n_max; ++n) PutDouble(o, s[n * (n + 1) / 2 + m]);
  }
}

}  // namespace

absl::StatusOr<WmmCoefficients> ParseWmmCof(std::string_view text, std::string_view source) {
  WmmCoefficients w;
  std::istringstream in{std::string(text)};
  std::string line;
  int number = 0;
  bool header = false;
  while (std::getline(in, line)) {
    ++number;
    std::istringstream fields(line);
    if (!header) {
      std::string date;
      if (!(fields >> w.epoch >> w.name >> date) || !(w.epoch > 1900 && w.epoch < 2200)) {
        return Bad(source, number, "expected the header 'EPOCH NAME DATE'");
      }
      header = true;
      continue;
    }
    if (line.rfind("9999", 0) == 0) break;  // the end marker
    int n = 0, m = 0;
    double g = 0, h = 0, gd = 0, hd = 0;
    if (!(fields >> n >> m >> g >> h >> gd >> hd) || n < 1 || n > 30 || m < 0 || m > n ||
        !std::isfinite(g + h + gd + hd)) {
      return Bad(source, number, "expected 'n m g h g_dot h_dot' with 0 <= m <= n <= 30");
    }
    const size_t size = size_t((n + 1) * (n + 2) / 2);
    for (std::vector<double>* v : {&w.g, &w.h, &w.g_dot, &w.h_dot}) {
      if (v->size() < size) v->resize(size, 0.0);
    }
    const size_t i = size_t(n * (n + 1) / 2 + m);
    w.g[i] = g, w.h[i] = h, w.g_dot[i] = gd, w.h_dot[i] = hd;
    w.n_max = std::max(w.n_max, n);
  }
  if (!header || w.n_max == 0) return Bad(source, number, "no coefficients");
  return w;
}

const WmmCoefficients& BuiltInWmm() {
  static const WmmCoefficients* model = [] {
    absl::StatusOr<WmmCoefficients> parsed = ParseWmmCof(kBuiltInWmmCof, "WMM2025.COF");
    return new WmmCoefficients(parsed.ok() ? *std::move(parsed) : WmmCoefficients{});
  }();
  return *model;
}

absl::StatusOr<double> MagneticDeclinationDeg(const WmmCoefficients& model, double lat_deg,
                                              double lon_deg, double height_m, double year) {
  if (model.n_max == 0) return absl::InternalError("no magnetic model");
  if (!(lat_deg >= -90 && lat_deg <= 90) || !std::isfinite(lon_deg) ||
      !std::isfinite(height_m)) {
    return absl::OutOfRangeError(
        absl::StrCat("location ", lat_deg, ", ", lon_deg, ": latitude must be in [-90, 90]"));
  }
  if (!(year >= model.epoch && year <= model.epoch + 5)) {
    return absl::OutOfRangeError(absl::StrCat("the date ", year, " is outside ", model.name,
                                              "'s years ", model.epoch, " to ",
                                              model.epoch + 5));
  }
  char pattern[] = "/tmp/carvemap-wmm-XXXXXX";
  if (::mkdtemp(pattern) == nullptr) {
    return absl::UnavailableError("cannot make a temporary folder for the magnetic model");
  }
  const fs::path dir(pattern);
  const std::string id = "CARVEWMM";
  {
    std::ofstream meta(dir / "model.wmm");
    meta << "WMMF-2\nName model\nRadius 6371200\nNumModels 1\nEpoch " << model.epoch
         << "\nID " << id << "\n";
    std::ofstream cof(dir / "model.wmm.cof", std::ios::binary);
    cof.write(id.data(), 8);
    PutSet(cof, model.n_max, model.g, model.h);
    PutSet(cof, model.n_max, model.g_dot, model.h_dot);
    if (!meta || !cof) {
      std::error_code ec;
      fs::remove_all(dir, ec);
      return absl::UnavailableError("cannot write the magnetic model's temporary files");
    }
  }
  absl::StatusOr<double> declination;
  try {
    const GeographicLib::MagneticModel geo("model", dir.string());
    double east = 0, north = 0, up = 0;
    geo(year, lat_deg, lon_deg, height_m, east, north, up);
    declination = std::atan2(east, north) * 180 / std::numbers::pi;
  } catch (const std::exception& e) {
    declination = absl::InternalError(absl::StrCat("GeographicLib: ", e.what()));
  }
  std::error_code ec;
  fs::remove_all(dir, ec);
  return declination;
}

}  // namespace carvemap
