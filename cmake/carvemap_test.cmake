# The gtest main of every test binary: a private scratch directory per test process.
add_library(carvemap_test_main STATIC ${PROJECT_SOURCE_DIR}/tests/test_main.cc)
target_link_libraries(carvemap_test_main PUBLIC GTest::gtest GTest::gmock)

# carvemap_add_test(name SOURCES a_test.cc ... LIBS lib ... [TIMEOUT seconds])
# One gtest binary per test file; tests are discovered into ctest, each
# with a timeout of 600 s unless TIMEOUT says otherwise.
function(carvemap_add_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;LIBS" ${ARGN})
  if(NOT ARG_SOURCES)
    set(ARG_SOURCES ${name}.cc)
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 600)
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} carvemap_test_main)
  target_compile_definitions(${name} PRIVATE
      CARVEMAP_TEST_DATA_DIR="${CARVEMAP_TEST_DATA_DIR}"
      CARVEMAP_BINARY_DIR="${PROJECT_BINARY_DIR}")
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES TIMEOUT ${ARG_TIMEOUT})
endfunction()
