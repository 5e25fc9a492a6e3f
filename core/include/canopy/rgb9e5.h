// rgb9e5.h: non-negative RGB in one 32-bit word with a shared exponent (the layout of OpenGL's
// EXT_texture_shared_exponent, Vulkan's E5B9G9R9_UFLOAT_PACK32), identical on host and device.
//
// Bits 0-8 red, 9-17 green, 18-26 blue (9-bit mantissas, no implicit one), 27-31 the shared
// exponent e (bias 15): a channel's value is mantissa * 2^(e - 24). The largest value is
// 511/512 * 2^16 = 65408; the smallest non-zero 2^-24. Each channel is within half a unit,
// 2^(e - 25), which is at most max(r, g, b) / 511 (or 2^-25 for values below 2^-16). Every word
// decodes to a finite value, so a corrupt word can give wrong light but never a NaN.
//
// Used for the light items of `.canopy` files from 4.0 (formats/canopy_layout.h): two thirds of the
// bytes of three float16s, one load per sample instead of three.
#pragma once
#include <cmath>
#include <cstdint>

#include "canopy/half.h"
#include "canopy/hd.h"

namespace canopy {

constexpr float kRgb9e5Max = 65408.0f;  // 511/512 * 2^16

// The three channels of a shared-exponent word. Exact: mantissa * 2^(e - 24), a normal float (or
// 0). No integer-to-float conversion (a slow pipe on the GPU, and a player's light sample decodes
// 32 words): with E = e + 126, the float of bits E << 23 | m is 2^(E - 127) + m 2^(E - 150), so
// subtracting the float of bits E << 23 leaves m 2^(e - 24) exactly (both in one binade).
CANOPY_HD CANOPY_FORCEINLINE void rgb9e5Decode(uint32_t w, float rgb[3]) {
  const uint32_t e = ((w >> 27) + 126u) << 23;
  const float base = bitsToFloat(e);
  rgb[0] = bitsToFloat(e | (w & 511u)) - base;
  rgb[1] = bitsToFloat(e | ((w >> 9) & 511u)) - base;
  rgb[2] = bitsToFloat(e | ((w >> 18) & 511u)) - base;
}

// Nearest word for r, g, b (the extension's algorithm, round half up): values below 0 and NaN
// become 0, values above kRgb9e5Max become kRgb9e5Max. Deterministic (double arithmetic on exact
// powers of two).
inline uint32_t rgb9e5Encode(float r, float g, float b) {
  auto clampChannel = [](float v) { return v > 0.0f ? double(v < kRgb9e5Max ? v : kRgb9e5Max) : 0.0; };  // NaN -> 0
  const double c[3] = {clampChannel(r), clampChannel(g), clampChannel(b)};
  const double maxc = std::fmax(c[0], std::fmax(c[1], c[2]));
  int e = 0;  // shared exponent: 2^(e - 16) > maxc, at least 0
  if (maxc > 0.0) {
    int exp2 = 0;
    std::frexp(maxc, &exp2);  // maxc = m * 2^exp2, m in [0.5, 1): floor(log2 maxc) = exp2 - 1
    e = exp2 + 15 < 0 ? 0 : exp2 + 15;
  }
  if (std::floor(std::ldexp(maxc, 24 - e) + 0.5) >= 512.0) ++e;  // the largest rounds up to 2^9
  uint32_t w = uint32_t(e) << 27;
  for (int i = 0; i < 3; ++i) w |= uint32_t(std::floor(std::ldexp(c[i], 24 - e) + 0.5)) << (9 * i);
  return w;
}

}  // namespace canopy
