// chaar.h: the .chaar file, Canopy's Haar-compressed light (19 LB base solutions of one plant).
//
// Written by canopy-haar, read by canopy-octreepack and canopy-play. Little-endian, every section
// 16-byte aligned, every multi-byte field naturally aligned. Version 1.0 layout:
//
//   offset 0    ChaarHeader (384 bytes, below): magic "CNPYHAAR", version, sizes, lattice,
//               index->model transform, threshold, precision, section table with CRC-32s,
//               header CRC-32 (over the header with its crc field zeroed)
//   sections, in this order, each starting at a multiple of 16, zero padding between them:
//   META     UTF-8 JSON object (tool version, source file and hash, options); informative only
//   BASES    ChaarBaseEntry[baseCount] (64 bytes each): direction, stream offset/count, stats
//   SLOTS    uint32[brickDims.x*y*z] (x fastest): slot of each brick, 0xffffffff = no light in
//            any base (brick not stored); every slot 0..slotCount-1 appears exactly once
//   RECORDS  BrickRecord[baseCount * slotCount] (12 bytes: u32 mask lo, u32 mask hi, u32 first
//            coefficient index in bits 0..30 and the raw flag in bit 31), base-major; within a
//            base, records in slot order and `first` = running sum of the popcounts (the
//            coefficient stream is compact, no gaps, no overlaps)
//   COEFS    the compacted coefficient streams of all bases, base after base: per entry three
//            channels (R,G,B) as float32 (12 bytes) or binary16 (6 bytes)
//   end of file = fileSize; nothing may follow.
// Version 1.1 adds one thing: ChaarBaseEntry::flags bit 0 (kChaarBaseScattered), set for a sun base
// that canopy-lbsolve stored without its direct beam (lbsolve's default since 2026-12; grid
// metadata canopy_direct_beam = false). A writer writes 1.0 when no base has a flag, so files
// without it are 1.0 byte for byte. A 1.0 reader reads 1.1 files (it ignores the flags).
//
// Version 2.0 is Precision::Quant (quantised integer coefficients, formats/haar_brick.h): the same
// header, META, BASES (quantStep, quantWords filled) and SLOTS; RECORDS holds QuantRecord[baseCount
// * slotCount] (16 bytes: u32 mask lo, u32 mask hi, u32 bit offset, u32 widths), base-major, each
// base's bit offsets the running sum of its records' bits in slot order; COEFS holds each base's
// stream (quantWords little-endian u64, bits past the last field zero) followed by one zero word,
// base after base (coefOffset = the base's first word); header coefCount = kept coefficients. A
// writer writes 2.x only for Quant, so fp32/fp16 files stay 1.x byte for byte; 1.x readers
// reject 2.x files (a newer major), a 2.x reader reads every 1.x file.
//
// Version 2.1 adds raw quantised bricks (bit 31 of QuantRecord::widths: the brick's values, not
// its coefficients, with the details' widths and no average; haar_brick.h kQuantRawBit), each
// base's `rawBricks` counting them. The writer writes 2.1 only where a brick is raw, so other
// quantised files stay 2.0 byte for byte; a raw flag in a 2.0 file is rejected.
//
// A reader (parseChaar) trusts nothing: it rejects bad magic, a newer major version, truncation,
// trailing bytes, checksum mismatch, sections out of range or overlapping, inconsistent counts,
// out-of-range slots/indices and non-finite values, each with canopy::Error(InvalidInput) naming
// the file. Minor versions may append header fields (headerSize grows) and sections after COEFS;
// a v1.x reader reads v1.y files. A major version change means a layout change.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "canopy/errors.h"
#include "formats/haar_view.h"

namespace canopy::haar {

constexpr char kChaarMagic[8] = {'C', 'N', 'P', 'Y', 'H', 'A', 'A', 'R'};
constexpr uint16_t kChaarVersionMajor = 2;  // the newest major this reader reads (2: Quant)
constexpr uint16_t kChaarVersionMinor = 1;   // the newest 1.x minor
constexpr uint16_t kChaarVersion2Minor = 1;  // the newest 2.x minor (2.1: raw quantised bricks)
constexpr int kChaarSectionCount = 5;
enum ChaarSection : int { kSecMeta = 0, kSecBases = 1, kSecSlots = 2, kSecRecords = 3, kSecCoefs = 4 };
constexpr int kMaxLatticeEdge = 1 << 15;  // per axis; a light lattice is 64..512 in practice
constexpr size_t kMaxMetaBytes = 1 << 16;

struct ChaarSectionEntry {  // 24 bytes
  uint64_t offset;          //  0 from the start of the file, multiple of 16
  uint64_t size;            //  8 bytes
  uint32_t crc32;           // 16 CRC-32 (zlib polynomial) of the section's bytes
  uint32_t reserved;        // 20 zero
};
static_assert(sizeof(ChaarSectionEntry) == 24, "section entry layout");

struct ChaarHeader {                  // offset
  char magic[8];                      //   0 "CNPYHAAR"
  uint16_t versionMajor;              //   8
  uint16_t versionMinor;              //  10
  uint32_t headerSize;                //  12 sizeof(ChaarHeader) for v1.0
  uint64_t fileSize;                  //  16 total bytes
  uint32_t baseCount;                 //  24 1..32 (19 for lbsolve output)
  uint32_t precision;                 //  28 Precision: 0 fp32, 1 fp16
  int32_t latticeMin[3];              //  32 inclusive lattice bounds (index space)
  int32_t latticeMax[3];              //  44
  int32_t brickDims[3];               //  56 ceil((max-min+1)/3)
  uint32_t slotCount;                 //  68 stored bricks (light in at least one base)
  double indexToModel[16];            //  72 OpenVDB Mat4d, row-vector convention:
                                      //     model = [i j k 1] * M, translation in [12..14]
  float threshold;                    // 200 --threshold given (or -1 under --max-error)
  float maxErrorTarget;               // 204 --max-error given (or -1)
  uint64_t coefCount;                 // 208 entries in COEFS (all bases)
  ChaarSectionEntry sections[kChaarSectionCount];  // 216 .. 336
  uint8_t reserved[44];               // 336 zero
  uint32_t headerCrc32;               // 380 CRC-32 of bytes [0, headerSize) with this field = 0
};
static_assert(sizeof(ChaarHeader) == 384, "ChaarHeader is 384 bytes");
static_assert(offsetof(ChaarHeader, indexToModel) == 72, "header layout");
static_assert(offsetof(ChaarHeader, sections) == 216, "header layout");
static_assert(offsetof(ChaarHeader, headerCrc32) == 380, "header layout");

struct ChaarBaseEntry {    // 64 bytes
  int32_t direction[3];    //  0 lattice direction c_j of base B_j ((0,0,0) for B00)
  uint32_t flags;          // 12 ChaarBaseFlags (1.1; zero in 1.0)
  uint64_t coefOffset;     // 16 first entry of this base in COEFS
  uint64_t coefCount;      // 24 entries of this base
  float threshold;         // 32 threshold this base was encoded with
  float maxError;          // 36 encoder-measured max |decoded - input| over all stored texels
  float rmsError;          // 40 encoder-measured RMS error over the lattice volume
  float valueMax;          // 44 largest input value (any channel): the PSNR peak
  uint32_t brickCount;     // 48 bricks with light in this base (mask != 0)
  uint32_t rawBrickCount;  // 52 of those, stored raw (no transform)
  float quantStep;         // 56 (2.x, Quant) the base's step T (haar_brick.h quantSteps); zero otherwise
  uint32_t quantWords;     // 60 (2.x, Quant) 64-bit words of the base's stream, without its zero end word
};
static_assert(sizeof(ChaarBaseEntry) == 64, "ChaarBaseEntry is 64 bytes");

enum ChaarBaseFlags : uint32_t {
  // The base holds only light scattered at least once: canopy-lbsolve removed the sun base's
  // unscattered beam (tools/lbsolve/beam.h), which the player adds as its shadowed direct sun.
  kChaarBaseScattered = 1u,
};

// A .chaar in memory, typed and validated. view() gives the CPU sampler's POD view of it.
struct ChaarData {
  ChaarHeader header{};                 // as read or as to be written (offsets/CRCs filled on write)
  std::string meta;                     // META section (JSON text)
  std::vector<ChaarBaseEntry> bases;
  std::vector<uint32_t> slots;
  std::vector<BrickRecord> records;
  std::vector<float> coefs32;           // 3 * coefCount floats when precision == fp32
  std::vector<uint16_t> coefs16;        // 3 * coefCount halves when precision == fp16
  // Quant (2.x): the on-disk records and the bit streams (each base's words, then one zero word).
  // `records` then holds their masks, raw flags and `first` = the running entry index, so code
  // that only counts coefficients or looks at masks serves every precision.
  std::vector<QuantRecord> quantRecords;
  std::vector<uint64_t> quantWords;

  Precision precision() const { return Precision(header.precision); }
  uint32_t baseCount() const { return header.baseCount; }
  uint64_t brickCount() const {
    return uint64_t(header.brickDims[0]) * header.brickDims[1] * header.brickDims[2];
  }
  uint64_t latticeCells() const;
  ChaarView view() const;  // host pointers into this object (valid while it lives, unmodified)
  // Bytes of this base's share of the file: its records (12 per stored brick) and coefficients.
  uint64_t baseBytes(uint32_t base) const;
};

// Parses and validates a .chaar image. `name` (usually the path) prefixes every error message.
ChaarData parseChaar(const uint8_t* data, size_t size, const std::string& name);
// Reads and parses a file (Io errors for missing/unreadable files).
ChaarData readChaar(const std::string& path);

// Fills the header's sizes, offsets and checksums and returns the file image (deterministic).
// Throws runtimeError if the data is inconsistent (a programming error in the caller).
std::vector<uint8_t> serializeChaar(ChaarData& data);
// serializeChaar + atomic write.
void writeChaar(const std::string& path, ChaarData& data);

// Rebuilds the two decoded views used by tools and tests: every lattice cell's value as decoded
// from the brick that owns it. out: 3 floats per cell, x fastest over the lattice box.
void decodeBaseDense(const ChaarData& data, uint32_t base, std::vector<float>& out);

// Bytes of one brick record of a base.
inline uint64_t recordBytes(Precision p) { return p == Precision::Quant ? sizeof(QuantRecord) : sizeof(BrickRecord); }

// "B07" for base 7.
std::string baseName(uint32_t base);

}  // namespace canopy::haar
