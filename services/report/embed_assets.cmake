# Writes OUT, a C++ file defining the report's page and script (index.html, report.js) as
# string constants, so that the binary carries them (cmake -P, from CMakeLists.txt).
file(READ "${HTML}" html)
file(READ "${JS}" js)
file(WRITE "${OUT}" "// Generated from services/report/index.html and report.js; do not edit.\n"
     "#include \"services/report/report_assets.h\"\n"
     "namespace carvemap {\n"
     "const char* const kReportIndexHtml = R\"carvemap_asset(${html})carvemap_asset\";\n"
     "const char* const kReportJs = R\"carvemap_asset(${js})carvemap_asset\";\n"
     "}  // namespace carvemap\n")
