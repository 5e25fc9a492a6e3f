// chaar.cpp: .chaar reader, writer and CPU decoder (see chaar.h). No OpenVDB: this file is also
// compiled into the sanitized format test and the fuzzer.
#include "formats/chaar.h"

#include <cmath>
#include <cstdio>
#include <cstring>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "canopy/hash.h"

namespace canopy::haar {
namespace {

constexpr uint64_t kAlign = 16;
uint64_t alignUp(uint64_t v) { return (v + kAlign - 1) / kAlign * kAlign; }

const char* kSectionNames[kChaarSectionCount] = {"META", "BASES", "SLOTS", "RECORDS", "COEFS"};

uint32_t headerCrc(const uint8_t* bytes, size_t headerSize) {
  const size_t crcAt = offsetof(ChaarHeader, headerCrc32);
  uint32_t crc = crc32(0, bytes, crcAt);
  const uint32_t zero = 0;
  crc = crc32(crc, &zero, sizeof zero);
  return crc32(crc, bytes + crcAt + 4, headerSize - crcAt - 4);
}

bool isFiniteHalf(uint16_t h) { return (h & 0x7c00u) != 0x7c00u; }

// Each validation failure: "<name>: <problem>".
struct Checker {
  const std::string& name;
  [[noreturn]] void fail(const std::string& what) const { throw invalidInput(name + ": " + what); }
  void require(bool ok, const std::string& what) const {
    if (!ok) fail(what);
  }
};

std::string str(uint64_t v) { return std::to_string(v); }

}  // namespace

std::string baseName(uint32_t base) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "B%02u", base);
  return buf;
}

uint64_t ChaarData::latticeCells() const {
  uint64_t n = 1;
  for (int a = 0; a < 3; ++a) n *= uint64_t(int64_t(header.latticeMax[a]) - header.latticeMin[a] + 1);
  return n;
}

ChaarView ChaarData::view() const {
  ChaarView v;
  for (int a = 0; a < 3; ++a) {
    v.latticeMin[a] = header.latticeMin[a];
    v.latticeMax[a] = header.latticeMax[a];
    v.brickDims[a] = header.brickDims[a];
  }
  v.slotCount = header.slotCount;
  v.baseCount = header.baseCount;
  v.precision = precision();
  v.slots = slots.data();
  v.records = records.data();
  v.quantRecords = quantRecords.data();
  v.coefs = precision() == Precision::Quant  ? static_cast<const void*>(quantWords.data())
            : precision() == Precision::Fp16 ? static_cast<const void*>(coefs16.data())
                                             : static_cast<const void*>(coefs32.data());
  for (uint32_t b = 0; b < header.baseCount && b < uint32_t(kMaxBases); ++b) {
    v.baseCoefOffset[b] = bases[b].coefOffset;
    if (precision() == Precision::Quant) quantSteps(bases[b].quantStep, v.quantStep[b]);
  }
  return v;
}

uint64_t ChaarData::baseBytes(uint32_t base) const {
  if (precision() == Precision::Quant)
    return uint64_t(header.slotCount) * sizeof(QuantRecord) + (uint64_t(bases[base].quantWords) + 1) * 8;
  const uint64_t entryBytes = precision() == Precision::Fp16 ? 6 : 12;
  return uint64_t(header.slotCount) * sizeof(BrickRecord) + bases[base].coefCount * entryBytes;
}

// Validates base b's quantised records against its stream and fills d.records with their masks
// (first = the running entry index), which the shared checks below then verify.
void checkQuantRecords(ChaarData& d, uint32_t b, const Checker& ck) {
  const ChaarHeader& h = d.header;
  const ChaarBaseEntry& e = d.bases[b];
  const std::string bn = "base " + baseName(b);
  uint64_t bit = 0, entries = 0;
  for (uint32_t s = 0; s < h.slotCount; ++s) {
    const QuantRecord& q = d.quantRecords[uint64_t(b) * h.slotCount + s];
    const std::string at = bn + " slot " + str(s);
    const uint64_t m = q.mask();
    ck.require(((q.widths >> 24) & 0x7fu) == 0, at + " has reserved width bits set");
    ck.require(!q.raw() || h.versionMinor >= 1, at + " is a raw brick in a 2.0 file");
    ck.require(q.hasAverage() || q.groupBits(0) == 0, at + " has average widths without an average");
    ck.require((m & ~uint64_t(q.hasAverage())) || q.groupBits(1) == 0, at + " has detail widths without details");
    ck.require(q.bitOffset == bit, at + " bit offset out of order or out of range");
    bit += q.bits();
    ck.require(bit <= 64 * uint64_t(e.quantWords), at + " fields run past the base's stream");
    d.records[uint64_t(b) * h.slotCount + s].set(m, uint32_t(entries), q.raw());
    entries += uint64_t(popcount64(m));
  }
  ck.require((bit + 63) / 64 == e.quantWords, bn + " stream is longer than its records' fields");
  if (bit % 64)
    ck.require((d.quantWords[e.coefOffset + bit / 64] >> (bit % 64)) == 0, bn + " has nonzero bits after its last field");
}

// ---------------------------------------------------------------------------------------------
namespace {

// What parseChaar's stages derive from the header.
struct ChaarParse {
  uint32_t headerSize = 0;
  bool quant = false;                      // Precision::Quant (2.x)
  uint16_t knownMinor = 0;                 // the newest minor of the file's major that this reader knows
  uint64_t brickCount = 0;
};

// The header: magic, version, header size, checksum and file size; returns the header size.
uint32_t readHeader(const uint8_t* data, size_t size, ChaarHeader& h, const Checker& ck) {
  ck.require(size >= sizeof(kChaarMagic) && std::memcmp(data, kChaarMagic, sizeof kChaarMagic) == 0,
             "not a .chaar file (bad magic)");
  ck.require(size >= 16, "truncated (" + str(size) + " bytes, shorter than the header)");
  uint16_t major, minor;
  uint32_t headerSize;
  std::memcpy(&major, data + 8, 2);
  std::memcpy(&minor, data + 10, 2);
  std::memcpy(&headerSize, data + 12, 4);
  ck.require(major <= kChaarVersionMajor,
             ".chaar version " + str(major) + "." + str(minor) + " is newer than this reader (" +
                 str(kChaarVersionMajor) + "." + str(kChaarVersionMinor) + "); update Canopy");
  ck.require(major >= 1, "unsupported .chaar major version " + str(major));
  ck.require(headerSize >= sizeof(ChaarHeader) && headerSize <= 4096 && headerSize % kAlign == 0,
             "bad header size " + str(headerSize));
  ck.require(size >= headerSize,
             "truncated (" + str(size) + " bytes, header needs " + str(headerSize) + ")");
  std::memcpy(&h, data, sizeof h);
  ck.require(headerCrc(data, headerSize) == h.headerCrc32, "header checksum mismatch (corrupted)");
  ck.require(h.fileSize >= headerSize, "bad file size field");
  ck.require(size >= h.fileSize,
             "truncated (" + str(size) + " bytes, header says " + str(h.fileSize) + ")");
  ck.require(size == h.fileSize, str(size - h.fileSize) + " trailing bytes after the end of the file");
  return headerSize;
}

// Header fields: bases, precision and version, lattice and brick grid, transform, thresholds, counts.
void checkHeaderFields(const ChaarData& d, ChaarParse& p, const Checker& ck) {
  const ChaarHeader& h = d.header;
  ck.require(h.baseCount >= 1 && h.baseCount <= uint32_t(kMaxBases), "bad base count " + str(h.baseCount));
  ck.require(h.precision <= 2, "unknown coefficient precision " + str(h.precision));
  p.quant = h.precision == uint32_t(Precision::Quant);
  const bool quant = p.quant;
  ck.require(quant == (h.versionMajor == 2), quant ? "quantised coefficients in a 1.x file"
                                                   : "float coefficients in a 2.x file");
  // The newest minor of the file's major that this reader knows.
  p.knownMinor = h.versionMajor == 1 ? kChaarVersionMinor : kChaarVersion2Minor;
  for (int a = 0; a < 3; ++a) {
    const int64_t dim = int64_t(h.latticeMax[a]) - h.latticeMin[a] + 1;
    ck.require(dim >= 1 && dim <= kMaxLatticeEdge, "bad lattice bounds on axis " + str(a));
    ck.require(std::abs(int64_t(h.latticeMin[a])) < (int64_t(1) << 24) &&
                   std::abs(int64_t(h.latticeMax[a])) < (int64_t(1) << 24),
               "lattice bounds beyond float precision");
    ck.require(h.brickDims[a] == (dim + kBrickCore - 1) / kBrickCore,
               "brick grid does not match the lattice on axis " + str(a));
  }
  for (double m : h.indexToModel) ck.require(std::isfinite(m), "non-finite index-to-model transform");
  ck.require(h.indexToModel[3] == 0 && h.indexToModel[7] == 0 && h.indexToModel[11] == 0 &&
                 h.indexToModel[15] == 1,
             "index-to-model transform is not affine");
  ck.require((std::isfinite(h.threshold) && (h.threshold >= 0 || h.threshold == -1)) &&
                 (std::isfinite(h.maxErrorTarget) && (h.maxErrorTarget >= 0 || h.maxErrorTarget == -1)),
             "bad threshold fields");
  p.brickCount = d.brickCount();
  ck.require(h.slotCount <= p.brickCount, "more stored bricks than the brick grid holds");
  ck.require(h.coefCount <= uint64_t(h.baseCount) * h.slotCount * kBrickValues,
             "coefficient count larger than the bricks can hold");
}

// Section table: in order, aligned, inside the file, not overlapping, checksummed.
void checkSectionTable(const uint8_t* data, const ChaarHeader& h, const ChaarParse& p, const Checker& ck) {
  const bool quant = p.quant;
  const uint64_t entryBytes = h.precision == 1 ? 6 : 12;
  const uint64_t expected[kChaarSectionCount] = {
      0, uint64_t(h.baseCount) * sizeof(ChaarBaseEntry), p.brickCount * 4,
      uint64_t(h.baseCount) * h.slotCount * (quant ? sizeof(QuantRecord) : sizeof(BrickRecord)), 0};
  uint64_t cursor = p.headerSize;
  for (int s = 0; s < kChaarSectionCount; ++s) {
    const ChaarSectionEntry& e = h.sections[s];
    const std::string sec = std::string("section ") + kSectionNames[s];
    ck.require(e.offset % kAlign == 0 && e.offset >= cursor && e.offset <= h.fileSize &&
                   e.size <= h.fileSize - e.offset,
               sec + " lies outside the file or overlaps another");
    if (s == kSecMeta)
      ck.require(e.size <= kMaxMetaBytes, sec + " is too large");
    else if (s == kSecCoefs)
      ck.require(quant ? e.size % 8 == 0 && e.size >= 8 * uint64_t(h.baseCount) : e.size == h.coefCount * entryBytes,
                 sec + " has the wrong size");
    else
      ck.require(e.size == expected[s], sec + " has the wrong size");
    for (uint64_t i = cursor; i < e.offset; ++i)
      ck.require(data[i] == 0, "nonzero padding byte at offset " + str(i) + " (corrupted)");
    ck.require(crc32(0, data + e.offset, e.size) == e.crc32,
               sec + " checksum mismatch (corrupted)");
    cursor = e.offset + e.size;
  }
  // A newer minor version may append sections after COEFS; in ours the file ends there.
  if (h.versionMinor <= p.knownMinor)
    ck.require(cursor == h.fileSize, str(h.fileSize - cursor) + " unaccounted bytes after the last section");
}

// Copy sections into typed arrays (float coefficients must be finite).
void copySections(const uint8_t* data, ChaarData& d, const ChaarParse& p, const Checker& ck) {
  const ChaarHeader& h = d.header;
  auto sectionPtr = [&](int s) { return data + h.sections[s].offset; };
  d.meta.assign(reinterpret_cast<const char*>(sectionPtr(kSecMeta)), h.sections[kSecMeta].size);
  d.bases.resize(h.baseCount);
  std::memcpy(d.bases.data(), sectionPtr(kSecBases), h.sections[kSecBases].size);
  d.slots.resize(p.brickCount);
  std::memcpy(d.slots.data(), sectionPtr(kSecSlots), h.sections[kSecSlots].size);
  d.records.resize(uint64_t(h.baseCount) * h.slotCount);
  if (p.quant) {  // (levels are bounded by their widths; the records are checked below)
    d.quantRecords.resize(d.records.size());
    std::memcpy(static_cast<void*>(d.quantRecords.data()), sectionPtr(kSecRecords), h.sections[kSecRecords].size);
    d.quantWords.resize(h.sections[kSecCoefs].size / 8);
    std::memcpy(d.quantWords.data(), sectionPtr(kSecCoefs), h.sections[kSecCoefs].size);
  } else {
    std::memcpy(static_cast<void*>(d.records.data()), sectionPtr(kSecRecords), h.sections[kSecRecords].size);
    if (h.precision == 1) {
      d.coefs16.resize(3 * h.coefCount);
      std::memcpy(d.coefs16.data(), sectionPtr(kSecCoefs), h.sections[kSecCoefs].size);
      for (uint16_t v : d.coefs16) ck.require(isFiniteHalf(v), "non-finite coefficient");
    } else {
      d.coefs32.resize(3 * h.coefCount);
      std::memcpy(d.coefs32.data(), sectionPtr(kSecCoefs), h.sections[kSecCoefs].size);
      for (float v : d.coefs32) ck.require(std::isfinite(v), "non-finite coefficient");
    }
  }
}

// Bases: streams consecutive and covering COEFS exactly.
void checkBases(const ChaarData& d, const ChaarParse& p, const Checker& ck) {
  const ChaarHeader& h = d.header;
  const bool quant = p.quant;
  uint64_t coefCursor = 0, wordCursor = 0;
  for (uint32_t b = 0; b < h.baseCount; ++b) {
    const ChaarBaseEntry& e = d.bases[b];
    const std::string bn = "base " + baseName(b);
    ck.require(e.coefCount <= h.coefCount - coefCursor, bn + " coefficient count out of range");
    if (quant) {
      ck.require(e.coefOffset == wordCursor && e.quantWords < d.quantWords.size() - wordCursor,
                 bn + " coefficient stream out of range");
      // Steps: finite, positive, and small enough that 2^14 steps of sqrt(2)^3 T stay finite.
      ck.require(std::isfinite(e.quantStep) && e.quantStep > 0 && e.quantStep < 1e30f, bn + " has a bad quantisation step");
      ck.require(d.quantWords[e.coefOffset + e.quantWords] == 0, bn + " stream's end word is not zero (corrupted)");
      wordCursor += uint64_t(e.quantWords) + 1;
    } else {
      ck.require(e.coefOffset == coefCursor, bn + " coefficient stream out of range");
      ck.require(e.quantStep == 0 && e.quantWords == 0, bn + " has quantisation fields in a float file");
    }
    ck.require(e.coefCount <= uint64_t(BrickRecord::kMaxFirst) + 1, bn + " coefficient stream too long");
    for (int a = 0; a < 3; ++a)
      ck.require(e.direction[a] >= -1 && e.direction[a] <= 1, bn + " has a bad direction");
    // Flags: none in 1.0; in 1.1 only kChaarBaseScattered, on a sun base (a newer minor may add more).
    if (h.versionMajor == 1 && h.versionMinor == 0) ck.require(e.flags == 0, bn + " has flags in a 1.0 file");
    if (h.versionMinor <= p.knownMinor)
      ck.require((e.flags & ~uint32_t(kChaarBaseScattered)) == 0, bn + " has unknown flags " + str(e.flags));
    ck.require(!(e.flags & kChaarBaseScattered) || e.direction[0] != 0 || e.direction[1] != 0 || e.direction[2] != 0,
               bn + " is the ambient base but flagged scattered-only");
    ck.require(std::isfinite(e.threshold) && std::isfinite(e.maxError) && std::isfinite(e.rmsError) &&
                   std::isfinite(e.valueMax),
               bn + " has non-finite statistics");
    coefCursor += e.coefCount;
  }
  ck.require(coefCursor == h.coefCount, "base streams do not cover the coefficient section");
  ck.require(!quant || wordCursor == d.quantWords.size(), "base streams do not cover the coefficient section");
}

// Slots: a bijection between stored bricks and slots.
void checkSlots(const ChaarData& d, const ChaarParse& p, const Checker& ck) {
  const ChaarHeader& h = d.header;
  std::vector<uint8_t> seen(h.slotCount, 0);
  for (uint64_t i = 0; i < p.brickCount; ++i) {
    const uint32_t s = d.slots[i];
    if (s == kEmptySlot) continue;
    ck.require(s < h.slotCount, "brick " + str(i) + " has slot " + str(s) + " out of range");
    ck.require(!seen[s], "slot " + str(s) + " used by two bricks");
    seen[s] = 1;
  }
  for (uint32_t s = 0; s < h.slotCount; ++s)
    ck.require(seen[s], "slot " + str(s) + " belongs to no brick");
}

// Records: compact, in order, within the base's stream; raw only where there is light.
void checkRecords(ChaarData& d, const ChaarParse& p, const Checker& ck) {
  const ChaarHeader& h = d.header;
  for (uint32_t b = 0; b < h.baseCount; ++b) {
    uint64_t next = 0;
    uint32_t nonEmpty = 0, raw = 0;
    if (p.quant) checkQuantRecords(d, b, ck);
    for (uint32_t s = 0; s < h.slotCount; ++s) {
      const BrickRecord& r = d.records[uint64_t(b) * h.slotCount + s];
      ck.require(!r.raw() || r.mask() != 0,
                 "base " + baseName(b) + " slot " + str(s) + " is an empty brick flagged raw");
      ck.require(r.first() == next, "base " + baseName(b) + " slot " + str(s) +
                                      " coefficient index out of order or out of range");
      next += uint64_t(popcount64(r.mask()));
      nonEmpty += r.mask() != 0;
      raw += r.raw();
    }
    ck.require(next == d.bases[b].coefCount,
               "base " + baseName(b) + " records do not match its coefficient count");
    ck.require(nonEmpty == d.bases[b].brickCount && raw == d.bases[b].rawBrickCount,
               "base " + baseName(b) + " brick counts do not match its records");
  }
}

// Every stored slot has light in at least one base.
void checkStoredSlots(const ChaarData& d, const Checker& ck) {
  const ChaarHeader& h = d.header;
  for (uint32_t s = 0; s < h.slotCount; ++s) {
    bool any = false;
    for (uint32_t b = 0; b < h.baseCount && !any; ++b)
      any = d.records[uint64_t(b) * h.slotCount + s].mask() != 0;
    ck.require(any, "slot " + str(s) + " is stored but empty in every base");
  }
}

}  // namespace

// Parses in stages (above, in this order: each may rely on what the earlier ones checked).
ChaarData parseChaar(const uint8_t* data, size_t size, const std::string& name) {
  const Checker ck{name};
  ChaarData d;
  ChaarParse p;
  p.headerSize = readHeader(data, size, d.header, ck);
  checkHeaderFields(d, p, ck);
  checkSectionTable(data, d.header, p, ck);
  copySections(data, d, p, ck);
  checkBases(d, p, ck);
  checkSlots(d, p, ck);
  checkRecords(d, p, ck);
  checkStoredSlots(d, ck);
  return d;
}

ChaarData readChaar(const std::string& path) {
  const std::vector<unsigned char> bytes = readFile(path);
  return parseChaar(bytes.data(), bytes.size(), path);
}

// ---------------------------------------------------------------------------------------------
std::vector<uint8_t> serializeChaar(ChaarData& d) {
  ChaarHeader& h = d.header;
  std::memcpy(h.magic, kChaarMagic, sizeof kChaarMagic);
  const bool quant = h.precision == uint32_t(Precision::Quant);
  // 2.0 only for quantised coefficients; 1.1 only where a 1.1 field is used: files without base
  // flags stay 1.0, byte for byte.
  bool flagged = false;
  for (const ChaarBaseEntry& e : d.bases) flagged = flagged || e.flags != 0;
  bool rawQuant = false;  // 2.1 only where a brick is raw: other quantised files stay 2.0, byte for byte
  for (const QuantRecord& q : d.quantRecords) rawQuant = rawQuant || q.raw();
  h.versionMajor = quant ? 2 : 1;
  h.versionMinor = quant ? (rawQuant ? kChaarVersion2Minor : 0) : (flagged ? kChaarVersionMinor : 0);
  h.headerSize = sizeof(ChaarHeader);
  h.baseCount = uint32_t(d.bases.size());
  const bool fp16 = h.precision == uint32_t(Precision::Fp16);
  uint64_t coefEntries = fp16 ? d.coefs16.size() / 3 : d.coefs32.size() / 3;
  if (quant) {
    coefEntries = 0;
    for (const ChaarBaseEntry& e : d.bases) coefEntries += e.coefCount;
  }
  h.coefCount = coefEntries;
  if (d.slots.size() != d.brickCount() || d.records.size() != uint64_t(h.baseCount) * h.slotCount ||
      (quant && d.quantRecords.size() != d.records.size()))
    throw runtimeError("serializeChaar: inconsistent brick tables");
  std::memset(h.reserved, 0, sizeof h.reserved);

  const void* src[kChaarSectionCount] = {d.meta.data(), d.bases.data(), d.slots.data(),
                                         quant ? static_cast<const void*>(d.quantRecords.data())
                                               : static_cast<const void*>(d.records.data()),
                                         quant  ? static_cast<const void*>(d.quantWords.data())
                                         : fp16 ? static_cast<const void*>(d.coefs16.data())
                                                : static_cast<const void*>(d.coefs32.data())};
  const uint64_t sizes[kChaarSectionCount] = {
      d.meta.size(), d.bases.size() * sizeof(ChaarBaseEntry), d.slots.size() * 4,
      quant ? d.quantRecords.size() * sizeof(QuantRecord) : d.records.size() * sizeof(BrickRecord),
      quant ? d.quantWords.size() * 8 : coefEntries * (fp16 ? 6 : 12)};
  uint64_t cursor = sizeof(ChaarHeader);
  for (int s = 0; s < kChaarSectionCount; ++s) {
    cursor = alignUp(cursor);
    h.sections[s].offset = cursor;
    h.sections[s].size = sizes[s];
    h.sections[s].crc32 = crc32(0, src[s], sizes[s]);
    h.sections[s].reserved = 0;
    cursor += sizes[s];
  }
  h.fileSize = cursor;
  std::vector<uint8_t> out(cursor, 0);
  h.headerCrc32 = 0;
  std::memcpy(out.data(), &h, sizeof h);
  for (int s = 0; s < kChaarSectionCount; ++s)
    if (sizes[s]) std::memcpy(out.data() + h.sections[s].offset, src[s], sizes[s]);
  h.headerCrc32 = headerCrc(out.data(), sizeof h);
  std::memcpy(out.data() + offsetof(ChaarHeader, headerCrc32), &h.headerCrc32, 4);
  return out;
}

void writeChaar(const std::string& path, ChaarData& d) {
  const std::vector<uint8_t> bytes = serializeChaar(d);
  writeFileAtomic(path, bytes.data(), bytes.size());
}

// ---------------------------------------------------------------------------------------------
void decodeBaseDense(const ChaarData& d, uint32_t base, std::vector<float>& out) {
  const ChaarHeader& h = d.header;
  int64_t dim[3];
  for (int a = 0; a < 3; ++a) dim[a] = int64_t(h.latticeMax[a]) - h.latticeMin[a] + 1;
  out.assign(size_t(3 * dim[0] * dim[1] * dim[2]), 0.0f);
  const ChaarView v = d.view();
  float vals[3][kBrickValues];
  for (int64_t bz = 0; bz < h.brickDims[2]; ++bz)
    for (int64_t by = 0; by < h.brickDims[1]; ++by)
      for (int64_t bx = 0; bx < h.brickDims[0]; ++bx) {
        const uint32_t slot = d.slots[size_t((bz * h.brickDims[1] + by) * h.brickDims[0] + bx)];
        if (slot == kEmptySlot || !decodeSlot(v, int(base), slot, vals)) continue;
        // The brick owns its 3^3 core; the border belongs to the next brick.
        for (int z = 0; z < kBrickCore; ++z)
          for (int y = 0; y < kBrickCore; ++y)
            for (int x = 0; x < kBrickCore; ++x) {
              const int64_t gx = bx * kBrickCore + x, gy = by * kBrickCore + y, gz = bz * kBrickCore + z;
              if (gx >= dim[0] || gy >= dim[1] || gz >= dim[2]) continue;
              const size_t o = size_t(3 * ((gz * dim[1] + gy) * dim[0] + gx));
              const int c = brickIndex(x, y, z);
              out[o] = vals[0][c];
              out[o + 1] = vals[1][c];
              out[o + 2] = vals[2][c];
            }
      }
}

}  // namespace canopy::haar
