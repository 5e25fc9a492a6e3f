// texture_sample.h: glTF base-colour texture lookup (wrap modes, bilinear or nearest).
//
// Colour texels are sRGB-encoded (glTF baseColorTexture) and decoded to linear before filtering;
// alpha is linear. uv (0,0) is the image's top-left corner, as in glTF.
// A fine sub-cell covers many texels of a large texture, so lookups use a box-filtered mip chain
// (colour averaged in linear space, alpha averaged) at the level whose texel matches the sub-cell's
// footprint: the alpha test then sees the leaf's coverage over that footprint, and the lookups stay
// in cache.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>

#include "mesh_io.h"

namespace canopy::vox {

inline float srgbToLinear8(int v) {
  static const auto table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      const float c = float(i) / 255.f;
      t[size_t(i)] = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
    }
    return t;
  }();
  return table[size_t(v)];
}

// Texel index along one axis for glTF's wrap modes (REPEAT 10497, CLAMP 33071, MIRRORED 33648).
inline int wrapIndex(int i, int n, int mode) {
  if (i >= 0 && i < n) return i;
  if (mode == 33071) return i < 0 ? 0 : (i >= n ? n - 1 : i);
  if (mode == 33648) {
    const int period = 2 * n;
    int m = i % period;
    if (m < 0) m += period;
    return m < n ? m : period - 1 - m;
  }
  int m = i % n;
  return m < 0 ? m + n : m;
}

inline uint8_t linearToSrgb8(float c) {
  c = c < 0 ? 0 : (c > 1 ? 1 : c);
  const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
  return uint8_t(std::lround(s * 255.f));
}

// Level 0 is the texture itself; level k+1 averages 2x2 texels of level k (odd edges clamp).
struct MipChain {
  std::vector<mesh::Texture> levels;
};

inline MipChain buildMips(const mesh::Texture& base) {
  MipChain m;
  m.levels.push_back(base);
  while (m.levels.back().width > 1 || m.levels.back().height > 1) {
    const mesh::Texture& src = m.levels.back();
    mesh::Texture dst = src;
    dst.width = std::max(1, src.width / 2);
    dst.height = std::max(1, src.height / 2);
    dst.rgba.assign(size_t(dst.width) * size_t(dst.height) * 4, 0);
    for (int y = 0; y < dst.height; ++y)
      for (int x = 0; x < dst.width; ++x) {
        float acc[4] = {0, 0, 0, 0};
        for (int dy = 0; dy < 2; ++dy)
          for (int dx = 0; dx < 2; ++dx) {
            const int sx = std::min(src.width - 1, 2 * x + dx), sy = std::min(src.height - 1, 2 * y + dy);
            const uint8_t* p = &src.rgba[(size_t(sy) * size_t(src.width) + size_t(sx)) * 4];
            for (int c = 0; c < 3; ++c) acc[c] += srgbToLinear8(p[c]);
            acc[3] += p[3];
          }
        uint8_t* q = &dst.rgba[(size_t(y) * size_t(dst.width) + size_t(x)) * 4];
        for (int c = 0; c < 3; ++c) q[c] = linearToSrgb8(acc[c] / 4);
        q[3] = uint8_t(std::lround(acc[3] / 4));
      }
    m.levels.push_back(std::move(dst));
  }
  return m;
}

// The mip level for a triangle: texels per sub-cell edge = sqrt(texel area / fine-cell area) of
// the triangle (uvArea in uv units^2, fineArea in fine cells^2); level = floor(log2(that)).
inline int mipLevel(const MipChain& m, double uvArea, double fineArea) {
  const mesh::Texture& t = m.levels[0];
  if (!(fineArea > 0) || !(uvArea > 0)) return 0;
  const double r = std::sqrt(uvArea * double(t.width) * double(t.height) / fineArea);
  if (!(r > 1)) return 0;
  const int level = int(std::floor(std::log2(r)));
  return std::min(level, int(m.levels.size()) - 1);
}

// floor() for values already clamped to a small range, without a libm call.
inline int floorToInt(double x) {
  const int i = int(x);
  return x < double(i) ? i - 1 : i;
}

// Bilinear (or nearest) footprint of (u, v): four texel offsets into rgba and their weights.
struct Footprint {
  size_t at[4];
  float w[4];
};

inline Footprint footprint(const mesh::Texture& t, float u, float v) {
  if (!std::isfinite(u) || !std::isfinite(v)) u = v = 0;
  // Keep the coordinate in a sane range before converting to int (REPEAT/MIRROR are periodic).
  const double fu = (t.wrapS == 33071 || (u >= 0 && u <= 2)) ? u : double(u) - 2.0 * std::floor(double(u) / 2.0);
  const double fv = (t.wrapT == 33071 || (v >= 0 && v <= 2)) ? v : double(v) - 2.0 * std::floor(double(v) / 2.0);
  const double x = std::clamp(fu, -4.0, 4.0) * t.width - 0.5;
  const double y = std::clamp(fv, -4.0, 4.0) * t.height - 0.5;
  auto offset = [&](int xi, int yi) {
    return (size_t(wrapIndex(yi, t.height, t.wrapT)) * size_t(t.width) +
            size_t(wrapIndex(xi, t.width, t.wrapS))) * 4;
  };
  Footprint f;
  if (t.nearest) {
    const size_t o = offset(floorToInt(x + 0.5), floorToInt(y + 0.5));
    for (int i = 0; i < 4; ++i) { f.at[i] = o; f.w[i] = i == 0 ? 1.f : 0.f; }
    return f;
  }
  const int x0 = floorToInt(x), y0 = floorToInt(y);
  const float ax = float(x - x0), ay = float(y - y0);
  f.at[0] = offset(x0, y0);
  f.at[1] = offset(x0 + 1, y0);
  f.at[2] = offset(x0, y0 + 1);
  f.at[3] = offset(x0 + 1, y0 + 1);
  f.w[0] = (1 - ax) * (1 - ay);
  f.w[1] = ax * (1 - ay);
  f.w[2] = (1 - ax) * ay;
  f.w[3] = ax * ay;
  return f;
}

inline float sampleAlpha(const mesh::Texture& t, const Footprint& f) {
  float a = 0;
  for (int i = 0; i < 4; ++i) a += f.w[i] * float(t.rgba[f.at[i] + 3]);
  return a / 255.f;
}

inline void sampleColor(const mesh::Texture& t, const Footprint& f, float rgb[3]) {
  rgb[0] = rgb[1] = rgb[2] = 0;
  for (int i = 0; i < 4; ++i)
    for (int c = 0; c < 3; ++c) rgb[c] += f.w[i] * srgbToLinear8(t.rgba[f.at[i] + size_t(c)]);
}

// out = linear RGB + alpha at (u, v).
inline void sampleTexture(const mesh::Texture& t, float u, float v, float out[4]) {
  const Footprint f = footprint(t, u, v);
  sampleColor(t, f, out);
  out[3] = sampleAlpha(t, f);
}

}  // namespace canopy::vox
