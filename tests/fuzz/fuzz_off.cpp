// fuzz_off.cpp: libFuzzer harness for Canopy's OFF reader (ASCII [ST][C][N]OFF).
// Any input must load or throw canopy::Error, promptly; a crash, sanitizer report, leak, hang or
// other exception is a bug.
#include <cstddef>
#include <cstdint>

#include "canopy/errors.h"
#include "mesh_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    const canopy::mesh::Mesh m = canopy::mesh::loadOffFromMemory(data, size, "fuzz.off");
    (void)m;
  } catch (const canopy::Error&) {
  }
  return 0;
}
