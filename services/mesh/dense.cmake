# Boundary faces (DESIGN §6 stage 1, seed §4.3.3 Fig 4.9) and dense meshing by dual contouring
# (§4.3.3 "Dense octree meshing"; DESIGN §7 mesh/dense.ply).
add_library(carvemap_mesh_dense boundary_faces.cc dual_contouring.cc)
target_link_libraries(carvemap_mesh_dense PUBLIC carvemap_tiles carvemap_geometry carvemap_fileio
                      absl::status absl::statusor
                      PRIVATE absl::strings absl::str_format absl::flat_hash_map)

carvemap_add_test(boundary_faces_test LIBS carvemap_mesh_dense)
carvemap_add_test(dual_contouring_test LIBS carvemap_mesh_dense carvemap_mesh_checks)
