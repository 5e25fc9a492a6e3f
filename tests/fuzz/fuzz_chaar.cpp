// libFuzzer harness for the .chaar reader: any byte string must parse or throw canopy::Error, never
// crash, read out of bounds or hit undefined behaviour. A parsed file is then sampled and decoded
// (the reader's validation must make every index the sampler uses safe).
// Build: cmake -DCANOPY_BUILD_FUZZERS=ON -DCMAKE_CXX_COMPILER=clang++ ...; ninja fuzz_chaar;
// run: ./bin/fuzz_chaar -max_len=65536 tests/haar/data/   (the frozen file is a good seed)
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "canopy/errors.h"
#include "canopy/hash.h"
#include "formats/chaar.h"

using canopy::haar::ChaarHeader;

namespace {

// Rewrites the section and header CRCs of a mutated file so that the fuzzer also reaches the
// semantic checks behind them (slots, records, streams), not only the checksums.
void fixChecksums(std::vector<uint8_t>& b) {
  if (b.size() < sizeof(ChaarHeader)) return;
  ChaarHeader h;
  std::memcpy(&h, b.data(), sizeof h);
  for (auto& s : h.sections)
    if (s.offset <= b.size() && s.size <= b.size() - s.offset) s.crc32 = canopy::crc32(0, b.data() + s.offset, s.size);
  h.headerCrc32 = 0;
  std::memcpy(b.data(), &h, sizeof h);
  if (h.headerSize < sizeof(ChaarHeader) || h.headerSize > b.size()) return;
  h.headerCrc32 = canopy::crc32(0, b.data(), h.headerSize);
  std::memcpy(b.data() + offsetof(ChaarHeader, headerCrc32), &h.headerCrc32, 4);
}

void parseAndUse(const uint8_t* data, size_t size) {
  try {
    const canopy::haar::ChaarData d = canopy::haar::parseChaar(data, size, "fuzz");
    const canopy::haar::ChaarView v = d.view();
    const float pts[4][3] = {{-1e9f, 0, 0}, {0.5f, 1.5f, 2.5f}, {1e9f, 1e9f, 1e9f}, {3.0f, 3.0f, 3.0f}};
    float sink = 0;
    for (uint32_t b = 0; b < d.baseCount(); ++b)
      for (const auto& p : pts) sink += canopy::haar::chaarSample(v, int(b), p[0], p[1], p[2]).g;
    if (d.latticeCells() <= (1u << 16)) {
      std::vector<float> dense;
      canopy::haar::decodeBaseDense(d, 0, dense);
    }
    (void)sink;
  } catch (const canopy::Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  parseAndUse(data, size);
  std::vector<uint8_t> fixed(data, data + size);
  fixChecksums(fixed);
  parseAndUse(fixed.data(), fixed.size());
  return 0;
}
