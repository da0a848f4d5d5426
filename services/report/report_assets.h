// The report's page and script (services/report/index.html, report.js), built into the binary
// by embed_assets.cmake.
#pragma once

namespace carvemap {

extern const char* const kReportIndexHtml;
extern const char* const kReportJs;

}  // namespace carvemap
