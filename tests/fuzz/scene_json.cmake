# fuzz_scene_json: arbitrary bytes as a scene instance list (formats/scene_json.h).
add_executable(fuzz_scene_json ${CMAKE_CURRENT_LIST_DIR}/fuzz_scene_json.cpp
  ${CMAKE_SOURCE_DIR}/formats/scene_json.cpp)
target_include_directories(fuzz_scene_json PRIVATE ${CMAKE_SOURCE_DIR})
target_compile_options(fuzz_scene_json PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_options(fuzz_scene_json PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_scene_json PRIVATE canopy_core)
