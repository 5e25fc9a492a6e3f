// The .chaar reader under AddressSanitizer/UBSan (chaar.cpp and haar_encode.cpp are compiled into
// this test with sanitizers): the frozen v1.0 file decodes to the same values forever; every
// truncated prefix, every flipped byte, wrong versions, trailing bytes and semantically broken
// files with valid checksums are rejected with canopy::Error(InvalidInput) naming the file.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "canopy/atomic_file.h"
#include "canopy/hash.h"
#include "formats/chaar.h"
#include "formats/haar_encode.h"
#include "synthetic_light.h"

using namespace canopy::haar;

namespace {

// Printed once when the frozen file was written (XXH64 of every base's decoded cells, in base
// order, and one sample of B03 at (0.25, 2.5, 1.75) = 0.477340698, 0.530464172, 0.397865295).
constexpr uint64_t FROZEN_DENSE_HASH = 0x4e4bcc7bfce5a027ULL;
constexpr float FROZEN_SAMPLE_R = 0x1.e8ccp-2f, FROZEN_SAMPLE_G = 0x1.0f99p-1f, FROZEN_SAMPLE_B = 0x1.976ap-2f;

// The same, printed once when the quantised 2.0 file was written (B03 at the same point =
// 0.499171644, 0.550343215, 0.414585859: the sampler's bits, CPU and GPU).
constexpr uint64_t FROZEN2_DENSE_HASH = 0x6dac22a9050ef3baULL;
constexpr float FROZEN2_SAMPLE_R = 0x1.ff26dap-2f, FROZEN2_SAMPLE_G = 0x1.19c696p-1f, FROZEN2_SAMPLE_B = 0x1.a88932p-2f;

// And for the 2.1 file (raw quantised bricks; B03 at the same point = 0.560000002, 0.560000002,
// 0.400000006).
constexpr uint64_t FROZEN21_DENSE_HASH = 0x7fca36a1f7295f72ULL;
constexpr float FROZEN21_SAMPLE_R = 0x1.1eb852p-1f, FROZEN21_SAMPLE_G = 0x1.1eb852p-1f, FROZEN21_SAMPLE_B = 0x1.99999ap-2f;

const std::string kFrozen = std::string(CANOPY_SOURCE_DIR) + "/tests/haar/data/small_v1_0.chaar";
const std::string kFrozen2 = std::string(CANOPY_SOURCE_DIR) + "/tests/haar/data/small_v2_0.chaar";
const std::string kFrozen21 = std::string(CANOPY_SOURCE_DIR) + "/tests/haar/data/small_v2_1.chaar";

std::vector<uint8_t> frozenBytes(const std::string& path = kFrozen) {
  const auto b = canopy::readFile(path);
  return std::vector<uint8_t>(b.begin(), b.end());
}

// Expects parseChaar to throw InvalidInput whose message starts with the file's name.
void expectRejected(const std::vector<uint8_t>& bytes, const std::string& what, const std::string& needle = "") {
  try {
    parseChaar(bytes.data(), bytes.size(), "frozen.chaar");
    ADD_FAILURE() << what << ": accepted";
  } catch (const canopy::Error& e) {
    EXPECT_EQ(e.code(), canopy::ExitCode::InvalidInput) << what;
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("frozen.chaar: ", 0), 0u) << what << ": " << m;
    if (!needle.empty()) {
      EXPECT_NE(m.find(needle), std::string::npos) << what << ": " << m;
    }
  }
}

uint64_t denseHash(const ChaarData& d) {
  canopy::Hasher h;
  std::vector<float> dense;
  for (uint32_t b = 0; b < d.baseCount(); ++b) {
    decodeBaseDense(d, b, dense);
    h.update(dense.data(), dense.size() * sizeof(float));
  }
  return h.digest();
}

// Rewrites the header CRC after an edit (so that only the edited field is wrong).
void fixHeaderCrc(std::vector<uint8_t>& bytes) {
  uint32_t zero = 0;
  std::memcpy(&bytes[offsetof(ChaarHeader, headerCrc32)], &zero, 4);
  uint32_t hs;
  std::memcpy(&hs, &bytes[12], 4);
  const uint32_t crc = canopy::crc32(0, bytes.data(), hs);
  std::memcpy(&bytes[offsetof(ChaarHeader, headerCrc32)], &crc, 4);
}

}  // namespace

// Frozen by `canopy-haar small.light.vdb -o small_v1_0.chaar --threshold 0.02 --precision fp16`
// (see tests/haar/data/README.md); these values were printed when it was written and must never
// change while the format is 1.x.
TEST(ChaarFrozen, DecodesToKnownValues) {
  const std::vector<uint8_t> bytes = frozenBytes();
  const ChaarData d = parseChaar(bytes.data(), bytes.size(), kFrozen);
  EXPECT_EQ(d.header.versionMajor, 1);
  EXPECT_EQ(d.header.versionMinor, 0);
  EXPECT_EQ(d.baseCount(), 19u);
  EXPECT_EQ(d.precision(), Precision::Fp16);
  EXPECT_EQ(d.header.latticeMin[0], -2);
  EXPECT_EQ(d.header.latticeMax[2], 5);
  EXPECT_FLOAT_EQ(d.header.threshold, 0.02f);
  EXPECT_EQ(d.bases[7].direction[0], 1);
  EXPECT_EQ(d.bases[7].direction[1], 1);
  EXPECT_EQ(denseHash(d), FROZEN_DENSE_HASH);
  const ChaarView v = d.view();
  const Rgb s = chaarSample(v, 3, 0.25f, 2.5f, 1.75f);
  EXPECT_EQ(s.r, FROZEN_SAMPLE_R);
  EXPECT_EQ(s.g, FROZEN_SAMPLE_G);
  EXPECT_EQ(s.b, FROZEN_SAMPLE_B);
  // Byte-identical round trip through the writer.
  ChaarData copy = d;
  EXPECT_EQ(serializeChaar(copy), bytes);
}

// A frozen quantised file: its version, step, raw and Haar brick counts, decoded values (hash),
// one sample's bits, and its byte-identical round trip.
void expectFrozenQuant(const std::string& path, uint16_t minor, float step, size_t raw, size_t haar, uint64_t hash,
                       const float sample[3]) {
  const std::vector<uint8_t> bytes = frozenBytes(path);
  const ChaarData d = parseChaar(bytes.data(), bytes.size(), path);
  EXPECT_EQ(d.header.versionMajor, 2);
  EXPECT_EQ(d.header.versionMinor, minor);
  EXPECT_EQ(d.baseCount(), 19u);
  EXPECT_EQ(d.precision(), Precision::Quant);
  EXPECT_FLOAT_EQ(d.header.threshold, step);
  EXPECT_FLOAT_EQ(d.bases[5].quantStep, step);
  size_t r = 0, h = 0;
  for (const QuantRecord& q : d.quantRecords) {
    r += q.raw();
    h += !q.raw() && q.mask() != 0;
  }
  EXPECT_EQ(r, raw);
  EXPECT_EQ(h, haar);
  const Rgb s = chaarSample(d.view(), 3, 0.25f, 2.5f, 1.75f);
  EXPECT_EQ(denseHash(d), hash);
  EXPECT_EQ(s.r, sample[0]);
  EXPECT_EQ(s.g, sample[1]);
  EXPECT_EQ(s.b, sample[2]);
  ChaarData copy = d;
  EXPECT_EQ(serializeChaar(copy), bytes);
}

// Frozen by `canopy-haar small.light.vdb -o small_v2_0.chaar --threshold 0.004 --precision quant`
// (the same input; tests/haar/data/README.md): must never change while the format is 2.x.
TEST(ChaarFrozen, QuantisedV2DecodesToKnownValues) {
  const float sample[3] = {FROZEN2_SAMPLE_R, FROZEN2_SAMPLE_G, FROZEN2_SAMPLE_B};
  expectFrozenQuant(kFrozen2, 0, 0.004f, 0, 152, FROZEN2_DENSE_HASH, sample);
}

// Frozen by `canopy-haar small.light.vdb -o small_v2_1.chaar --threshold 0.04 --precision quant`
// (the same input, 2026-12-02): 80 of its 150 bricks with light are raw. Must never change while the
// format is 2.x.
TEST(ChaarFrozen, QuantisedV21WithRawBricksDecodesToKnownValues) {
  const float sample[3] = {FROZEN21_SAMPLE_R, FROZEN21_SAMPLE_G, FROZEN21_SAMPLE_B};
  expectFrozenQuant(kFrozen21, 1, 0.04f, 80, 70, FROZEN21_DENSE_HASH, sample);
}

TEST(ChaarFrozen, EveryTruncatedPrefixIsRejected) {
  for (const std::string& path : {kFrozen, kFrozen2, kFrozen21}) {
    const std::vector<uint8_t> bytes = frozenBytes(path);
    for (size_t n = 0; n < bytes.size(); ++n) {
      std::vector<uint8_t> t(bytes.begin(), bytes.begin() + long(n));
      expectRejected(t, path + " prefix " + std::to_string(n));
    }
  }
}

TEST(ChaarFrozen, EveryFlippedByteIsRejected) {
  for (const std::string& path : {kFrozen, kFrozen2, kFrozen21}) {
    std::vector<uint8_t> bytes = frozenBytes(path);
    for (size_t i = 0; i < bytes.size(); ++i) {
      for (uint8_t flip : {uint8_t(0x01), uint8_t(0x80)}) {
        bytes[i] ^= flip;
        expectRejected(bytes, path + " flip at " + std::to_string(i));
        bytes[i] ^= flip;
      }
    }
  }
}

TEST(ChaarFrozen, TrailingBytesAndVersionsAreRejected) {
  std::vector<uint8_t> bytes = frozenBytes();
  std::vector<uint8_t> longer = bytes;
  longer.push_back(0);
  expectRejected(longer, "trailing byte", "trailing");

  std::vector<uint8_t> v2 = bytes;
  const uint16_t major2 = 2;
  std::memcpy(&v2[8], &major2, 2);
  fixHeaderCrc(v2);
  expectRejected(v2, "major 2", "float coefficients in a 2.x file");
  std::vector<uint8_t> v3 = bytes;
  const uint16_t major3 = 3;
  std::memcpy(&v3[8], &major3, 2);
  fixHeaderCrc(v3);
  expectRejected(v3, "major 3", "newer than this reader");
  std::vector<uint8_t> v0 = bytes;
  const uint16_t major0 = 0;
  std::memcpy(&v0[8], &major0, 2);
  fixHeaderCrc(v0);
  expectRejected(v0, "major 0", "unsupported .chaar major version");
  // A newer minor version of the same major is read.
  std::vector<uint8_t> minor = bytes;
  const uint16_t minor9 = 9;
  std::memcpy(&minor[10], &minor9, 2);
  fixHeaderCrc(minor);
  EXPECT_NO_THROW(parseChaar(minor.data(), minor.size(), "minor"));

  std::vector<uint8_t> magic = bytes;
  magic[0] = 'X';
  expectRejected(magic, "magic", "bad magic");
  expectRejected({}, "empty", "bad magic");
}

// Files whose checksums are right but whose content is inconsistent (a buggy writer, or a crafted
// file): the semantic checks must catch them.
TEST(ChaarFormat, ValidChecksumsButBadIndicesAreRejected) {
  using namespace canopy::haar::testing;
  const LatticeGeom g = makeGeom(7, 6, 5);
  const ChaarData good = encodeLights(g, {smoothLight(g, 1), randomLight(g, 2)}, 0.01f);
  auto rejects = [&](const char* what, const std::string& needle, auto edit) {
    ChaarData d = good;
    edit(d);
    const std::vector<uint8_t> bytes = serializeChaar(d);
    expectRejected(bytes, what, needle);
  };
  ASSERT_GT(good.header.slotCount, 1u);
  rejects("slot out of range", "out of range", [](ChaarData& d) {
    for (auto& s : d.slots)
      if (s != kEmptySlot) { s = d.header.slotCount + 3; break; }
  });
  rejects("slot twice", "used by two bricks", [](ChaarData& d) {
    uint32_t* first = nullptr;
    for (auto& s : d.slots)
      if (s != kEmptySlot) {
        if (!first) first = &s;
        else { s = *first; break; }
      }
  });
  rejects("record first", "coefficient index", [](ChaarData& d) { d.records[1].firstAndRaw += 1; });
  rejects("record mask", "coefficient", [](ChaarData& d) { d.records[0].maskHi ^= 0x80000000u; });
  rejects("raw empty brick", "empty brick flagged raw", [](ChaarData& d) {
    for (auto& r : d.records)
      if (r.mask() == 0) {
        r.firstAndRaw |= BrickRecord::kRawBit;
        return;
      }
    d.records[0].set(0, d.records[0].first(), true);  // (no empty record: make one)
  });
  rejects("base stream", "out of range", [](ChaarData& d) { d.bases[1].coefOffset += 1; });
  rejects("brick dims", "brick grid", [](ChaarData& d) {
    d.header.brickDims[0] += 1;
    d.slots.resize(d.brickCount(), kEmptySlot);
  });
  rejects("nan coefficient", "non-finite", [](ChaarData& d) { d.coefs32[4] = NAN; });
  rejects("base count", "bad base count", [](ChaarData& d) {
    d.bases.resize(40, d.bases[0]);
    d.records.resize(40 * size_t(d.header.slotCount));
  });
  rejects("precision", "unknown coefficient precision", [](ChaarData& d) { d.header.precision = 7; });
  rejects("transform", "transform", [](ChaarData& d) { d.header.indexToModel[3] = 1; });
  rejects("direction", "direction", [](ChaarData& d) { d.bases[0].direction[2] = 5; });
  // The untouched file passes.
  ChaarData ok = good;
  const std::vector<uint8_t> bytes = serializeChaar(ok);
  EXPECT_NO_THROW(parseChaar(bytes.data(), bytes.size(), "ok"));
}

// Format 1.1: a sun base flagged kChaarBaseScattered (its direct beam removed by lbsolve). A flag
// makes the writer write 1.1; without flags it writes 1.0 (the frozen file above stays byte-identical).
// Flags in a 1.0 file, unknown flags and a flagged ambient base are rejected.
TEST(ChaarFormat, ScatteredSunBaseFlagsAreVersion1_1) {
  using namespace canopy::haar::testing;
  const LatticeGeom g = makeGeom(7, 6, 5);
  ChaarData plain = encodeLights(g, {smoothLight(g, 1), smoothLight(g, 2), randomLight(g, 3)}, 0.01f);
  EXPECT_EQ(parseChaar(serializeChaar(plain).data(), serializeChaar(plain).size(), "plain").header.versionMinor, 0);
  ChaarData flagged = plain;
  const int32_t dirs[3][3] = {{0, 0, 0}, {1, 0, 0}, {-1, 0, 0}};  // B00 (ambient), then two sun bases
  for (uint32_t b = 0; b < 3; ++b)
    for (int a = 0; a < 3; ++a) flagged.bases[b].direction[a] = dirs[b][a];
  flagged.bases[1].flags = kChaarBaseScattered;
  flagged.bases[2].flags = kChaarBaseScattered;
  std::vector<uint8_t> bytes = serializeChaar(flagged);
  const ChaarData back = parseChaar(bytes.data(), bytes.size(), "flagged");
  EXPECT_EQ(back.header.versionMinor, 1);
  EXPECT_EQ(back.bases[0].flags, 0u);
  EXPECT_EQ(back.bases[1].flags, uint32_t(kChaarBaseScattered));
  EXPECT_EQ(back.bases[2].flags, uint32_t(kChaarBaseScattered));
  ChaarData again = back;
  EXPECT_EQ(serializeChaar(again), bytes);  // round trip, byte for byte

  std::vector<uint8_t> asV10 = bytes;  // the same bases claiming to be 1.0
  const uint16_t minor0 = 0;
  std::memcpy(&asV10[10], &minor0, 2);
  fixHeaderCrc(asV10);
  expectRejected(asV10, "flags in 1.0", "has flags in a 1.0 file");
  ChaarData unknown = flagged;
  unknown.bases[1].flags = 2;
  expectRejected(serializeChaar(unknown), "unknown flag", "unknown flags");
  ChaarData ambient = flagged;
  ambient.bases[0].flags = kChaarBaseScattered;
  expectRejected(serializeChaar(ambient), "ambient flagged", "ambient base");
  // A newer minor may define more flags: not rejected there.
  std::vector<uint8_t> newer = serializeChaar(unknown);
  const uint16_t minor2 = 2;
  std::memcpy(&newer[10], &minor2, 2);
  fixHeaderCrc(newer);
  EXPECT_NO_THROW(parseChaar(newer.data(), newer.size(), "newer"));
}

// Quantised (2.0) files whose checksums are right but whose records, streams or steps are not.
TEST(ChaarFormat, QuantisedFilesWithBadFieldsAreRejected) {
  using namespace canopy::haar::testing;
  const LatticeGeom g = makeGeom(7, 6, 5);
  const ChaarData good = encodeLights(g, {smoothLight(g, 1), randomLight(g, 2)}, 0.03f, -1.0f, Precision::Quant);
  {
    ChaarData copy = good;
    const std::vector<uint8_t> bytes = serializeChaar(copy);
    const ChaarData back = parseChaar(bytes.data(), bytes.size(), "good");
    EXPECT_EQ(back.header.versionMajor, 2);
    EXPECT_EQ(back.header.versionMinor, 1) << "raw bricks: a 2.1 file";
    EXPECT_EQ(back.quantWords, good.quantWords);
    ChaarData again = back;
    EXPECT_EQ(serializeChaar(again), bytes);
  }
  auto rejects = [&](const char* what, const std::string& needle, auto edit) {
    ChaarData d = good;
    edit(d);
    expectRejected(serializeChaar(d), what, needle);
  };
  // The first Haar slot of base 0 with an average and details, its first raw slot, and the base's
  // used bits.
  const uint32_t slots = good.header.slotCount;
  const size_t records = good.quantRecords.size();
  size_t full = records, raw = records;  // (in any base)
  uint64_t used = 0;
  for (size_t i = 0; i < records; ++i) {
    const QuantRecord& q = good.quantRecords[i];
    if (full == records && q.hasAverage() && (q.mask() >> 1)) full = i;
    if (raw == records && q.raw()) raw = i;
    if (i < slots) used += q.bits();
  }
  ASSERT_LT(full, records);
  ASSERT_LT(raw, records) << "the random light has dense bricks: some are raw";
  rejects("reserved width bits", "reserved width bits", [&](ChaarData& d) { d.quantRecords[full].widths |= 1u << 28; });
  rejects("bit offset", "bit offset", [&](ChaarData& d) { d.quantRecords[slots - 1].bitOffset += 1; });
  rejects("wider field", "base B00", [&](ChaarData& d) { d.quantRecords[slots - 1].widths += 1u << 12; });
  rejects("average widths, no average", "average widths without an average",
          [&](ChaarData& d) { d.quantRecords[full].maskLo &= ~1u; });
  rejects("detail widths, no details", "detail widths without details", [&](ChaarData& d) {
    d.quantRecords[full].maskLo &= 1u;
    d.quantRecords[full].maskHi = 0;
  });
  rejects("raw brick with average widths", "average widths without an average",
          [&](ChaarData& d) { d.quantRecords[raw].widths |= 1u; });
  rejects("raw brick, no values", "detail widths without details", [&](ChaarData& d) {
    d.quantRecords[raw].maskLo = 0;
    d.quantRecords[raw].maskHi = 0;
  });
  rejects("Haar brick flagged raw", "base B0", [&](ChaarData& d) { d.quantRecords[full].widths |= kQuantRawBit; });
  // The good file claiming another version (checksums fixed).
  auto rejectsAsVersion = [&](uint16_t major, uint16_t minor, const char* what, const std::string& needle) {
    ChaarData c = good;
    std::vector<uint8_t> bytes = serializeChaar(c);
    std::memcpy(&bytes[8], &major, 2);
    std::memcpy(&bytes[10], &minor, 2);
    fixHeaderCrc(bytes);
    expectRejected(bytes, what, needle);
  };
  rejectsAsVersion(2, 0, "raw in 2.0", "raw brick in a 2.0 file");
  {  // without raw bricks the writer still writes 2.0
    ChaarData c = encodeLights(g, {smoothLight(g, 1)}, 0.05f, -1.0f, Precision::Quant);
    for (const QuantRecord& q : c.quantRecords) ASSERT_FALSE(q.raw());
    const std::vector<uint8_t> bytes = serializeChaar(c);
    EXPECT_EQ(parseChaar(bytes.data(), bytes.size(), "smooth").header.versionMinor, 0);
  }
  ASSERT_NE(used % 64, 0u) << "the tail test needs unused bits in base 0's last word";
  rejects("tail bits", "nonzero bits after its last field",
          [&](ChaarData& d) { d.quantWords[d.bases[0].quantWords - 1] |= uint64_t(1) << 63; });
  rejects("end word", "end word", [&](ChaarData& d) { d.quantWords[d.bases[0].quantWords] = 1; });
  rejects("short stream", "base B00", [&](ChaarData& d) {
    d.bases[0].quantWords -= 1;
  });
  rejects("zero step", "quantisation step", [&](ChaarData& d) { d.bases[1].quantStep = 0; });
  rejects("nan step", "quantisation step", [&](ChaarData& d) { d.bases[1].quantStep = NAN; });
  rejects("huge step", "quantisation step", [&](ChaarData& d) { d.bases[1].quantStep = 1e31f; });
  // Quantised coefficients claiming 1.x, and float files carrying quantisation fields.
  rejectsAsVersion(1, 1, "quant as 1.x", "quantised coefficients in a 1.x file");
  ChaarData f = encodeLights(g, {smoothLight(g, 1)}, 0.01f);
  f.bases[0].quantStep = 0.5f;
  expectRejected(serializeChaar(f), "float with a step", "quantisation fields in a float file");
}

TEST(ChaarFormat, WriterIsDeterministic) {
  using namespace canopy::haar::testing;
  const LatticeGeom g = makeGeom(9, 8, 7);
  ChaarData a = encodeLights(g, {smoothLight(g, 5), smoothLight(g, 6)}, 0.005f);
  ChaarData b = encodeLights(g, {smoothLight(g, 5), smoothLight(g, 6)}, 0.005f);
  EXPECT_EQ(serializeChaar(a), serializeChaar(b));
}
