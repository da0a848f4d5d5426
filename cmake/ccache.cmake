# Compiles through ccache when it is installed (scripts/install-deps.sh installs Debian's).
# base_dir and no hash of the working directory let a fresh clone elsewhere (CI's) reuse the
# objects an earlier build compiled: the paths under the source tree are made relative before
# hashing. Set CARVEMAP_CCACHE=OFF to compile without it.
option(CARVEMAP_CCACHE "Compile through ccache when it is found" ON)
find_program(CARVEMAP_CCACHE_PROGRAM ccache)
if(CARVEMAP_CCACHE AND CARVEMAP_CCACHE_PROGRAM AND NOT CMAKE_CXX_COMPILER_LAUNCHER)
  get_filename_component(_carvemap_ccache_base "${CMAKE_CURRENT_LIST_DIR}/.." ABSOLUTE)
  set(_carvemap_ccache_launcher
      ${CMAKE_COMMAND} -E env CCACHE_BASEDIR=${_carvemap_ccache_base} CCACHE_NOHASHDIR=1
      ${CARVEMAP_CCACHE_PROGRAM})
  set(CMAKE_C_COMPILER_LAUNCHER ${_carvemap_ccache_launcher})
  set(CMAKE_CXX_COMPILER_LAUNCHER ${_carvemap_ccache_launcher})
  message(STATUS "Compiling through ${CARVEMAP_CCACHE_PROGRAM}")
endif()
