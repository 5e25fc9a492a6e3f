# fuzz_glb: the glTF binary loader (GLB container, tinygltf JSON, Draco, accessors, images).
#   build-fuzz/tests/fuzz/fuzz_glb -max_len=65536 corpus/   (seed corpus: canopy-voxelize --write-sample)
set(vox_src ${CMAKE_SOURCE_DIR}/tools/voxelize)
add_executable(fuzz_glb ${CMAKE_CURRENT_SOURCE_DIR}/fuzz_glb.cpp
  ${vox_src}/tinygltf_impl.cpp ${vox_src}/gltf_loader.cpp ${vox_src}/openmesh_loader.cpp ${vox_src}/ply_loader.cpp)
target_include_directories(fuzz_glb PRIVATE ${vox_src})
target_compile_definitions(fuzz_glb PRIVATE _USE_MATH_DEFINES)
target_compile_options(fuzz_glb PRIVATE -fsanitize=fuzzer,address,undefined -fno-omit-frame-pointer)
target_link_options(fuzz_glb PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_glb PRIVATE canopy_core draco::draco OpenMeshCore canopy_stb nlohmann_json::nlohmann_json)

# fuzz_ply: the PLY reader (tools/voxelize/ply_loader.cpp; header, ascii and binary bodies).
#   build-fuzz/tests/fuzz/fuzz_ply -max_len=4096 -timeout=5 corpus/   (seed: any small .ply)
add_executable(fuzz_ply ${CMAKE_CURRENT_SOURCE_DIR}/fuzz_ply.cpp ${vox_src}/ply_loader.cpp)
target_include_directories(fuzz_ply PRIVATE ${vox_src})
target_compile_options(fuzz_ply PRIVATE -fsanitize=fuzzer,address,undefined -fno-omit-frame-pointer)
target_link_options(fuzz_ply PRIVATE -fsanitize=fuzzer,address,undefined)
target_link_libraries(fuzz_ply PRIVATE canopy_core canopy_stb)
