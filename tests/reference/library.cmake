# canopy_mc_reference: the Monte Carlo reference of canopy-play's lighting (pathtrace.cpp) and the
# in-process pipeline comparison (compare.cpp). Included by tests/reference and bench/reference
# (the bench is configured before the tests and builds without them), whichever comes first.
if(NOT TARGET canopy_mc_reference AND TARGET canopy_runtime AND TARGET canopy_octreepack_lib
   AND TARGET canopy_voxelize_lib AND TARGET canopy_lbsolve_lib)
  add_library(canopy_mc_reference STATIC
    ${CMAKE_SOURCE_DIR}/tests/reference/pathtrace.cpp ${CMAKE_SOURCE_DIR}/tests/reference/compare.cpp)
  target_include_directories(canopy_mc_reference PUBLIC ${CMAKE_SOURCE_DIR})
  target_link_libraries(canopy_mc_reference
    PUBLIC canopy_runtime canopy_octreepack_lib canopy_voxelize_lib canopy_lbsolve_lib canopy_core
    PRIVATE canopy_warnings)
endif()
