# Planar meshing of the building surfaces (seed §4.2.5, §4.3.3; DESIGN §6 stage 2, §8).
# CGAL (header-only) is used inside planar_mesh.cc only, for the 2D constrained Delaunay
# triangulation of each region.
find_package(CGAL REQUIRED)
add_library(carvemap_mesh_planar planar_mesh.cc)
target_link_libraries(carvemap_mesh_planar
                      PUBLIC carvemap_geometry carvemap_fileio Eigen3::Eigen absl::status
                             absl::statusor
                      PRIVATE carvemap_mesh_checks CGAL::CGAL absl::flat_hash_map absl::raw_hash_set absl::hash
                              absl::strings)

set(_planar_test_libs carvemap_mesh_planar carvemap_mesh_checks)
set(_planar_test_defs)
if(TARGET carvemap_mesh_regions)
  list(APPEND _planar_test_libs carvemap_mesh_regions)
  list(APPEND _planar_test_defs CARVEMAP_HAVE_MESH_REGIONS=1)
endif()
if(TARGET carvemap_mesh_dense)
  list(APPEND _planar_test_libs carvemap_mesh_dense)
  list(APPEND _planar_test_defs CARVEMAP_HAVE_MESH_DENSE=1)
endif()
carvemap_add_test(planar_mesh_test LIBS ${_planar_test_libs})
if(_planar_test_defs)
  target_compile_definitions(planar_mesh_test PRIVATE ${_planar_test_defs})
endif()

# The same test file against real carved data (the simulated `room` preset, carved in-process):
# a separate binary because it links the simulator and the worker.
if(TARGET carvemap_mesh_regions AND TARGET carvemap_mesh_dense AND
   EXISTS ${PROJECT_SOURCE_DIR}/worker/CMakeLists.txt AND
   EXISTS ${PROJECT_SOURCE_DIR}/coordinator/CMakeLists.txt)
  carvemap_add_test(planar_mesh_carved_test SOURCES planar_mesh_test.cc
                    LIBS carvemap_mesh_planar carvemap_mesh_checks carvemap_mesh_regions
                         carvemap_mesh_dense carvemap_sim carvemap_worker)
  target_compile_definitions(planar_mesh_carved_test PRIVATE CARVEMAP_PLANAR_CARVED_ONLY=1
                             CARVEMAP_HAVE_MESH_REGIONS=1 CARVEMAP_HAVE_MESH_DENSE=1)
endif()
