# fuzz_lbsolve_params: arbitrary bytes as an lbsolve parameter file (JSON -> LightParams).
add_executable(fuzz_lbsolve_params ${CMAKE_CURRENT_LIST_DIR}/fuzz_lbsolve_params.cpp
  ${CMAKE_SOURCE_DIR}/tools/lbsolve/params.cpp)
target_include_directories(fuzz_lbsolve_params PRIVATE ${CMAKE_SOURCE_DIR}/tools/lbsolve)
target_compile_options(fuzz_lbsolve_params PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_options(fuzz_lbsolve_params PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_lbsolve_params PRIVATE canopy_core)
