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
// The CPU and CUDA decoders agree bit for bit (products use explicitly rounded multiplies/adds on
// the device so nvcc cannot contract them into FMAs). The point sampler below (sampleBrick) does not
// decode: it sums the kept coefficients its footprint depends on, each times the trilinear weight
// of its basis function; CPU and CUDA samples agree bit for bit too, and equal decode-then-trilinear
// up to float rounding.
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
    return Rgb{halfValue(p[3 * i]), halfValue(p[3 * i + 1]), halfValue(p[3 * i + 2])};
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

// ---- trilinear sampling inside one brick, as one weighted sum ---------------------------------
//
// A trilinear sample is linear in the brick's coefficients: sample = sum over coefficients k of
// c_k * Wx(kx) * Wy(ky) * Wz(kz), where W(k) along an axis is the trilinear interpolation of that
// axis's Haar basis function k. Position pos (0..3) is reconstructed as ((s +- D) +- d_{pos/2})
// (unlift4), so with the footprint's lower texel at l and fraction f (weights 1-f at l, f at l+1):
//   l = 0: W = [1,  1,     1-2f,  0   ]
//   l = 1: W = [1,  1-2f,  f-1,   f   ]
//   l = 2: W = [1, -1,     0,     1-2f]
// and for a raw brick (values, no transform) W(k) = 1-f at k = l, f at k = l+1, else 0. Only the
// kept coefficients whose W is non-zero on all three axes are read (footprintNeedMask): at most 27
// of a Haar brick's 64, 8 of a raw brick's, in one loop over their bits. Branch-free per
// coefficient, so the 32 samples of a warp in 32 different bricks do not diverge (as a per-row or
// per-slab structure does).
//
// The sum is in coefficient order with explicitly rounded operations: CPU and CUDA give the same
// bits. It is not the same rounding as decoding the brick (decodeBrick) and interpolating its 8
// texels: the two agree to a few float ulps of the sum of |c_k W_k| (tests bound it).

CANOPY_HD CANOPY_FORCEINLINE void haarAxisWeights(int l, float f, float w[4]) {
  const float e = subRn(1.0f, addRn(f, f));  // 1 - 2f (2f is exact)
  w[0] = 1.0f;
  w[1] = l == 0 ? 1.0f : (l == 1 ? e : -1.0f);
  w[2] = l == 0 ? e : (l == 1 ? subRn(f, 1.0f) : 0.0f);
  w[3] = l == 0 ? 0.0f : (l == 1 ? f : e);
}
CANOPY_HD CANOPY_FORCEINLINE void rawAxisWeights(int l, float f, float w[4]) {
  const float g = subRn(1.0f, f);
  w[0] = l == 0 ? g : 0.0f;
  w[1] = l == 1 ? g : (l == 0 ? f : 0.0f);
  w[2] = l == 2 ? g : (l == 1 ? f : 0.0f);
  w[3] = l == 2 ? f : 0.0f;
}
// w[k] for a k known only at run time, by selects (an indexed register array would go to memory).
CANOPY_HD CANOPY_FORCEINLINE float pickWeight(const float w[4], uint32_t k) {
  const float lo = (k & 1u) ? w[1] : w[0], hi = (k & 1u) ? w[3] : w[2];
  return (k & 2u) ? hi : lo;
}

// The 64-bit set of coefficients c = x + 4y + 16z with x in nx, y in ny and z in nz (4-bit sets).
CANOPY_HD CANOPY_FORCEINLINE uint64_t coefficientBox(uint32_t nx, uint32_t ny, uint32_t nz) {
  // Spread ny to one bit per nibble and nz to one bit per 16 bits; multiplying places the inner
  // set at each selected position (no carries: the copies do not overlap).
  const uint32_t spreadY = (ny & 1u) | ((ny & 2u) << 3) | ((ny & 4u) << 6) | ((ny & 8u) << 9);
  const uint64_t spreadZ = uint64_t(nz & 1u) | (uint64_t(nz & 2u) << 15) | (uint64_t(nz & 4u) << 30) |
                           (uint64_t(nz & 8u) << 45);
  return spreadZ * uint64_t(spreadY * nx);
}
// The axis coefficients whose W is non-zero for a footprint at l (0..2): s and D always, d0 for
// l <= 1, d1 for l >= 1.
CANOPY_HD CANOPY_FORCEINLINE uint32_t axisNeedBits(int l) { return l == 0 ? 0x7u : (l == 1 ? 0xfu : 0xbu); }
// The coefficients a Haar brick's footprint at (lx, ly, lz) depends on (at most 27 of 64).
CANOPY_HD CANOPY_FORCEINLINE uint64_t footprintNeedMask(int lx, int ly, int lz) {
  return coefficientBox(axisNeedBits(lx), axisNeedBits(ly), axisNeedBits(lz));
}

CANOPY_HD CANOPY_FORCEINLINE uint32_t popcount32(uint32_t v) {
#if defined(__CUDA_ARCH__)
  return uint32_t(__popc(v));
#else
  return uint32_t(__builtin_popcount(v));
#endif
}
CANOPY_HD CANOPY_FORCEINLINE uint32_t lowestBit32(uint32_t v) {  // v != 0
#if defined(__CUDA_ARCH__)
  return uint32_t(__ffs(int(v)) - 1);
#else
  return uint32_t(__builtin_ctz(v));
#endif
}

// The per-axis weights of a footprint and the kept coefficients it needs (raw or Haar brick).
struct FootprintWeights {
  float wx[4], wy[4], wz[4];
  uint64_t need;  // mask bits whose weight is non-zero on all three axes
  // The weight of coefficient c (x + 4y + 16z).
  CANOPY_HD CANOPY_FORCEINLINE float operator()(uint32_t c) const {
    return mulRn(mulRn(pickWeight(wx, c & 3u), pickWeight(wy, (c >> 2) & 3u)), pickWeight(wz, c >> 4));
  }
};
CANOPY_HD CANOPY_FORCEINLINE FootprintWeights footprintWeights(const BrickRecord& rec, int lx, int ly, int lz, float fx,
                                                             float fy, float fz) {
  FootprintWeights fw;
  if (rec.raw()) {
    rawAxisWeights(lx, fx, fw.wx);
    rawAxisWeights(ly, fy, fw.wy);
    rawAxisWeights(lz, fz, fw.wz);
    fw.need = rec.mask() & coefficientBox(3u << lx, 3u << ly, 3u << lz);
  } else {
    haarAxisWeights(lx, fx, fw.wx);
    haarAxisWeights(ly, fy, fw.wy);
    haarAxisWeights(lz, fz, fw.wz);
    fw.need = rec.mask() & footprintNeedMask(lx, ly, lz);
  }
  return fw;
}
CANOPY_HD CANOPY_FORCEINLINE void accumulate(Rgb& out, const Rgb& v, float w) {
  out.r = addRn(out.r, mulRn(v.r, w));
  out.g = addRn(out.g, mulRn(v.g, w));
  out.b = addRn(out.b, mulRn(v.b, w));
}

// Trilinear sample of one brick: (lx, ly, lz) in 0..2 is the lower texel of the 2^3 footprint
// (brick-local), (fx, fy, fz) in [0, 1] the fractions. The terms are summed in coefficient order.
template <class Reader>
CANOPY_HD inline Rgb sampleBrick(const BrickRecord& rec, const Reader& read, int lx, int ly, int lz,
                                 float fx, float fy, float fz) {
  const uint64_t mask = rec.mask();
  if (mask == 0) return Rgb{};
  const uint32_t first = rec.first();
  if (mask == 1u && !rec.raw()) return read(first);  // only the average: the fast path
  const FootprintWeights fw = footprintWeights(rec, lx, ly, lz, fx, fy, fz);
  Rgb out;
  // The mask's two 32-bit halves in two loops: 32-bit bit scans and popcounts (measured on an H200:
  // 20.4 against 16.5 G samples/s for one loop over the 64-bit set).
  for (uint32_t need = uint32_t(fw.need); need; need &= need - 1u) {
    const uint32_t c = lowestBit32(need);
    accumulate(out, read(first + popcount32(rec.maskLo & ((1u << c) - 1u))), fw(c));
  }
  const uint32_t firstHi = first + popcount32(rec.maskLo);
  for (uint32_t need = uint32_t(fw.need >> 32); need; need &= need - 1u) {
    const uint32_t c = lowestBit32(need);
    accumulate(out, read(firstHi + popcount32(rec.maskHi & ((1u << c) - 1u))), fw(c + 32u));
  }
  return out;
}

}  // namespace canopy::haar
