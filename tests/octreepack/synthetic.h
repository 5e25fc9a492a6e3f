// synthetic.h: deterministic test plants for the octreepack tests (no OpenVDB).
//   syntheticPlant(): a leafy shell (varying density, albedo), a wooden trunk and a solid uniform
//   core (to exercise constant nodes), inside a lattice of `edge` cells whose minimum is `origin`.
#pragma once
#include <cmath>
#include <cstdint>

#include "tools/octreepack/octree_build.h"

namespace canopy::octreepack::testing {

inline uint32_t mix32(uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352dU;
  x ^= x >> 15;
  x *= 0x846ca68bU;
  x ^= x >> 16;
  return x;
}
inline float unit(uint32_t h) { return float(h & 0xFFFFFF) / float(0x1000000); }

inline ModelSource syntheticPlant(int edge, int32_t origin, const char* name = "synthetic", int coreHalf = 8) {
  ModelSource s;
  s.name = name;
  s.sourceLabel = std::string("synthetic:") + name;
  for (int a = 0; a < 3; ++a) {
    s.latticeMin[a] = origin;
    s.latticeMax[a] = origin + edge - 1;
  }
  s.indexToModel = {0.05, 0, 0, 0.1, 0, 0.05, 0, -0.2, 0, 0, 0.05, 0.3};
  const float c = 0.5f * float(edge - 1);
  const float R = 0.42f * float(edge);
  for (int k = 1; k < edge - 1; ++k)
    for (int j = 1; j < edge - 1; ++j)
      for (int i = 1; i < edge - 1; ++i) {
        const float x = float(i) - c, y = float(j) - c, z = float(k) - c;
        const float r = std::sqrt(x * x + y * y + z * z);
        const uint32_t h = mix32(uint32_t(i) * 73856093U ^ uint32_t(j) * 19349663U ^ uint32_t(k) * 83492791U);
        SourceCell cell{{origin + i, origin + j, origin + k}, 0, 0, {0, 0, 0}};
        const bool core = std::abs(x) < float(coreHalf) && std::abs(y) < float(coreHalf) && std::abs(z) < float(coreHalf);
        const bool trunk = std::abs(x) < 1.6f && std::abs(z) < 1.6f && y < 0;
        if (core) {  // uniform: constant nodes at the finest levels
          cell.density = 0.75f;
          cell.wood = 1.0f;
          cell.albedo[0] = 0.4f, cell.albedo[1] = 0.25f, cell.albedo[2] = 0.1f;
        } else if (trunk) {
          cell.density = 0.9f;
          cell.wood = 1.0f;
          cell.albedo[0] = 0.35f, cell.albedo[1] = 0.22f, cell.albedo[2] = 0.12f;
        } else if (r > R - 3 && r < R && (h & 3) != 0) {  // leafy shell with holes
          cell.density = 0.05f + 0.9f * unit(h >> 2);
          cell.wood = (h >> 30) == 0 ? 0.5f : 0.0f;
          cell.albedo[0] = 0.1f + 0.2f * unit(h * 3u);
          cell.albedo[1] = 0.3f + 0.5f * unit(h * 5u);
          cell.albedo[2] = 0.05f + 0.1f * unit(h * 7u);
        } else {
          continue;
        }
        s.cells.push_back(cell);
      }
  return s;
}

// An analytic lighting field: smooth in space, distinct per base and channel.
inline void analyticLight(int32_t i, int32_t j, int32_t k, float* out) {
  for (uint32_t b = 0; b < kCanopyLightBases; ++b)
    for (int c = 0; c < 3; ++c)
      out[3 * b + c] = 0.1f * float(b + 1) + 0.03f * float(c) + 0.01f * float(i) - 0.004f * float(j) + 0.002f * float(k * k % 17);
}

}  // namespace canopy::octreepack::testing
