// libFuzzer harness for the density lattice reader (formats/density_lattice.h, the one contract
// canopy-lbsolve, canopy-octreepack and canopy-voxelize info read lattices through): any byte string
// must read or throw canopy::Error, never crash or hit undefined behaviour. The UUID checksum is
// re-derived from the mutated bytes (vdbio::rewriteUuid) so that the fuzzer reaches OpenVDB's
// parser and the grid and value checks behind it, not only the checksum.
// Build: cmake -DCANOPY_BUILD_FUZZERS=ON -DCMAKE_CXX_COMPILER=clang++ ...; ninja fuzz_density_lattice;
// run: ./bin/fuzz_density_lattice -max_len=65536 corpus/   (seed: canopy-voxelize --write-sample s.glb
// && canopy-voxelize s.glb -r 16 -o corpus/s.vdb)
// Known finding (2026-12-04, first 90 s): with the checksum re-derived, a changed size field makes
// OpenVDB's blosc reader (io::bloscFromStream) allocate what the stream says, and libFuzzer stops
// on out-of-memory; OpenVDB reads that size before any check of ours can run. Files with Canopy's
// content UUID only get there through a deliberately re-derived checksum.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "canopy/errors.h"
#include "formats/density_lattice.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = "/tmp/fuzz_density_lattice." + std::to_string(getpid()) + ".vdb";
  std::string bytes(reinterpret_cast<const char*>(data), size);
  canopy::vdbio::rewriteUuid(bytes);  // false (left as is) where there is no VDB header
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
  try {
    const canopy::vdbio::DensityLattice L = canopy::vdbio::readDensityLattice(path);
    for (const canopy::vdbio::DensityCell& c : L.cells)  // what the reader promises
      if (!(c.density > 0.f && c.density <= 1.f && c.wood >= 0.f && c.wood <= 1.f)) __builtin_trap();
  } catch (const canopy::Error&) {
  }
  return 0;
}
