// hash.cpp: XXH64 (public-domain algorithm by Yann Collet, reimplemented) and CRC-32 via zlib.
#include "canopy/hash.h"

#include <zlib.h>

#include <cstdio>
#include <cstring>
#include <fstream>

#include "canopy/errors.h"

namespace canopy {
namespace {
constexpr uint64_t P1 = 11400714785074694791ULL, P2 = 14029467366897019727ULL,
                   P3 = 1609587929392839161ULL, P4 = 9650029242287828579ULL,
                   P5 = 2870177450012600261ULL;
inline uint64_t rotl(uint64_t x, int r) { return (x << r) | (x >> (64 - r)); }
inline uint64_t read64(const unsigned char* p) { uint64_t v; std::memcpy(&v, p, 8); return v; }
inline uint32_t read32(const unsigned char* p) { uint32_t v; std::memcpy(&v, p, 4); return v; }
inline uint64_t round1(uint64_t acc, uint64_t in) { acc += in * P2; acc = rotl(acc, 31); return acc * P1; }
inline uint64_t merge(uint64_t acc, uint64_t v) { acc ^= round1(0, v); return acc * P1 + P4; }
}  // namespace

Hasher::Hasher(uint64_t seed) : seed_(seed) {
  v_[0] = seed + P1 + P2;
  v_[1] = seed + P2;
  v_[2] = seed;
  v_[3] = seed - P1;
}

void Hasher::update(const void* data, size_t size) {
  const unsigned char* p = static_cast<const unsigned char*>(data);
  total_ += size;
  if (bufLen_ + size < 32) {
    if (size) std::memcpy(buf_ + bufLen_, p, size);
    bufLen_ += size;
    return;
  }
  if (bufLen_) {
    size_t fill = 32 - bufLen_;
    std::memcpy(buf_ + bufLen_, p, fill);
    for (int i = 0; i < 4; ++i) v_[i] = round1(v_[i], read64(buf_ + 8 * i));
    p += fill;
    size -= fill;
    bufLen_ = 0;
  }
  while (size >= 32) {
    for (int i = 0; i < 4; ++i) v_[i] = round1(v_[i], read64(p + 8 * i));
    p += 32;
    size -= 32;
  }
  if (size) std::memcpy(buf_, p, size);
  bufLen_ = size;
}

uint64_t Hasher::digest() const {
  uint64_t h;
  if (total_ >= 32) {
    h = rotl(v_[0], 1) + rotl(v_[1], 7) + rotl(v_[2], 12) + rotl(v_[3], 18);
    for (int i = 0; i < 4; ++i) h = merge(h, v_[i]);
  } else {
    h = seed_ + P5;
  }
  h += total_;
  const unsigned char* p = buf_;
  size_t n = bufLen_;
  while (n >= 8) { h ^= round1(0, read64(p)); h = rotl(h, 27) * P1 + P4; p += 8; n -= 8; }
  if (n >= 4) { h ^= uint64_t(read32(p)) * P1; h = rotl(h, 23) * P2 + P3; p += 4; n -= 4; }
  while (n) { h ^= (*p) * P5; h = rotl(h, 11) * P1; ++p; --n; }
  h ^= h >> 33; h *= P2; h ^= h >> 29; h *= P3; h ^= h >> 32;
  return h;
}

uint64_t hash64(const void* data, size_t size, uint64_t seed) {
  Hasher h(seed);
  h.update(data, size);
  return h.digest();
}

uint64_t hashFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw ioError(path + ": cannot open for hashing");
  Hasher h;
  char buf[1 << 16];
  while (f) {
    f.read(buf, sizeof buf);
    h.update(buf, size_t(f.gcount()));
  }
  return h.digest();
}

std::string hex64(uint64_t v) {
  char s[17];
  std::snprintf(s, sizeof s, "%016llx", static_cast<unsigned long long>(v));
  return s;
}

std::string describeSource(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return (slash == std::string::npos ? path : path.substr(slash + 1)) + " xxh64:" + hex64(hashFile(path));
}

uint32_t crc32(uint32_t crc, const void* data, size_t size) {
  const Bytef* p = static_cast<const Bytef*>(data);
  uLong c = crc;
  while (size > 0) {
    uInt chunk = size > 0x40000000u ? 0x40000000u : uInt(size);
    c = ::crc32(c, p, chunk);
    p += chunk;
    size -= chunk;
  }
  return uint32_t(c);
}

}  // namespace canopy
