#include "services/geomag/magnetic_declination.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace carvemap {
namespace {

// NOAA's 100 test points of WMM2025 (dates 2025.0 to 2029.5, heights 0–100 km, the whole
// globe; tests/data/SOURCES.md): the declination within their printed 0.01°. The file also
// holds earlier models' points (before 2025), which WMM2025 does not cover.
TEST(MagneticDeclinationTest, MatchesNoaasTestValues) {
  const WmmCoefficients& model = BuiltInWmm();
  ASSERT_EQ(model.name, "WMM-2025");
  ASSERT_EQ(model.n_max, 12);
  std::ifstream in(CARVEMAP_WMM_TEST_VALUES);
  ASSERT_TRUE(in) << CARVEMAP_WMM_TEST_VALUES;
  std::string line;
  std::getline(in, line);  // header
  int points = 0;
  double worst = 0;
  while (std::getline(in, line)) {
    // date,alt,lat,lon,x,y,z,h,f,incl,decl,gv
    std::vector<double> v;
    std::istringstream fields(line);
    for (std::string cell; std::getline(fields, cell, ',');) v.push_back(std::stod(cell));
    ASSERT_EQ(v.size(), 12u) << line;
    const double year = v[0], height_km = v[1], lat = v[2], lon = v[3], declination = v[10];
    if (year < model.epoch) continue;
    absl::StatusOr<double> d = MagneticDeclinationDeg(model, lat, lon, height_km * 1000, year);
    ASSERT_TRUE(d.ok()) << d.status() << " at " << line;
    worst = std::max(worst, std::abs(*d - declination));
    EXPECT_NEAR(*d, declination, 0.0051) << line;
    ++points;
  }
  EXPECT_EQ(points, 100);
  RecordProperty("worst_error_deg", std::to_string(worst));
}

TEST(MagneticDeclinationTest, RefusesWhatTheModelDoesNotCover) {
  const WmmCoefficients& model = BuiltInWmm();
  absl::StatusOr<double> d = MagneticDeclinationDeg(model, 48, 11, 0, 2031.0);
  EXPECT_EQ(d.status().code(), absl::StatusCode::kOutOfRange);
  EXPECT_NE(d.status().message().find("WMM-2025"), std::string::npos) << d.status();
  d = MagneticDeclinationDeg(model, 91, 11, 0, 2026.0);
  EXPECT_EQ(d.status().code(), absl::StatusCode::kOutOfRange);
}

TEST(MagneticDeclinationTest, ParseErrorsNameTheLine) {
  absl::StatusOr<WmmCoefficients> w = ParseWmmCof("2025.0 WMM-2025 11/13/2024\n1 0 x\n", "a.cof");
  ASSERT_FALSE(w.ok());
  EXPECT_NE(w.status().message().find("a.cof line 2"), std::string::npos) << w.status();
  EXPECT_FALSE(ParseWmmCof("", "b.cof").ok());
}

}  // namespace
}  // namespace carvemap
