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
//
// Quantised bases (Precision::Quant, .chaar 2.0 and 2.1) store integer levels in bit streams with
// 16-byte records instead: see "quantised coefficients" below.
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

enum class Precision : uint32_t { Fp32 = 0, Fp16 = 1, Quant = 2 };

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

// Expands a brick's kept coefficients (by rank, as sampleMasked reads them) into 64 values per
// channel and unlifts them (raw bricks are copied), then applies coef.finish per value. out[ch][c].
// This is the reference decoder of one brick.
template <class Coefs>
CANOPY_HD inline void decodeMasked(uint64_t mask, bool raw, const Coefs& coef, float out[3][kBrickValues]) {
  uint32_t j = 0;
  for (int c = 0; c < kBrickValues; ++c) {
    Rgb v{};
    if ((mask >> c) & 1u) v = coef(j++, uint32_t(c));
    out[0][c] = v.r;
    out[1][c] = v.g;
    out[2][c] = v.b;
  }
  if (!raw)
    for (int ch = 0; ch < 3; ++ch) unliftBrick(out[ch]);
  for (int c = 0; c < kBrickValues; ++c) {
    const Rgb v = coef.finish(Rgb{out[0][c], out[1][c], out[2][c]});
    out[0][c] = v.r;
    out[1][c] = v.g;
    out[2][c] = v.b;
  }
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
// kept coefficients whose W is non-zero on all three axes are read (footprintNeedMask): 3 per axis
// at l = 0 or 2, 4 at l = 1, so 27 to 64 of a Haar brick's 64, and 8 of a raw brick's, in one loop
// over their bits. Branch-free per coefficient; but a warp runs its loop as often as its busiest
// lane needs: on oak_medium's light at 64^3 (1 % RMS) 30.2 iterations for a mean of 11.1 needed
// coefficients per lane (quant), 25.8 for 7.3 (fp16). Spreading a warp's terms evenly over its
// lanes (same terms, same order of addition, through shared memory) was tried and measured slower
// (docs/performance.md, 'Raw bricks': quant 9.5 against 11.6 G samples/s on an H200).
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
// The coefficients a Haar brick's footprint at (lx, ly, lz) depends on (27 to 64 of 64).
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
  float wx[4] = {}, wy[4] = {}, wz[4] = {};
  uint64_t need = 0;  // mask bits whose weight is non-zero on all three axes
  // The weight of coefficient c + 32 * h (x + 4y + 16z), c in 0..31, in half h of the mask (z in
  // {2h, 2h + 1}: the z weight is one select): wx(x) * wy(y) * wz(z), rounded in that order.
  CANOPY_HD CANOPY_FORCEINLINE float inHalf(uint32_t c, int h) const {
    return mulRn(mulRn(pickWeight(wx, c & 3u), pickWeight(wy, (c >> 2) & 3u)), (c & 16u) ? wz[2 * h + 1] : wz[2 * h]);
  }
};
CANOPY_HD CANOPY_FORCEINLINE FootprintWeights footprintWeights(uint64_t mask, bool raw, int lx, int ly, int lz, float fx,
                                                             float fy, float fz) {
  FootprintWeights fw;
  if (raw) {
    rawAxisWeights(lx, fx, fw.wx);
    rawAxisWeights(ly, fy, fw.wy);
    rawAxisWeights(lz, fz, fw.wz);
    fw.need = mask & coefficientBox(3u << lx, 3u << ly, 3u << lz);
  } else {
    haarAxisWeights(lx, fx, fw.wx);
    haarAxisWeights(ly, fy, fw.wy);
    haarAxisWeights(lz, fz, fw.wz);
    fw.need = mask & footprintNeedMask(lx, ly, lz);
  }
  return fw;
}
CANOPY_HD CANOPY_FORCEINLINE Rgb weighted(const Rgb& v, float w) { return Rgb{mulRn(v.r, w), mulRn(v.g, w), mulRn(v.b, w)}; }
CANOPY_HD CANOPY_FORCEINLINE void addTo(Rgb& out, const Rgb& t) {
  out.r = addRn(out.r, t.r);
  out.g = addRn(out.g, t.g);
  out.b = addRn(out.b, t.b);
}

// A sample's sum: out + the terms coef(rank, c) * weight(c) over the kept coefficients c it needs, in
// increasing c. Both samplers (float and quantised) are this sum.
template <class Coefs>
CANOPY_HD CANOPY_FORCEINLINE Rgb sumTerms(Rgb out, const FootprintWeights& fw, uint32_t maskLo, uint32_t maskHi,
                                          const Coefs& coef) {
  // The mask's two 32-bit halves in two loops: 32-bit bit scans and popcounts (measured on an H200:
  // 20.4 against 16.5 G samples/s for one loop over the 64-bit set).
  for (uint32_t need = uint32_t(fw.need); need; need &= need - 1u) {
    const uint32_t c = lowestBit32(need);
    addTo(out, weighted(coef(popcount32(maskLo & ((1u << c) - 1u)), c), fw.inHalf(c, 0)));
  }
  const uint32_t rankHi = popcount32(maskLo);
  for (uint32_t need = uint32_t(fw.need >> 32); need; need &= need - 1u) {
    const uint32_t c = lowestBit32(need);
    addTo(out, weighted(coef(rankHi + popcount32(maskHi & ((1u << c) - 1u)), c + 32u), fw.inHalf(c, 1)));
  }
  return out;
}

// Trilinear sample of a brick given its mask and its kept coefficients by rank: coef(j, c) returns
// the j-th kept coefficient (in mask order), which is coefficient c of the brick. The float
// sampler (sampleBrick); quantised bricks have their own, sampleQuantBrick, which folds the steps
// into the weights.
// (lx, ly, lz) in 0..2 is the lower texel of the 2^3 footprint (brick-local), (fx, fy, fz) in
// [0, 1] the fractions. The terms are summed in coefficient order.
template <class Coefs>
CANOPY_HD inline Rgb sampleMasked(uint64_t mask, bool raw, const Coefs& coef, int lx, int ly, int lz, float fx,
                                  float fy, float fz) {
  if (mask == 0) return Rgb{};
  if (mask == 1u && !raw) return coef(0u, 0u);  // only the average: the fast path
  return sumTerms(Rgb{}, footprintWeights(mask, raw, lx, ly, lz, fx, fy, fz), uint32_t(mask), uint32_t(mask >> 32),
                  coef);
}

// The kept coefficients of a float brick record: entries first, first + 1, ... of a stream
// (finish: decodeMasked's per-value map, the identity here).
template <class Reader>
struct RankedEntries {
  const Reader& read;
  uint32_t first;
  CANOPY_HD CANOPY_FORCEINLINE Rgb operator()(uint32_t j, uint32_t) const { return read(uint64_t(first) + j); }
  CANOPY_HD CANOPY_FORCEINLINE Rgb finish(const Rgb& v) const { return v; }
};

// Trilinear sample of one float brick (fp32 or fp16 stream).
template <class Reader>
CANOPY_HD inline Rgb sampleBrick(const BrickRecord& rec, const Reader& read, int lx, int ly, int lz,
                                 float fx, float fy, float fz) {
  return sampleMasked(rec.mask(), rec.raw(), RankedEntries<Reader>{read, rec.first()}, lx, ly, lz, fx, fy, fz);
}

// The reference decoder of one float brick.
template <class Reader>
CANOPY_HD inline void decodeBrick(const BrickRecord& rec, const Reader& read, float out[3][kBrickValues]) {
  decodeMasked(rec.mask(), rec.raw(), RankedEntries<Reader>{read, rec.first()}, out);
}

// ---- quantised coefficients (Precision::Quant, .chaar 2.0 and 2.1) -----------------------------
//
// A quantised base stores integers: channel values are first taken to (Y, R-Y, B-Y) with Y = G
// (the light's channels are strongly correlated, so the two differences are small), lifted as
// above, and coefficient c of a brick is stored as q = round(v / step) per channel, where step =
// the base's step T times sqrt(2) per axis along which c is a fine detail (d0 or d1: those basis
// functions cover half the texels, so their error weighs half as much). |v| < kQuantDeadZone *
// step stores 0; a coefficient whose three q are 0 is dropped from the mask. Decoding multiplies
// back (q * step, rounded float), unlifts, and maps (Y, R-Y, B-Y) back to RGB.
//
// Bits: each base's stream is an array of little-endian 64-bit words. A brick's fields start at
// its record's bitOffset: the average's three channels (if mask bit 0 is set), then each kept
// detail's three channels in mask order; a field is a two's-complement integer of its width, the
// widths (0..15 bits, 0 = all zero) are per brick, one per channel for the average and one per
// channel for the details (QuantRecord::widths). A coefficient's three fields are read from one
// 64-bit window at its bit position (quantWindow); each base stream ends with one zero word, so
// the window's loads never leave the stream.

constexpr float kQuantDeadZone = 0.7f;     // |v| / step below this stores 0
constexpr int kQuantMaxWidth = 15;         // bits per field
constexpr int32_t kQuantMaxLevel = 16383;  // |q| <= 2^14 - 1 (15-bit fields, one level of margin)
// Raw quantised bricks (.chaar 2.1): the brick's values (Y, R-Y, B-Y), not its coefficients, each
// q = round(v / (kQuantRawFactor * T)); flagged by kQuantRawBit in QuantRecord::widths. The encoder
// stores a brick raw where its Haar form keeps more than kQuantRawAbove coefficients: a sample then
// needs at most 8 fields instead of up to 64 (docs/performance.md, 'Raw bricks').
constexpr uint32_t kQuantRawBit = 0x80000000u;
constexpr float kQuantRawFactor = 4.0f;  // a power of two: T * 4 is exact
constexpr int kQuantRawAbove = 16;

// One brick of one quantised base: 16 bytes on disk and in memory.
struct alignas(16) QuantRecord {  // (aligned: one 16-byte load on the device)
  uint32_t maskLo = 0, maskHi = 0;  // kept coefficients (bit c = coefficient c)
  uint32_t bitOffset = 0;           // first bit of the brick's fields in the base's stream
  uint32_t widths = 0;              // nibbles: 0-2 the average's Y, R-Y, B-Y widths, 3-5 the details'; bits
                                    // 24-30 zero; bit 31 kQuantRawBit (2.1: values, with the details' widths)
  CANOPY_HD uint64_t mask() const { return uint64_t(maskLo) | (uint64_t(maskHi) << 32); }
  CANOPY_HD bool raw() const { return (widths & kQuantRawBit) != 0; }
  CANOPY_HD uint32_t width(int group, int ch) const { return (widths >> (4 * (3 * group + ch))) & 0xfu; }
  CANOPY_HD uint32_t groupBits(int group) const { return width(group, 0) + width(group, 1) + width(group, 2); }
  // 1 where the brick stores an average (mask bit 0 of a Haar brick) with the group-0 widths.
  CANOPY_HD uint32_t hasAverage() const { return raw() ? 0u : (maskLo & 1u); }
  // Bits of all the brick's fields.
  CANOPY_HD uint64_t bits() const {
    const uint32_t has0 = hasAverage();
    return uint64_t(has0) * groupBits(0) + uint64_t(popcount64(mask()) - int(has0)) * groupBits(1);
  }
};
static_assert(sizeof(QuantRecord) == 16, "QuantRecord is 16 bytes on disk and on the device");

// A record read whole (one 16-byte load on the device, not one load per field as it is used).
CANOPY_HD CANOPY_FORCEINLINE QuantRecord loadQuantRecord(const QuantRecord* p) {
#if defined(__CUDA_ARCH__)
  const uint4 u = __ldg(reinterpret_cast<const uint4*>(p));
  QuantRecord r;
  r.maskLo = u.x, r.maskHi = u.y, r.bitOffset = u.z, r.widths = u.w;
  return r;
#else
  return *p;
#endif
}

// The number of axes along which coefficient c (x + 4y + 16z) is a fine detail (axis index 2 or 3).
CANOPY_HD CANOPY_FORCEINLINE uint32_t fineDetailAxes(uint32_t c) {
  return ((c >> 1) & 1u) + ((c >> 3) & 1u) + ((c >> 5) & 1u);
}

// The step factor per fine-detail axis.
constexpr double kQuantFineFactor = 1.4142135623730951;  // sqrt(2)

// The steps of a base with step T: T * sqrt(2)^n for n = 0..3 fine-detail axes, each rounded to
// float once (readers compute them on the host, so CPU and GPU use the same bits), and step[4] =
// T * kQuantRawFactor for raw bricks' values.
constexpr int kQuantSteps = 5;
inline void quantSteps(float T, float step[kQuantSteps]) {
  double s = double(T);
  for (int n = 0; n < 4; ++n, s *= kQuantFineFactor) step[n] = float(s);
  step[4] = T * kQuantRawFactor;
}

// 32-bit word i of a stream of little-endian 64-bit words.
CANOPY_HD CANOPY_FORCEINLINE uint32_t streamWord(const uint64_t* words, uint32_t i) {
#if defined(__CUDA_ARCH__)
  return __ldg(reinterpret_cast<const uint32_t*>(words) + i);
#else
  return uint32_t(words[i >> 1] >> (32u * (i & 1u)));
#endif
}
// Bits sh .. sh+31 of hi:lo (sh taken mod 32): the device's funnel shift.
CANOPY_HD CANOPY_FORCEINLINE uint32_t funnelRight(uint32_t lo, uint32_t hi, uint32_t sh) {
#if defined(__CUDA_ARCH__)
  return __funnelshift_r(lo, hi, sh);
#else
  return uint32_t(((uint64_t(hi) << 32) | lo) >> (sh & 31u));
#endif
}
// The 64 bits of a stream from bit pos as two halves, from three aligned 32-bit words and two
// funnel shifts (a kept coefficient's fields end at or before the stream's last used bit, so the
// third word lies inside the base's end word). CPU and device run the same steps; only the load and
// the funnel shift are intrinsics on the device. (Reading the third word only for triples over 33
// bits was measured slower: 13.77 against 13.97 G samples/s on an H200.)
CANOPY_HD CANOPY_FORCEINLINE void quantWindow(const uint64_t* words, uint32_t pos, uint32_t& lo, uint32_t& hi) {
  const uint32_t i = pos >> 5;
  const uint32_t a = streamWord(words, i), b = streamWord(words, i + 1), c = streamWord(words, i + 2);
  lo = funnelRight(a, b, pos);
  hi = funnelRight(b, c, pos);
}

// A two's-complement field of width w (0..15) to float, exactly, without shifts or a conversion:
// flipping its sign bit gives q + 2^(w-1) as an unsigned field u; with the exponent bits of
// 1.5 * 2^23 ORed in (they lie above bit 22), the word is the float 1.5 * 2^23 + u, and adding
// -(1.5 * 2^23 + 2^(w-1)) leaves q. Mask, flip and OR are one three-input logic instruction on the
// device ((x & m) ^ k with k = sign bit | exponent bits), then one float add. Width 0: m = 0, so
// the result is 0.
struct QuantField {
  uint32_t m, k;  // the field's mask, and its sign bit | 0x4B400000
  float o;        // -(1.5 * 2^23 + 2^(w-1)); -1.5 * 2^23 at w = 0
  CANOPY_HD CANOPY_FORCEINLINE explicit QuantField(uint32_t w) {
    m = (1u << w) - 1u;
    const uint32_t sign = (m + 1u) >> 1;
    k = sign | 0x4B400000u;
    o = -(12582912.0f + float(sign));  // exact: an integer below 2^24
  }
  CANOPY_HD CANOPY_FORCEINLINE float operator()(uint32_t x) const {
    const uint32_t u = (x & m) ^ k;
#if defined(__CUDA_ARCH__)
    return __fadd_rn(__uint_as_float(u), o);
#else
    float f;
    __builtin_memcpy(&f, &u, 4);
    return f + o;
#endif
  }
};

// One group's (average or details) three field layouts, fixed per brick: the offsets of the second
// and third field in the window (the first is at 0) and each field's decoding constants.
struct QuantFieldLayout {
  uint32_t at1, at2;
  QuantField f0, f1, f2;
  CANOPY_HD CANOPY_FORCEINLINE explicit QuantFieldLayout(uint32_t widths3)
      : at1(widths3 & 0xfu),
        at2((widths3 & 0xfu) + ((widths3 >> 4) & 0xfu)),
        f0(widths3 & 0xfu),
        f1((widths3 >> 4) & 0xfu),
        f2((widths3 >> 8) & 0xfu) {}
  CANOPY_HD CANOPY_FORCEINLINE Rgb levels(const uint64_t* words, uint32_t pos) const {
    uint32_t lo, hi;
    quantWindow(words, pos, lo, hi);
    return Rgb{f0(lo), f1(funnelRight(lo, hi, at1)), f2(funnelRight(lo, hi, at2))};
  }
};

// (Y, R-Y, B-Y) -> RGB.
CANOPY_HD CANOPY_FORCEINLINE Rgb quantToRgb(const Rgb& v) { return Rgb{addRn(v.r, v.g), v.r, addRn(v.r, v.b)}; }

// The detail fields of a quantised brick by rank j (counting the average, as the mask does; a raw
// brick's values are all "details"): detail j starts at bit base + j * bits of the base's stream,
// base = bitOffset + hasAverage * (average bits - detail bits) (unsigned wrap-around).
struct QuantDetails {
  const uint64_t* words;  // the base's stream
  QuantFieldLayout layout;
  uint32_t base, bits;
  CANOPY_HD CANOPY_FORCEINLINE QuantDetails(const QuantRecord& r, const uint64_t* w)
      : words(w), layout((r.widths >> 12) & 0xfffu), base(r.bitOffset + r.hasAverage() * (r.groupBits(0) - r.groupBits(1))),
        bits(r.groupBits(1)) {}
  CANOPY_HD CANOPY_FORCEINLINE Rgb operator()(uint32_t j, uint32_t) const { return layout.levels(words, base + j * bits); }
};

// The kept coefficients of a quantised brick record (the rank accessor of decodeMasked): levels
// times the coefficient's step.
struct QuantBrick {
  const uint64_t* words;  // the base's stream
  const float* step;      // the base's steps (quantSteps)
  QuantFieldLayout avg;
  QuantDetails details;
  uint32_t pos0;
  bool has0, raw;
  CANOPY_HD CANOPY_FORCEINLINE QuantBrick(const QuantRecord& r, const uint64_t* w, const float* st)
      : words(w), step(st), avg(r.widths & 0xfffu), details(r, w), pos0(r.bitOffset), has0(r.hasAverage() != 0),
        raw(r.raw()) {}
  CANOPY_HD CANOPY_FORCEINLINE Rgb operator()(uint32_t j, uint32_t c) const {
    const Rgb q = c == 0 && has0 ? avg.levels(words, pos0) : details(j, c);
    const uint32_t n = fineDetailAxes(c);
    const float st = raw ? step[4] : n < 2 ? (n == 0 ? step[0] : step[1]) : (n == 2 ? step[2] : step[3]);
    return Rgb{mulRn(q.r, st), mulRn(q.g, st), mulRn(q.b, st)};
  }
  CANOPY_HD CANOPY_FORCEINLINE Rgb finish(const Rgb& v) const { return quantToRgb(v); }
};

// Trilinear sample of a quantised brick: sumTerms over the integer levels, starting from the
// average's levels (weight 1 on every axis), with the steps folded in (Haar: sqrt(2) into each
// axis's fine-detail weights; raw: the trilinear weights), the base step (`T`, or `rawStep` = T *
// kQuantRawFactor for a raw brick: the base's step[0] and step[4]) applied once to the sum, then
// (Y, R-Y, B-Y) -> RGB. CPU and GPU agree bit for bit; decodeQuantBrick then trilinear agrees up to
// float rounding (the steps are applied in another order).
CANOPY_HD inline Rgb sampleQuantBrick(const QuantRecord& rec, const uint64_t* words, float T, float rawStep, int lx,
                                      int ly, int lz, float fx, float fy, float fz) {
  if (rec.maskLo == 0 && rec.maskHi == 0) return Rgb{};
  const bool raw = rec.raw();
  const uint32_t has0 = rec.hasAverage();
  Rgb init;
  if (has0) init = QuantFieldLayout(rec.widths & 0xfffu).levels(words, rec.bitOffset);
  // (An average-only brick needs no details: fw.need is 0.)
  FootprintWeights fw = footprintWeights(rec.mask() & ~uint64_t(has0), raw, lx, ly, lz, fx, fy, fz);
  if (!raw) {
    const float r2 = float(kQuantFineFactor);
    fw.wx[2] = mulRn(fw.wx[2], r2), fw.wx[3] = mulRn(fw.wx[3], r2);
    fw.wy[2] = mulRn(fw.wy[2], r2), fw.wy[3] = mulRn(fw.wy[3], r2);
    fw.wz[2] = mulRn(fw.wz[2], r2), fw.wz[3] = mulRn(fw.wz[3], r2);
  }
  const Rgb sum = sumTerms(init, fw, rec.maskLo, rec.maskHi, QuantDetails(rec, words));
  return quantToRgb(weighted(sum, raw ? rawStep : T));
}
CANOPY_HD inline void decodeQuantBrick(const QuantRecord& rec, const uint64_t* words, const float* step,
                                       float out[3][kBrickValues]) {
  decodeMasked(rec.mask(), rec.raw(), QuantBrick(rec, words, step), out);
}

}  // namespace canopy::haar
