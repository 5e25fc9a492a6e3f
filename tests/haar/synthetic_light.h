// synthetic_light.h: deterministic light fields for the Haar tests and benchmark (no OpenVDB).
//   smoothLight: what an LB solve looks like: light decaying into a leafy ball along the base's
//                direction, smooth inside, exactly zero outside the ball (empty bricks);
//   randomLight: white noise in [0, scale) on a random half of the cells (worst case for Haar).
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "formats/haar_encode.h"

namespace canopy::haar::testing {

// The 19 lattice directions in lbsolve's order: rest, 6 axial, 12 diagonal.
inline std::array<int32_t, 3> latticeDirection(uint32_t b) {
  static const int32_t c[19][3] = {{0, 0, 0},  {1, 0, 0},  {-1, 0, 0}, {0, 1, 0},  {0, -1, 0},
                                   {0, 0, 1},  {0, 0, -1}, {1, 1, 0},  {-1, -1, 0}, {1, -1, 0},
                                   {-1, 1, 0}, {1, 0, 1},  {-1, 0, -1}, {1, 0, -1}, {-1, 0, 1},
                                   {0, 1, 1},  {0, -1, -1}, {0, 1, -1}, {0, -1, 1}};
  return {c[b % 19][0], c[b % 19][1], c[b % 19][2]};
}

inline LatticeGeom makeGeom(int nx, int ny, int nz, int ox = 0, int oy = 0, int oz = 0) {
  const int32_t mn[3] = {ox, oy, oz}, mx[3] = {ox + nx - 1, oy + ny - 1, oz + nz - 1};
  return LatticeGeom::fromBounds(mn, mx, "synthetic");
}

inline DenseLight smoothLight(const LatticeGeom& g, uint32_t base, float scale = 1.0f) {
  DenseLight d;
  d.rgb.assign(3 * g.cells, 0.0f);
  const auto c = latticeDirection(base);
  double n[3] = {double(c[0]), double(c[1]), double(c[2])};
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  for (double& v : n) v = len > 0 ? v / len : 0;
  const double cx = 0.5 * (g.dims[0] - 1), cy = 0.47 * (g.dims[1] - 1), cz = 0.53 * (g.dims[2] - 1);
  const double R = 0.42 * double(std::min(g.dims[0], std::min(g.dims[1], g.dims[2])));
  const float tint[3] = {0.9f, 1.0f, 0.75f};
  for (int64_t z = 0; z < g.dims[2]; ++z)
    for (int64_t y = 0; y < g.dims[1]; ++y)
      for (int64_t x = 0; x < g.dims[0]; ++x) {
        const double px = x - cx, py = y - cy, pz = z - cz;
        const double r = std::sqrt(px * px + py * py + pz * pz);
        if (r > R) continue;
        // Depth of the point along the light's travel direction, from the ball's entry side.
        const double depth = (px * n[0] + py * n[1] + pz * n[2]) + R;
        const double ambient = len > 0 ? 0.15 : 0.6;
        const double v = ambient + 0.85 * std::exp(-depth / (0.6 * R)) + 0.05 * std::sin(0.4 * x + 0.3 * y - 0.2 * z);
        const size_t o = size_t(3 * ((z * g.dims[1] + y) * g.dims[0] + x));
        for (int ch = 0; ch < 3; ++ch) d.rgb[o + size_t(ch)] = float(scale * v * tint[ch]);
        ++d.activeVoxels;
      }
  return d;
}

inline DenseLight randomLight(const LatticeGeom& g, uint32_t seed, float scale = 1.0f) {
  DenseLight d;
  d.rgb.assign(3 * g.cells, 0.0f);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (uint64_t i = 0; i < g.cells; ++i) {
    if (u(rng) < 0.5f) continue;
    for (int ch = 0; ch < 3; ++ch) d.rgb[3 * i + size_t(ch)] = scale * u(rng);
    ++d.activeVoxels;
  }
  return d;
}

// Encodes bases with the library encoder: threshold T, or (E >= 0) the max-error search.
inline ChaarData encodeLights(const LatticeGeom& g, const std::vector<DenseLight>& lights, float T,
                              float E = -1.0f, Precision p = Precision::Fp32) {
  ChaarAssembly a;
  a.geom = g;
  a.precision = p;
  a.threshold = E >= 0 ? -1.0f : T;
  a.maxErrorTarget = E >= 0 ? E : -1.0f;
  a.indexToModel[0] = a.indexToModel[5] = a.indexToModel[10] = 0.01;  // 1 cm lattice spacing
  a.indexToModel[12] = -0.5;
  for (uint32_t b = 0; b < lights.size(); ++b) {
    LiftedBase lb(g, lights[b], p, "synthetic B" + std::to_string(b));
    // (Quant with T = 0: each base's finest step.)
    const float t = p == Precision::Quant && T == 0.0f ? lb.minQuantStep() : T;
    a.codes.push_back(lb.encode(E >= 0 ? lb.searchThreshold(E) : t));
    a.directions.push_back(latticeDirection(b));
    a.valueMax.push_back(lb.valueMax());
  }
  return assembleChaar(a);
}

}  // namespace canopy::haar::testing
