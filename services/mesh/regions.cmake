# Planar regions of the boundary faces (seed §4.2.4, §4.3.3; DESIGN §6 stage 2). Only the
# BoundaryFace struct (a header) is needed, not the code that finds the faces.
add_library(carvemap_mesh_regions planar_regions.cc)
target_link_libraries(carvemap_mesh_regions
                      PUBLIC carvemap_geometry carvemap_tiles Eigen3::Eigen absl::status
                             absl::statusor
                      PRIVATE absl::flat_hash_map absl::raw_hash_set absl::hash absl::strings)
carvemap_add_test(planar_regions_test LIBS carvemap_mesh_regions)
