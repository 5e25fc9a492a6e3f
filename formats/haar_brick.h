// haar_brick.h: the per-brick math of Canopy's Haar light compression, written once for CPU and CUDA.
//
// A brick covers 3^3 lattice cells plus a forward border of one: it stores the 4^3 values at
// lattice nodes origin + (0..3)^3, so the 2^3 texels of any trilinear sample whose lower corner lies
// in the brick's 3^3 core are all in that one brick (dissertation §4.5). Value and coefficient
// index inside a brick: c = x + 4*y + 16*z (x fastest), bit c of the brick's 64-bit mask.
//
// Transform (dissertation §2.3, eq. 2.20-2.21): along one axis the 4 values v0..v3 become
//   [ s, D, d0, d1 ] with a_i = (v_2i + v_2i+1)/2, d_i = (v_2i - v_2i+1)/2, s = (a0+a1)/2, D = (a0-a1)/2,
// applied along z, then y, then x (the lift, done in double by the encoder). The inverse (unlift,
// float, x then y then z) computes every output as ((s +- D) +- d_{i/2}) in exactly that order.
// The point sampler below reconstructs only the 2^3 texels it needs but with the same float
// operations in the same order, so a sample equals trilinear interpolation of the fully decoded
// brick bit for bit, and the CPU and CUDA decoders agree bit for bit (products use explicitly
// rounded multiplies/adds on the device so nvcc cannot contract them into FMAs).
//
// A brick record (12 bytes, the dissertation's layout) stores the 64-bit mask of kept coefficients
// and the index of its first one in the base's compacted coefficient stream (coefficient j of the
// brick, counting set bits in order, is entry first + j); the index's top bit is the raw flag, so a
// base holds at most 2^31 coefficients. A raw brick is stored without transform (mask = its
// nonzero values):
// the encoder uses it where it is no larger and no less exact than the Haar brick, and at threshold
// 0, where a float Haar round trip is not always exact.
#pragma once
#include <cstdint>

#include "canopy/half.h"
#include "canopy/hd.h"

namespace canopy::haar {

constexpr int kBrickCore = 3;     // cells per brick edge that the brick owns
constexpr int kBrickEdge = 4;     // stored values per edge (core + forward border)
constexpr int kBrickValues = 64;  // 4^3
constexpr uint32_t kEmptySlot = 0xffffffffu;  // slot table entry of a brick with no light
constexpr int kMaxBases = 32;

enum class Precision : uint32_t { Fp32 = 0, Fp16 = 1 };

struct Rgb {
  float r = 0, g = 0, b = 0;
};

// One brick of one base: 12 bytes on disk and in memory.
struct BrickRecord {
  uint32_t maskLo = 0;         // bits 0..31 of the coefficient mask
  uint32_t maskHi = 0;         // bits 32..63
  uint32_t firstAndRaw = 0;    // bits 0..30: index of the first coefficient; bit 31: raw brick
  static constexpr uint32_t kRawBit = 0x80000000u;
  static constexpr uint32_t kMaxFirst = 0x7fffffffu;
  CANOPY_HD uint64_t mask() const { return uint64_t(maskLo) | (uint64_t(maskHi) << 32); }
  CANOPY_HD uint32_t first() const { return firstAndRaw & kMaxFirst; }
  CANOPY_HD bool raw() const { return (firstAndRaw & kRawBit) != 0; }
  CANOPY_HD void set(uint64_t mask, uint32_t first, bool raw) {
    maskLo = uint32_t(mask);
    maskHi = uint32_t(mask >> 32);
    firstAndRaw = (first & kMaxFirst) | (raw ? kRawBit : 0u);
  }
};
static_assert(sizeof(BrickRecord) == 12, "BrickRecord is 12 bytes on disk and on the device");

CANOPY_HD CANOPY_FORCEINLINE constexpr int brickIndex(int x, int y, int z) { return x + 4 * y + 16 * z; }

CANOPY_HD CANOPY_FORCEINLINE int popcount64(uint64_t v) {
#if defined(__CUDA_ARCH__)
  return __popcll(v);
#else
  return __builtin_popcountll(v);
#endif
}

// CANOPY_UNROLL (canopy/hd.h) unrolls fixed-size loops on the device.

// Rounded float arithmetic that a compiler may not fuse (device: __fmul_rn never becomes an FMA).
CANOPY_HD CANOPY_FORCEINLINE float mulRn(float a, float b) {
#if defined(__CUDA_ARCH__)
  return __fmul_rn(a, b);
#else
  return a * b;
#endif
}
CANOPY_HD CANOPY_FORCEINLINE float addRn(float a, float b) {
#if defined(__CUDA_ARCH__)
  return __fadd_rn(a, b);
#else
  return a + b;
#endif
}
CANOPY_HD CANOPY_FORCEINLINE float subRn(float a, float b) {
#if defined(__CUDA_ARCH__)
  return __fsub_rn(a, b);
#else
  return a - b;
#endif
}

// ---- lift / unlift of a whole brick (one channel, 64 values, in place) -------------------------

template <class T>
CANOPY_HD inline void lift4(T* v, int s) {
  const T half = T(0.5);
  const T a0 = (v[0] + v[s]) * half, d0 = (v[0] - v[s]) * half;
  const T a1 = (v[2 * s] + v[3 * s]) * half, d1 = (v[2 * s] - v[3 * s]) * half;
  v[0] = (a0 + a1) * half;
  v[s] = (a0 - a1) * half;
  v[2 * s] = d0;
  v[3 * s] = d1;
}

// Inverse of lift4 in float: output i = ((s +- D) +- d_{i/2}).
CANOPY_HD inline void unlift4(float* v, int s) {
  const float a0 = addRn(v[0], v[s]), a1 = subRn(v[0], v[s]);
  const float d0 = v[2 * s], d1 = v[3 * s];
  v[0] = addRn(a0, d0);
  v[s] = subRn(a0, d0);
  v[2 * s] = addRn(a1, d1);
  v[3 * s] = subRn(a1, d1);
}

// Forward 3D Haar: along z (stride 16), then y (stride 4), then x (stride 1).
template <class T>
CANOPY_HD inline void liftBrick(T* v) {
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) lift4(v + brickIndex(x, y, 0), 16);
  for (int z = 0; z < 4; ++z)
    for (int x = 0; x < 4; ++x) lift4(v + brickIndex(x, 0, z), 4);
  for (int z = 0; z < 4; ++z)
    for (int y = 0; y < 4; ++y) lift4(v + brickIndex(0, y, z), 1);
}

// Inverse 3D Haar: along x, then y, then z.
CANOPY_HD inline void unliftBrick(float* v) {
  for (int z = 0; z < 4; ++z)
    for (int y = 0; y < 4; ++y) unlift4(v + brickIndex(0, y, z), 1);
  for (int z = 0; z < 4; ++z)
    for (int x = 0; x < 4; ++x) unlift4(v + brickIndex(x, 0, z), 4);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) unlift4(v + brickIndex(x, y, 0), 16);
}

// ---- coefficient streams -------------------------------------------------------------------

// Reads entry i (three channels) of a coefficient stream.
struct CoefReader32 {
  const float* p;
  CANOPY_HD CANOPY_FORCEINLINE Rgb operator()(uint64_t i) const {
    return Rgb{p[3 * i], p[3 * i + 1], p[3 * i + 2]};
  }
};
struct CoefReader16 {
  const uint16_t* p;
  CANOPY_HD CANOPY_FORCEINLINE Rgb operator()(uint64_t i) const {
    return Rgb{halfToFloat(p[3 * i]), halfToFloat(p[3 * i + 1]), halfToFloat(p[3 * i + 2])};
  }
};

// Expands a brick's kept coefficients into 64 values per channel and unlifts them (raw bricks are
// copied). out[ch][c]. This is the reference decoder of one brick.
template <class Reader>
CANOPY_HD inline void decodeBrick(const BrickRecord& rec, const Reader& read, float out[3][kBrickValues]) {
  const uint64_t mask = rec.mask();
  uint64_t k = rec.first();
  for (int c = 0; c < kBrickValues; ++c) {
    Rgb v{};
    if ((mask >> c) & 1u) v = read(k++);
    out[0][c] = v.r;
    out[1][c] = v.g;
    out[2][c] = v.b;
  }
  if (rec.raw()) return;
  for (int ch = 0; ch < 3; ++ch) unliftBrick(out[ch]);
}

// ---- trilinear sampling inside one brick ----------------------------------------------------

CANOPY_HD CANOPY_FORCEINLINE float lerpRn(float a, float b, float t) { return addRn(a, mulRn(t, subRn(b, a))); }

// Trilinear interpolation of 2^3 texels v[z][y][x] (one channel): along x, then y, then z.
CANOPY_HD CANOPY_FORCEINLINE float trilinear(const float v[2][2][2], float fx, float fy, float fz) {
  const float c00 = lerpRn(v[0][0][0], v[0][0][1], fx), c10 = lerpRn(v[0][1][0], v[0][1][1], fx);
  const float c01 = lerpRn(v[1][0][0], v[1][0][1], fx), c11 = lerpRn(v[1][1][0], v[1][1][1], fx);
  return lerpRn(lerpRn(c00, c10, fy), lerpRn(c01, c11, fy), fz);
}

// Reconstruction of position pos (0..3) along one axis from that axis's coefficients [s, D, d0, d1]
// is ((s +- D) +- d_{pos/2}) (unlift4). axisSign(k, pos) is the sign with which coefficient k
// enters it: +1, -1, or 0 where it does not enter, as a 2-bit code (0 none, 1 plus, 3 minus) of
// one packed constant: k = 0: + + + +; k = 1: + + - -; k = 2: + - 0 0; k = 3: 0 0 + -.
constexpr uint32_t kAxisSignTable = (1u << 0) | (1u << 2) | (1u << 4) | (1u << 6) |     // k = 0
                                    (1u << 8) | (1u << 10) | (3u << 12) | (3u << 14) |  // k = 1
                                    (1u << 16) | (3u << 18) |                           // k = 2
                                    (1u << 28) | (3u << 30);                            // k = 3
CANOPY_HD CANOPY_FORCEINLINE uint32_t axisSign(int k, int pos) { return (kAxisSignTable >> (2 * (4 * k + pos))) & 3u; }

// acc +- c by sign code s (0: acc unchanged). Adding what the reference decoder adds, minus its
// additions of exact zeros (x + 0 == x), so the result equals the reference's value.
CANOPY_HD CANOPY_FORCEINLINE float foldSigned(float acc, float c, uint32_t s) {
  const float t = (s & 2u) ? subRn(acc, c) : addRn(acc, c);
  return s ? t : acc;
}
CANOPY_HD CANOPY_FORCEINLINE void foldSigned(Rgb& acc, const Rgb& c, uint32_t s) {
  acc.r = foldSigned(acc.r, c.r, s);
  acc.g = foldSigned(acc.g, c.g, s);
  acc.b = foldSigned(acc.b, c.b, s);
}

// The axis coefficients that positions l and l+1 (l in 0..2) depend on, as a 4-bit set: s and D
// always, d0 for l <= 1, d1 for l >= 1.
CANOPY_HD CANOPY_FORCEINLINE uint32_t axisNeedBits(int l) { return l == 0 ? 0x7u : (l == 1 ? 0xfu : 0xbu); }
// The 64-bit set of brick coefficients (c = x + 4y + 16z) that a footprint at (lx, ly, lz) depends
// on: the product of the three axis sets.
CANOPY_HD CANOPY_FORCEINLINE uint64_t footprintNeedMask(int lx, int ly, int lz) {
  const uint32_t nx = axisNeedBits(lx), ny = axisNeedBits(ly), nz = axisNeedBits(lz);
  // Spread a 4-bit set to one bit per nibble (4 bits apart) and per 16 bits; multiplying places
  // the inner set at each selected position (no carries: the sets do not overlap).
  const uint32_t spreadY = (ny & 1u) | ((ny & 2u) << 3) | ((ny & 4u) << 6) | ((ny & 8u) << 9);
  const uint64_t spreadZ = uint64_t(nz & 1u) | (uint64_t(nz & 2u) << 15) | (uint64_t(nz & 4u) << 30) |
                           (uint64_t(nz & 8u) << 45);
  return spreadZ * uint64_t(spreadY * nx);
}

// Entries of the coefficient stream before coefficient c of a brick: popcount of the mask below c.
CANOPY_HD CANOPY_FORCEINLINE uint32_t maskRank(uint64_t mask, int c) {
  return uint32_t(popcount64(mask & ((uint64_t(1) << c) - 1u)));
}

// Trilinear sample of one brick: (lx, ly, lz) in 0..2 is the lower texel of the 2^3 footprint
// (brick-local), (fx, fy, fz) in [0, 1] the fractions. Reconstructs just the 8 texels from just
// the kept coefficients they depend on (at most 27 of the 64; a row of 4 x-coefficients, or a
// z-slab of 16, with none of them kept is skipped whole), in the reference decoder's order: each
// row unlifted along x, the rows of a slab along y, the slabs along z.
template <class Reader>
CANOPY_HD inline Rgb sampleBrick(const BrickRecord& rec, const Reader& read, int lx, int ly, int lz,
                                 float fx, float fy, float fz) {
  const uint64_t mask = rec.mask();
  if (mask == 0) return Rgb{};
  const uint32_t first = rec.first();
  if (mask == 1u && !rec.raw()) return read(first);  // only the average: the fast path
  Rgb v[2][2][2] = {};  // [z][y][x]
  if (rec.raw()) {
    // Raw values: texel (x, y, z) is entry c of the brick when its mask bit is set, else zero.
    CANOPY_UNROLL
    for (int dz = 0; dz < 2; ++dz)
      CANOPY_UNROLL
      for (int dy = 0; dy < 2; ++dy) {
        const int row = brickIndex(0, ly + dy, lz + dz);
        const uint32_t rowBits = uint32_t(mask >> row) & 0xfu;
        if (!(rowBits >> lx & 3u)) continue;
        const uint32_t rowFirst = first + maskRank(mask, row);
        CANOPY_UNROLL
        for (int dx = 0; dx < 2; ++dx) {
          const int x = lx + dx;
          if (rowBits >> x & 1u) v[dz][dy][dx] = read(rowFirst + uint32_t(popcount64(rowBits & ((1u << x) - 1u))));
        }
      }
  } else {
    const uint64_t need = mask & footprintNeedMask(lx, ly, lz);
    CANOPY_UNROLL
    for (int kz = 0; kz < 4; ++kz) {
      const uint32_t slab = uint32_t(need >> (16 * kz)) & 0xffffu;
      if (!slab) continue;
      Rgb w[2][2] = {};  // [y][x]: x and y unlifted, coefficient index kz along z
      CANOPY_UNROLL
      for (int ky = 0; ky < 4; ++ky) {
        const uint32_t nib = (slab >> (4 * ky)) & 0xfu;
        if (!nib) continue;
        const int row = brickIndex(0, ky, kz);
        const uint32_t rowBits = uint32_t(mask >> row) & 0xfu;
        const uint32_t rowFirst = first + maskRank(mask, row);
        Rgb u[2] = {};  // [x]: x unlifted, coefficient indices (ky, kz)
        CANOPY_UNROLL
        for (int kx = 0; kx < 4; ++kx) {
          if (!(nib >> kx & 1u)) continue;
          const Rgb c = read(rowFirst + uint32_t(popcount64(rowBits & ((1u << kx) - 1u))));
          foldSigned(u[0], c, axisSign(kx, lx));
          foldSigned(u[1], c, axisSign(kx, lx + 1));
        }
        CANOPY_UNROLL
        for (int dy = 0; dy < 2; ++dy) {
          const uint32_t s = axisSign(ky, ly + dy);
          CANOPY_UNROLL
          for (int dx = 0; dx < 2; ++dx) foldSigned(w[dy][dx], u[dx], s);
        }
      }
      CANOPY_UNROLL
      for (int dz = 0; dz < 2; ++dz) {
        const uint32_t s = axisSign(kz, lz + dz);
        CANOPY_UNROLL
        for (int dy = 0; dy < 2; ++dy)
          CANOPY_UNROLL
          for (int dx = 0; dx < 2; ++dx) foldSigned(v[dz][dy][dx], w[dy][dx], s);
      }
    }
  }
  float ch[2][2][2];
  Rgb out;
  CANOPY_UNROLL
  for (int i = 0; i < 8; ++i) (&ch[0][0][0])[i] = (&v[0][0][0])[i].r;
  out.r = trilinear(ch, fx, fy, fz);
  CANOPY_UNROLL
  for (int i = 0; i < 8; ++i) (&ch[0][0][0])[i] = (&v[0][0][0])[i].g;
  out.g = trilinear(ch, fx, fy, fz);
  CANOPY_UNROLL
  for (int i = 0; i < 8; ++i) (&ch[0][0][0])[i] = (&v[0][0][0])[i].b;
  out.b = trilinear(ch, fx, fy, fz);
  return out;
}

}  // namespace canopy::haar
