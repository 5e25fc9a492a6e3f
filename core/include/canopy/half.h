// half.h: IEEE 754 binary16 ("fp16") <-> float conversion, identical on host and device.
//
// Written with integer bit manipulation (no F16C, no cuda_fp16.h; on the device halfToFloat uses the
// exact hardware conversion, Inf/NaN rebuilt in software), so a coefficient decoded on the CPU and
// in a CUDA kernel gives the same float bit for bit (tests/core: all 65536 halves). floatToHalf rounds to nearest,
// ties to even, keeps subnormals, maps overflow to +-inf and NaN to a quiet NaN; halfToFloat is
// exact (every binary16 value is a float).
#pragma once
#include <cstdint>
#include <cstring>

#include "canopy/hd.h"

namespace canopy {

CANOPY_HD CANOPY_FORCEINLINE uint32_t floatBits(float f) {
#if defined(__CUDA_ARCH__)
  return __float_as_uint(f);
#else
  uint32_t u;
  std::memcpy(&u, &f, sizeof u);
  return u;
#endif
}

CANOPY_HD CANOPY_FORCEINLINE float bitsToFloat(uint32_t u) {
#if defined(__CUDA_ARCH__)
  return __uint_as_float(u);
#else
  float f;
  std::memcpy(&f, &u, sizeof f);
  return f;
#endif
}

constexpr float kHalfMax = 65504.0f;  // largest finite binary16

CANOPY_HD CANOPY_FORCEINLINE float halfToFloat(uint16_t h) {
#if defined(__CUDA_ARCH__)
  // Every finite binary16 is exactly a float, so the hardware conversion gives the bits of the
  // portable code below in one instruction; Inf/NaN are rebuilt by a branch-free select, which keeps
  // a NaN's payload as the portable code does. Measured on an H100: with the portable code inlined
  // here fp16 .chaar sampling ran 11x slower than fp32; with a branch to it per value the player's
  // grove frame took 22.7 ms, with this select 16.2 ms.
  float f;
  asm("cvt.f32.f16 %0, %1;" : "=f"(f) : "h"(h));
  const uint32_t special = (uint32_t(h & 0x8000u) << 16) | 0x7f800000u | (uint32_t(h & 0x3ffu) << 13);
  return (h & 0x7c00u) == 0x7c00u ? bitsToFloat(special) : f;
#else
  const uint32_t sign = uint32_t(h & 0x8000u) << 16;
  const uint32_t exp = (h >> 10) & 0x1fu;
  uint32_t mant = h & 0x3ffu;
  if (exp == 0x1f) return bitsToFloat(sign | 0x7f800000u | (mant << 13));  // inf / NaN
  if (exp != 0) return bitsToFloat(sign | ((exp + 112u) << 23) | (mant << 13));
  if (mant == 0) return bitsToFloat(sign);  // +-0
  // Subnormal: normalise the mantissa.
  uint32_t e = 113u;
  while ((mant & 0x400u) == 0) {
    mant <<= 1;
    --e;
  }
  return bitsToFloat(sign | (e << 23) | ((mant & 0x3ffu) << 13));
#endif
}

// The value of a half, for hot loops that read stored coefficients (the Haar samplers): on the
// device the bare hardware conversion, one instruction. Bit for bit halfToFloat for every half but
// NaN, which stays a NaN with perhaps another payload (a NaN coefficient is invalid input anyway).
CANOPY_HD CANOPY_FORCEINLINE float halfValue(uint16_t h) {
#if defined(__CUDA_ARCH__)
  float f;
  asm("cvt.f32.f16 %0, %1;" : "=f"(f) : "h"(h));
  return f;
#else
  return halfToFloat(h);
#endif
}

CANOPY_HD CANOPY_FORCEINLINE uint16_t floatToHalf(float f) {
  const uint32_t u = floatBits(f);
  const uint16_t sign = uint16_t((u >> 16) & 0x8000u);
  const uint32_t absu = u & 0x7fffffffu;
  if (absu >= 0x7f800000u)  // inf or NaN
    return uint16_t(sign | 0x7c00u | (absu > 0x7f800000u ? 0x200u : 0u));
  if (absu >= 0x477ff000u) return uint16_t(sign | 0x7c00u);  // rounds to >= 65520: overflow
  if (absu < 0x38800000u) {
    // Result is subnormal (or zero): value = mant * 2^-24.
    if (absu < 0x33000000u) return sign;  // < 2^-25: rounds to zero (ties to even at 2^-25)
    const uint32_t e = absu >> 23;
    const uint32_t m = (absu & 0x7fffffu) | 0x800000u;
    const uint32_t shift = 126u - e;  // 14..24
    uint32_t r = m >> shift;
    const uint32_t rem = m & ((1u << shift) - 1u);
    const uint32_t half = 1u << (shift - 1u);
    if (rem > half || (rem == half && (r & 1u))) ++r;
    return uint16_t(sign | r);
  }
  // Normal: rebias exponent, round the 13 dropped mantissa bits to nearest even.
  uint32_t r = ((absu >> 13) - (112u << 10));
  const uint32_t rem = absu & 0x1fffu;
  if (rem > 0x1000u || (rem == 0x1000u && (r & 1u))) ++r;  // may carry into the exponent: fine
  return uint16_t(sign | r);
}

}  // namespace canopy
