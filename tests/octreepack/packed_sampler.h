// packed_sampler.h: CPU sampling of a packed .canopy model through the format's CANOPY_HD functions
// (canopyDescend + canopySampleBrick, canopyHaarSampleAt), with a page cache: what a player's CPU reference does.
#pragma once
#include <map>
#include <vector>

#include "formats/canopy_file.h"

namespace canopy::octreepack::testing {

class PackedSampler {
 public:
  explicit PackedSampler(const CanopyFile& f) : f_(f) {}

  // Sample at octree unit-space point u, stopping at maxLevel (or where the tree ends).
  CanopySample sampleUnit(uint32_t model, const float u[3], uint32_t maxLevel, uint32_t* levelReached = nullptr) {
    const CanopyLookup r = f_.descend(model, u[0], u[1], u[2], maxLevel);
    if (levelReached) *levelReached = r.level;
    if (r.node.brick == kCanopyNone) return canopyUnpack(r.node.density, r.node.material);
    const CanopyFile::BrickLocation at = f_.brickLocation(model, r.node.brick);  // dense or (2.0) sparse
    const std::vector<unsigned char>& page = pageData(at.page);
    return canopySampleBrickInPage(page.data(), at.slot, at.sparse, r.local[0], r.local[1], r.local[2]);
  }
  // Sample at a lattice index point (cell centres at integers) at the finest level.
  CanopySample sampleLattice(uint32_t model, float px, float py, float pz) {
    const CanopyModel& M = f_.model(model);
    float u[3];
    canopyLatticeToUnit(M.octreeOrigin, M.rootCells, px, py, pz, u);
    return sampleUnit(model, u, M.depth);
  }
  // The stored value of voxel g (global voxel index at `level`), or what the tree says there.
  CanopySample voxel(uint32_t model, uint32_t level, const int64_t g[3]) {
    const float n = float(kCanopyBrickSize << level);
    const float u[3] = {(float(g[0]) + 0.5f) / n, (float(g[1]) + 0.5f) / n, (float(g[2]) + 0.5f) / n};
    return sampleUnit(model, u, level);
  }
  // The finest level's Haar light of a Haar-lit model at lattice index point p, base `base`: the
  // format's canopyHaarLocate + canopyHaarSampleAt (what the player does), pages read on demand.
  haar::Rgb sampleHaar(uint32_t model, uint32_t base, float px, float py, float pz) {
    const CanopyHaarView v = f_.haarView(model);
    const CanopyHaarLocation at = canopyHaarLocate(v, px, py, pz);
    if (at.page == kCanopyNone) return haar::Rgb{};
    return canopyHaarSampleAt(canopyHaarItemInPage(pageData(at.page).data(), at.item), v.fp16, base, at.at);
  }
  const std::vector<unsigned char>& pageData(uint32_t index) {
    auto it = pages_.find(index);
    if (it == pages_.end()) it = pages_.emplace(index, f_.readPage(index)).first;
    return it->second;
  }

 private:
  const CanopyFile& f_;
  std::map<uint32_t, std::vector<unsigned char>> pages_;
};

}  // namespace canopy::octreepack::testing
