// cone_math.h: the per-pixel code's small vector math (V3, Affine, 16-byte loads, the ray/box test,
// division by a run-time constant). Part of runtime/cone.h (which includes every part, in order).
#pragma once
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "canopy/half.h"
#include "canopy/hd.h"
#include "canopy/sun_lookup.h"
#include "formats/canopy_sample.h"

// Out of line on the device (large per-sample code called from several places of a kernel: one
// copy instead of one per call site); inline on the host.
#if defined(__CUDA_ARCH__)
#define CANOPY_PLAY_NOINLINE __noinline__
#else
#define CANOPY_PLAY_NOINLINE inline
#endif

namespace canopy::play {

// ------------------------------------------------------------------------------------------------
// Small vector math
// ------------------------------------------------------------------------------------------------
struct V3 {
  float x, y, z;
};
CANOPY_HD CANOPY_FORCEINLINE V3 v3(float x, float y, float z) { return V3{x, y, z}; }
CANOPY_HD CANOPY_FORCEINLINE V3 operator+(V3 a, V3 b) { return V3{a.x + b.x, a.y + b.y, a.z + b.z}; }
CANOPY_HD CANOPY_FORCEINLINE V3 operator-(V3 a, V3 b) { return V3{a.x - b.x, a.y - b.y, a.z - b.z}; }
CANOPY_HD CANOPY_FORCEINLINE V3 operator*(V3 a, float s) { return V3{a.x * s, a.y * s, a.z * s}; }
CANOPY_HD CANOPY_FORCEINLINE float dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
CANOPY_HD CANOPY_FORCEINLINE V3 cross(V3 a, V3 b) {
  return V3{a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
CANOPY_HD CANOPY_FORCEINLINE float length(V3 a) { return sqrtf(dot(a, a)); }
CANOPY_HD CANOPY_FORCEINLINE V3 normalize(V3 a) {
  const float l = length(a);
  return l > 0.0f ? a * (1.0f / l) : a;
}
CANOPY_HD CANOPY_FORCEINLINE float comp(V3 a, int i) { return i == 0 ? a.x : (i == 1 ? a.y : a.z); }

// The four 32-bit words at p (16-byte aligned): one 16-byte load on the GPU (the compiler does not
// merge a struct's scalar loads across branches, nor where it cannot see the alignment), a copy on
// the host. Callers decode the words alike on both, so the CPU tests run their decoding.
struct Words4 {
  uint32_t w[4];
};
CANOPY_HD CANOPY_FORCEINLINE Words4 load16(const void* p) {
  Words4 r;
#if defined(__CUDA_ARCH__)
  const uint4 v = *static_cast<const uint4*>(p);
  r.w[0] = v.x, r.w[1] = v.y, r.w[2] = v.z, r.w[3] = v.w;
#else
  memcpy(&r, p, sizeof r);
#endif
  return r;
}

// load16 of data that no thread writes while a kernel runs (canopyLoadRO): non-coherent on the GPU.
CANOPY_HD CANOPY_FORCEINLINE Words4 load16ro(const void* p) {
#if defined(__CUDA_ARCH__)
  const uint4 v = canopyLoadRO(static_cast<const uint4*>(p));
  return Words4{{v.x, v.y, v.z, v.w}};
#else
  return load16(p);
#endif
}

// A 3x4 row-major affine map. Rows 16-byte aligned: one 16-byte load each on the GPU.
struct alignas(16) Affine {
  float m[12];
};
CANOPY_HD CANOPY_FORCEINLINE V3 applyPoint(const Affine& a, V3 p) {
  return V3{a.m[0] * p.x + a.m[1] * p.y + a.m[2] * p.z + a.m[3], a.m[4] * p.x + a.m[5] * p.y + a.m[6] * p.z + a.m[7],
            a.m[8] * p.x + a.m[9] * p.y + a.m[10] * p.z + a.m[11]};
}
CANOPY_HD CANOPY_FORCEINLINE V3 applyVector(const Affine& a, V3 v) {
  return V3{a.m[0] * v.x + a.m[1] * v.y + a.m[2] * v.z, a.m[4] * v.x + a.m[5] * v.y + a.m[6] * v.z,
            a.m[8] * v.x + a.m[9] * v.y + a.m[10] * v.z};
}

// Ray/box slab test: [t0, t1] of o + t d inside [lo, hi] (t0 > t1 = miss).
CANOPY_HD inline void rayBox(V3 o, V3 d, V3 lo, V3 hi, float& t0, float& t1) {
  t0 = -3.0e38f;
  t1 = 3.0e38f;
  for (int a = 0; a < 3; ++a) {
    const float oa = comp(o, a), da = comp(d, a), l = comp(lo, a), h = comp(hi, a);
    if (fabsf(da) < 1e-30f) {
      if (oa < l || oa > h) {
        t0 = 1.0f, t1 = 0.0f;
        return;
      }
      continue;
    }
    const float inv = 1.0f / da;
    float ta = (l - oa) * inv, tb = (h - oa) * inv;
    if (ta > tb) {
      const float s = ta;
      ta = tb, tb = s;
    }
    t0 = ta > t0 ? ta : t0;
    t1 = tb < t1 ? tb : t1;
  }
}

// Division by a run-time constant without a division instruction (the GPU has none: its integer
// division is a ~20-instruction sequence): q = n / d = the high 64 bits of c * n with c = ceil(2^64 / d),
// exact for every 32-bit n and 2 <= d < 2^32 (Lemire, Kaser and Kurz 2019, "Faster remainder by
// direct computation", theorem 1 with F = 64, N = 32: c * d - 2^64 < d, so the error term stays
// below 1/d). c = 0 stands for d = 1.
struct IndexDivisor {
  uint64_t c;
  uint32_t d;
};
inline IndexDivisor indexDivisor(uint32_t d) { return IndexDivisor{d > 1 ? ~uint64_t(0) / d + 1 : 0, d > 0 ? d : 1}; }
// n / d, and n % d in rem.
CANOPY_HD CANOPY_FORCEINLINE uint32_t divide(const IndexDivisor& v, uint32_t n, uint32_t& rem) {
#if defined(__CUDA_ARCH__)
  const uint32_t q = v.c != 0 ? uint32_t(__umul64hi(v.c, uint64_t(n))) : n;
#else
  const uint32_t q = v.c != 0 ? uint32_t((unsigned __int128)v.c * n >> 64) : n;
#endif
  rem = n - q * v.d;
  return q;
}

}  // namespace canopy::play
