// tinygltf_impl.cpp: the one translation unit that compiles tinygltf (with Draco) and stb_image /
// stb_image_write. Debian's prebuilt libtinygltf lacks KHR_draco_mesh_compression, so Canopy
// compiles the header-only implementation itself against libdraco-dev and libstb-dev.
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_ENABLE_DRACO
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_WRITE_IMPLEMENTATION
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wall"
#pragma GCC diagnostic ignored "-Wextra"
#endif
#include <tiny_gltf.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
