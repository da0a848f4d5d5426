# The dense mesh and the boundary faces of a whole tiles directory, out of core.
add_library(carvemap_merge_dense dense_mesh.cc)
target_link_libraries(carvemap_merge_dense PUBLIC carvemap_merge carvemap_mesh_dense)

# Links the simulator and the carver for tests/support/carved_preset.h (real carved data).
carvemap_add_test(dense_mesh_test LIBS carvemap_merge_dense carvemap_mesh_checks carvemap_sim
                  carvemap_worker)
