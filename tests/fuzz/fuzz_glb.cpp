// fuzz_glb.cpp: libFuzzer harness for the .glb loader. Any input must load or throw
// canopy::Error; a crash, sanitizer report, leak or other exception is a bug.
#include <cstddef>
#include <cstdint>

#include "canopy/errors.h"
#include "mesh_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    const canopy::mesh::Mesh m =
        canopy::mesh::loadGltfFromMemory(data, size, true, "/nonexistent", "fuzz.glb");
    canopy::mesh::requireFinite(m, "fuzz.glb");
  } catch (const canopy::Error&) {
  }
  return 0;
}
