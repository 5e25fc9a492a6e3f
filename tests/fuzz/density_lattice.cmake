# fuzz_density_lattice: the density lattice reader (formats/density_lattice.cpp and the VDB layer
# formats/lattice_vdb.cpp compiled in, with ASan/UBSan; OpenVDB itself is not instrumented).
add_executable(fuzz_density_lattice ${CMAKE_CURRENT_LIST_DIR}/fuzz_density_lattice.cpp
  ${CMAKE_SOURCE_DIR}/formats/density_lattice.cpp ${CMAKE_SOURCE_DIR}/formats/lattice_vdb.cpp)
target_include_directories(fuzz_density_lattice PRIVATE ${CMAKE_SOURCE_DIR})
target_compile_options(fuzz_density_lattice PRIVATE -fsanitize=fuzzer,address,undefined -fno-omit-frame-pointer)
target_link_options(fuzz_density_lattice PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_density_lattice PRIVATE OpenVDB::openvdb canopy_core)
