# Finds every third-party package as an imported target. All come from Debian packages
# (see .ci/run for the list).
find_package(TBB REQUIRED)
find_package(Threads REQUIRED)
find_package(CLI11 REQUIRED)
find_package(nlohmann_json REQUIRED)
find_package(ZLIB REQUIRED)
find_package(zstd CONFIG REQUIRED)  # libzstd-dev: 5.0's compressed .canopy pages
find_package(PNG REQUIRED)

# OpenVDB ships a Find module (and needs Boost.Iostreams through its config).
list(APPEND CMAKE_MODULE_PATH /usr/lib/x86_64-linux-gnu/cmake/OpenVDB)
find_package(OpenVDB REQUIRED)

find_package(OpenMesh REQUIRED)
find_package(CGAL REQUIRED)
find_package(draco REQUIRED)
find_package(OpenEXR REQUIRED)
find_package(TinyGLTF QUIET) # header used directly: we compile the implementation with Draco on

# stb headers (Debian libstb-dev) live in /usr/include/stb
find_path(STB_INCLUDE_DIR stb_image.h PATH_SUFFIXES stb REQUIRED)
add_library(canopy_stb INTERFACE)
target_include_directories(canopy_stb SYSTEM INTERFACE ${STB_INCLUDE_DIR})

if(CANOPY_BUILD_TESTS)
  find_package(GTest REQUIRED)
  include(GoogleTest)
endif()

# Warnings for our own code, in one place.
add_library(canopy_warnings INTERFACE)
target_compile_options(canopy_warnings INTERFACE
  $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wno-unused-parameter>)
