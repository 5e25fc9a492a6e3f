# fuzz_glb: the glTF binary loader (GLB container, tinygltf JSON, Draco, accessors, images).
#   build-fuzz/bin/fuzz_glb -max_len=65536 corpus/   (seed corpus: canopy-voxelize --write-sample)
set(vox_src ${CMAKE_SOURCE_DIR}/tools/voxelize)
add_executable(fuzz_glb ${CMAKE_CURRENT_SOURCE_DIR}/fuzz_glb.cpp
  ${vox_src}/tinygltf_impl.cpp ${vox_src}/gltf_loader.cpp ${vox_src}/gltf_scene.cpp ${vox_src}/openmesh_loader.cpp
  ${vox_src}/ply_loader.cpp ${vox_src}/off_loader.cpp)
target_include_directories(fuzz_glb PRIVATE ${vox_src} ${CMAKE_SOURCE_DIR})
target_compile_definitions(fuzz_glb PRIVATE _USE_MATH_DEFINES)
target_compile_options(fuzz_glb PRIVATE -fsanitize=fuzzer,address,undefined -fno-omit-frame-pointer)
target_link_options(fuzz_glb PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_glb PRIVATE canopy_core canopy_scene_json draco::draco OpenMeshCore canopy_stb nlohmann_json::nlohmann_json)

# fuzz_ply: the PLY reader (tools/voxelize/ply_loader.cpp; header, ascii and binary bodies).
#   build-fuzz/bin/fuzz_ply -max_len=4096 -timeout=5 corpus/   (seed: any small .ply)
add_executable(fuzz_ply ${CMAKE_CURRENT_SOURCE_DIR}/fuzz_ply.cpp ${vox_src}/ply_loader.cpp)
target_include_directories(fuzz_ply PRIVATE ${vox_src})
target_compile_options(fuzz_ply PRIVATE -fsanitize=fuzzer,address,undefined -fno-omit-frame-pointer)
target_link_options(fuzz_ply PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_ply PRIVATE canopy_core canopy_stb)

# fuzz_off: the OFF reader (tools/voxelize/off_loader.cpp; keyword, counts, vertices, faces, colours).
#   build-fuzz/bin/fuzz_off -max_len=4096 -timeout=5 corpus/   (seed: any small .off)
add_executable(fuzz_off ${CMAKE_CURRENT_SOURCE_DIR}/fuzz_off.cpp ${vox_src}/off_loader.cpp)
target_include_directories(fuzz_off PRIVATE ${vox_src})
target_compile_options(fuzz_off PRIVATE -fsanitize=fuzzer,address,undefined -fno-omit-frame-pointer)
target_link_options(fuzz_off PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_off PRIVATE canopy_core canopy_stb)
