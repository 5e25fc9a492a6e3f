# canopy_mc_reference: the Monte Carlo reference of canopy-play's lighting (pathtrace.cpp) and the
# in-process pipeline comparison (compare.cpp). Included by bench/reference (configured first, and
# built also without the tests) and tests/reference; the first include defines it.
include_guard(GLOBAL)
add_library(canopy_mc_reference STATIC
  ${CMAKE_SOURCE_DIR}/tests/reference/pathtrace.cpp ${CMAKE_SOURCE_DIR}/tests/reference/compare.cpp)
target_include_directories(canopy_mc_reference PUBLIC ${CMAKE_SOURCE_DIR})
target_link_libraries(canopy_mc_reference
  PUBLIC canopy_runtime canopy_octreepack_lib canopy_voxelize_lib canopy_lbsolve_lib canopy_core
  PRIVATE canopy_warnings)
