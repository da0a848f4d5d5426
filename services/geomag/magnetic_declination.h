// The magnetic declination at a place and date from the World Magnetic Model (WMM2025,
// NOAA/BGS, public domain; data/wmm/), for §2.3's turn from magnetic to true north.
// GeographicLib (Debian's libgeographiclib-dev) evaluates the model: its MagneticModel reads
// only its own file layout, so the NOAA coefficient text is parsed here and handed to it in
// that layout (magnetic.html#magneticformat of its docs) in a private temporary folder.
#ifndef CARVEMAP_SERVICES_GEOMAG_MAGNETIC_DECLINATION_H_
#define CARVEMAP_SERVICES_GEOMAG_MAGNETIC_DECLINATION_H_

#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"

namespace carvemap {

// A NOAA .COF file: Schmidt semi-normalized Gauss coefficients in nT (and nT/year), index
// n(n+1)/2 + m for 0 ≤ m ≤ n ≤ n_max (index 0 unused).
struct WmmCoefficients {
  std::string name;  // e.g. "WMM-2025"
  double epoch = 0;  // decimal year
  int n_max = 0;
  std::vector<double> g, h, g_dot, h_dot;
};

// INVALID_ARGUMENT naming `source` and the line for text that is not a .COF file.
absl::StatusOr<WmmCoefficients> ParseWmmCof(std::string_view text, std::string_view source);

// The model built into carvemap (data/wmm/WMM2025.COF).
const WmmCoefficients& BuiltInWmm();

// Degrees east of true north that magnetic north lies at, at geodetic latitude and longitude
// (degrees, WGS84), height above the ellipsoid (m) and decimal year. OUT_OF_RANGE outside the
// model's five years or for a latitude outside [-90, 90]; UNAVAILABLE if the temporary files
// cannot be written.
absl::StatusOr<double> MagneticDeclinationDeg(const WmmCoefficients& model, double lat_deg,
                                              double lon_deg, double height_m, double year);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_GEOMAG_MAGNETIC_DECLINATION_H_
