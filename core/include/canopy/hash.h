// hash.h: content hashes and checksums.
//   hash64 / Hasher: a fast 64-bit non-cryptographic hash (XXH64's algorithm) for content hashes
//   (canopy_source, deterministic file UUIDs);
//   crc32: the checksums inside Canopy's own formats (zlib's polynomial).
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>

namespace canopy {

// Streaming XXH64 (seed 0 by default).
class Hasher {
 public:
  explicit Hasher(uint64_t seed = 0);
  void update(const void* data, size_t size);
  uint64_t digest() const;

 private:
  uint64_t v_[4];
  uint64_t total_ = 0;
  unsigned char buf_[32];
  size_t bufLen_ = 0;
  uint64_t seed_;
};

uint64_t hash64(const void* data, size_t size, uint64_t seed = 0);
// Hash of a whole file's bytes; throws canopy::Error(Io) if it cannot be read.
uint64_t hashFile(const std::string& path);
// 16 lowercase hex digits.
std::string hex64(uint64_t v);
// "<file name> xxh64:<hash of the file's bytes>", how outputs record an input. The name without
// its folder: the same input gives the same output bytes wherever it lies (a cluster node may
// mount the library elsewhere).
std::string describeSource(const std::string& path);

// CRC-32 (the zlib/PNG polynomial), chainable: crc32(crc32(0, a), b) == crc32(0, a+b).
uint32_t crc32(uint32_t crc, const void* data, size_t size);

}  // namespace canopy
