// fixtures.h: small density lattices for the lbsolve tests, written with the one density lattice
// writer (formats/density_lattice.h, canopy-voxelize's).
#pragma once
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>

#include "formats/density_lattice.h"
#include "solver.h"

namespace fixtures {

// A deterministic pseudo-random number in [0, 1) from a node index and a seed.
inline float hashUnit(uint64_t i, uint64_t seed) {
  uint64_t x = i * 0x9E3779B97F4A7C15ull + seed * 0xBF58476D1CE4E5B9ull;
  x ^= x >> 31;
  x *= 0x94D049BB133111EBull;
  x ^= x >> 29;
  return float(x >> 40) / float(1ull << 24);
}

// A plant-like lattice: a wood trunk up the y axis and a leafy crown (ellipsoid of random density)
// in a cube of n nodes with an empty outer layer (voxelize guarantees that too).
struct Plant {
  int n;
  std::vector<float> density, wood;  // dense, index (z*n + y)*n + x
};

inline Plant makePlant(int n, uint64_t seed = 7) {
  Plant p{n, std::vector<float>(size_t(n) * n * n, 0.f), std::vector<float>(size_t(n) * n * n, 0.f)};
  const double c = (n - 1) / 2.0;
  for (int z = 1; z < n - 1; ++z)
    for (int y = 1; y < n - 1; ++y)
      for (int x = 1; x < n - 1; ++x) {
        const size_t i = (size_t(z) * n + y) * n + x;
        const double dx = (x - c) / (0.38 * n), dy = (y - 0.62 * n) / (0.3 * n), dz = (z - c) / (0.33 * n);
        const bool trunk = std::abs(x - c) < 0.06 * n + 0.5 && std::abs(z - c) < 0.06 * n + 0.5 && y < 0.7 * n;
        if (trunk) {
          p.density[i] = 0.9f;
          p.wood[i] = 1.0f;
        } else if (dx * dx + dy * dy + dz * dz < 1.0) {
          const float r = hashUnit(i, seed);
          p.density[i] = r < 0.45f ? 0.f : float(int((r - 0.45f) / 0.55f * 8 + 1)) / 8.f;  // 1/8..1
          p.wood[i] = hashUnit(i, seed + 1) < 0.1f ? 0.75f : 0.f;
        }
      }
  return p;
}

// A density lattice over [0, n-1]^3 (voxel size `voxel`) from dense arrays, as the writer takes it
// (formats/density_lattice.h): every node whose density is non-zero (or NaN) is a cell; albedo 0.5.
inline canopy::vdbio::DensityLatticeData latticeData(int nx, int ny, int nz, const std::vector<float>& density,
                                                     const std::vector<float>& wood, double voxel = 0.05) {
  canopy::vdbio::DensityLatticeData data;
  data.transform = openvdb::math::Transform::createLinearTransform(voxel);
  data.meta.min = openvdb::Coord(0);
  data.meta.max = openvdb::Coord(nx - 1, ny - 1, nz - 1);
  data.meta.source = "fixture";
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const size_t i = (size_t(z) * ny + y) * nx + x;
        if (density[i] != 0.f || std::isnan(density[i]))
          data.cells.push_back({{x, y, z}, density[i], wood[i], {0.5f, 0.5f, 0.5f}});
      }
  return data;
}

// Writes that lattice with the one writer; withWood = false drops the wood grid (a broken file).
inline void writeLattice(const std::string& path, int nx, int ny, int nz, const std::vector<float>& density,
                         const std::vector<float>& wood, double voxel = 0.05, bool withWood = true) {
  const canopy::vdbio::DensityLatticeData data = latticeData(nx, ny, nz, density, wood, voxel);
  if (withWood) return canopy::vdbio::writeDensityLattice(path, data);
  openvdb::GridPtrVec grids = canopy::vdbio::densityLatticeGrids(data);
  grids.erase(grids.begin() + 1);  // density, wood, albedo
  canopy::vdbio::writeVdb(path, grids);
}

inline void writePlant(const std::string& path, const Plant& p) {
  writeLattice(path, p.n, p.n, p.n, p.density, p.wood);
}

// The solver's view of a plant (every node stored), coding wood >= 0.5 as -rho.
inline canopy::lb::DenseLattice denseOf(int nx, int ny, int nz, const std::vector<float>& density,
                                        const std::vector<float>& wood) {
  canopy::lb::DenseLattice L;
  L.dims = {nx, ny, nz};
  L.coded.resize(density.size());
  for (size_t i = 0; i < density.size(); ++i)
    L.coded[i] = (density[i] > 0.f && wood[i] >= 0.5f) ? -density[i] : density[i];
  for (int64_t i = 0; i < L.dims.count(); ++i) L.stored.push_back(i);
  return L;
}

// A scratch directory under the build tree, emptied per test.
inline std::string scratch(const std::string& name) {
  const std::string dir = std::string(CANOPY_BINARY_DIR) + "/tests/lbsolve/scratch/" + name;
  std::string cmd = "rm -rf '" + dir + "' && mkdir -p '" + dir + "'";
  if (std::system(cmd.c_str()) != 0) std::abort();
  return dir;
}

inline bool exists(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (f) std::fclose(f);
  return f != nullptr;
}

}  // namespace fixtures
