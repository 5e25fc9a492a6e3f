# canopy_scene_json: the scene instance list (formats/scene_json.{h,cpp}), shared by voxelize
# (writer), lbsolve and octreepack (reader). No OpenVDB: it is sanitized and fuzzed on its own.
add_library(canopy_scene_json STATIC ${CMAKE_CURRENT_LIST_DIR}/scene_json.cpp)
target_include_directories(canopy_scene_json PUBLIC ${CMAKE_CURRENT_LIST_DIR}/..)
target_link_libraries(canopy_scene_json PUBLIC canopy_core nlohmann_json::nlohmann_json PRIVATE canopy_warnings)
