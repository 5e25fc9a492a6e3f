# fuzz_canopy: the .canopy reader (formats/canopy_file.cpp and page_coding.cpp compiled in, with
# ASan/UBSan; libzstd itself is not instrumented).
# Seed corpus: tests/octreepack/data/*.canopy.
add_executable(fuzz_canopy ${CMAKE_CURRENT_LIST_DIR}/fuzz_canopy.cpp ${CMAKE_SOURCE_DIR}/formats/canopy_file.cpp
                           ${CMAKE_SOURCE_DIR}/formats/page_coding.cpp)
target_include_directories(fuzz_canopy PRIVATE ${CMAKE_SOURCE_DIR})
target_compile_options(fuzz_canopy PRIVATE -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all)
target_link_options(fuzz_canopy PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_canopy PRIVATE canopy_core zstd::libzstd_shared canopy_warnings)
