# canopy_file: the .canopy reader (formats/canopy_file.{h,cpp}). No OpenVDB, so it compiles fast,
# can be sanitized (tests compile canopy_file.cpp into themselves) and fuzzed.
# page_coding.cpp: 5.0's compressed pages (Zstandard), decoded here and encoded by the writer.
add_library(canopy_file STATIC ${CMAKE_CURRENT_LIST_DIR}/canopy_file.cpp ${CMAKE_CURRENT_LIST_DIR}/page_coding.cpp)
target_include_directories(canopy_file PUBLIC ${CMAKE_CURRENT_LIST_DIR}/..)
target_link_libraries(canopy_file PUBLIC canopy_core zstd::libzstd_shared PRIVATE canopy_warnings)

# canopy_file_write: the .canopy writer (no OpenVDB either).
# canopy_haar_pages.cpp re-pages a .chaar's bricks as a model's Haar light.
add_library(canopy_file_write STATIC ${CMAKE_CURRENT_LIST_DIR}/canopy_write.cpp ${CMAKE_CURRENT_LIST_DIR}/canopy_haar_pages.cpp)
target_link_libraries(canopy_file_write PUBLIC canopy_file canopy_chaar PRIVATE canopy_warnings)
