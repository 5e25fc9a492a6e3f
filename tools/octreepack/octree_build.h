// octree_build.h: one model's sparse lattice -> its .canopy octree (node tiles + bricks).
//
// No OpenVDB here (inputs.cpp converts a density VDB into a ModelSource), so tests and the
// benchmark can build octrees from synthetic cells. The result is deterministic: the same cells in
// any order give the same bytes.
//
// Levels (formats/canopy_layout.h): level `depth` has one voxel per lattice cell; level d-1 is the
// 2x2x2 box filter of level d: density = mean of the 8 stored densities (summed in double in child
// order c = x + 2y + 4z, then rounded to float), albedo and wood = density-weighted means of the 8
// stored (already quantised) values, then quantised to unorm8. A node is constant when its whole
// subtree is one value (at the finest level: all 512 voxels equal; above: all 8 children constant
// and equal); an absent block is empty. Node tiles and brick ids are assigned breadth-first, coarse
// to fine, children in order c.
#pragma once
#include <array>
#include <functional>
#include <cstdint>
#include <string>
#include <vector>

#include "formats/canopy_file.h"
#include "formats/haar_view.h"

namespace canopy::octreepack {

// One occupied lattice cell of the source (density > 0).
struct SourceCell {
  int32_t ijk[3];
  float density;
  float wood;
  float albedo[3];
};

struct ModelSource {
  std::string name;
  std::string sourceLabel;                      // "<path> xxh64:<hash>" for the metadata
  int32_t latticeMin[3] = {0, 0, 0};            // inclusive
  int32_t latticeMax[3] = {0, 0, 0};
  std::array<double, 12> indexToModel{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  std::vector<SourceCell> cells;                // occupied cells, any order, inside the lattice
  // > 0: a detail lattice (canopy-voxelize --detail) 2^detailLevels times finer than the light
  // lattice [latticeMin >> n, latticeMax >> n], whose bounds must be whole light cells. The light
  // (LightFn) is then called at light lattice cells, and only the bricks of levels up to
  // depth - detailLevels get light items (CanopyModel.detailLevels, format 2.0).
  uint32_t detailLevels = 0;
};

// A model's lighting at one light lattice cell (cell centre): 19 bases x RGB, out[3 * base + channel].
// Called concurrently from several threads.
using LightFn = std::function<void(int32_t i, int32_t j, int32_t k, float* out)>;

// The lighting of a .chaar (19 bases) as a LightFn: the chaar decoder's value at each lattice cell,
// 0 outside the lattice. `view` points into its ChaarData, which must outlive the function.
LightFn chaarLightFn(const haar::ChaarView& view);

struct BuiltModel {
  CanopyModel record{};                         // firstTile/firstBrickPage etc. set by the writer
  std::vector<CanopyNode> tiles;                // 8 per tile, model-relative child indices
  std::vector<unsigned char> bricks;            // brickCount * kCanopyBrickBytes
  std::vector<uint32_t> light;                  // empty, or brickCount light items (canopy_layout.h)
  std::string sourceLabel;
  uint64_t occupiedCells = 0;
};

// Validates the source (finite values, density >= 0, cells inside the lattice, no duplicates,
// lattice not absurd) and builds its octree; with `light`, also one light item per brick (light
// levels = Haar averages of the lighting, layout in canopy_layout.h). Throws
// canopy::Error(InvalidInput) naming `what` (also for non-finite lighting).
BuiltModel buildOctree(const ModelSource& src, const std::string& what, const LightFn& light = nullptr);

// Helpers shared with the tests: the finest level that covers `maxDim` cells per axis.
uint32_t depthForCells(int64_t maxDim);

}  // namespace canopy::octreepack
