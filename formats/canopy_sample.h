// canopy_sample.h: sampling a `.canopy` file's page images, per element: brick and sparse brick
// voxels, empty cells, light items, the octree descent, the Haar light. CANOPY_HD: the player's CUDA
// kernels and its CPU reference share them. The byte layout they read: canopy_layout.h.
#pragma once
#include <math.h>
#include <string.h>

#include <cstddef>
#include <cstdint>
#include <cstring>

#include "canopy/half.h"
#include "canopy/hd.h"
#include "canopy/rgb9e5.h"
#include "formats/canopy_layout.h"
#include "formats/haar_view.h"

namespace canopy {

// ------------------------------------------------------------------------------------------------
// Per-sample functions (CANOPY_HD: the player's CUDA kernels and its CPU reference share them).
// Coordinates: "octree unit space" u in [0,1)^3 covers the root; lattice index p (VDB index space,
// cell centres at integers) maps to u = (p - octreeOrigin + 0.5) / rootCells.
// ------------------------------------------------------------------------------------------------
struct CanopySample {
  float density;
  float wood;
  float albedo[3];
};

// *p, for data that no thread writes while a kernel runs (a page of the cache, the scene's tiles):
// on the GPU a non-coherent load (ld.global.nc), which the compiler may issue ahead of the kernel's
// stores (the pages' use stamps), as it may not for a plain load.
template <class T>
CANOPY_HD CANOPY_FORCEINLINE T canopyLoadRO(const T* p) {
#if defined(__CUDA_ARCH__)
  return __ldg(p);
#else
  return *p;
#endif
}

// The float with bits b (host and device alike: the same code runs in CPU tests and kernels).
CANOPY_HD CANOPY_FORCEINLINE float canopyFloatFromBits(uint32_t b) {
  float f;
  memcpy(&f, &b, sizeof f);
  return f;
}

// The low byte of v as a float in [0, 1]. The byte becomes a float through the mantissa of 2^23
// (exactly the value of float(v & 0xFF)): on the device the integer-to-float instruction runs on a
// slow pipe, and a trilinear brick sample converts 24 bytes (canopySampleBrick).
CANOPY_HD CANOPY_FORCEINLINE float canopyUnorm8(uint32_t v) {
  return (canopyFloatFromBits(0x4B000000u | (v & 0xFFu)) - 8388608.0f) * (1.0f / 255.0f);
}

CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyToUnorm8(float v) {
  v = v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v);
  return uint32_t(v * 255.0f + 0.5f);
}

CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyPackMaterial(float r, float g, float b, float wood) {
  return canopyToUnorm8(r) | canopyToUnorm8(g) << 8 | canopyToUnorm8(b) << 16 | canopyToUnorm8(wood) << 24;
}

// A constant node's (or one voxel's) value.
CANOPY_HD CANOPY_FORCEINLINE CanopySample canopyUnpack(float density, uint32_t material) {
  CanopySample s;
  s.density = density;
  s.albedo[0] = canopyUnorm8(material);
  s.albedo[1] = canopyUnorm8(material >> 8);
  s.albedo[2] = canopyUnorm8(material >> 16);
  s.wood = canopyUnorm8(material >> 24);
  return s;
}

// One brick's arrays inside a page payload (see canopyBrickInPage).
struct CanopyBrickView {
  const float* density;      // kCanopyBrickVoxelCount values
  const uint32_t* material;  // kCanopyBrickVoxelCount values
};

CANOPY_HD CANOPY_FORCEINLINE CanopyBrickView canopyBrickAt(const void* brickBytes) {
  CanopyBrickView v;
  v.density = static_cast<const float*>(brickBytes);
  v.material = reinterpret_cast<const uint32_t*>(static_cast<const unsigned char*>(brickBytes) +
                                                 kCanopyBrickVoxelCount * sizeof(float));
  return v;
}

// The brick `slot` (= brick id % bricksPerPage) of a page image (pageBytes long, header included).
CANOPY_HD CANOPY_FORCEINLINE CanopyBrickView canopyBrickInPage(const void* page, uint32_t slot) {
  return canopyBrickAt(static_cast<const unsigned char*>(page) + sizeof(CanopyPageHeader) +
                       size_t(slot) * kCanopyBrickBytes);
}

// Stored voxel (x,y,z) in [0,10)^3 (0 and 9 are the border).
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyVoxelIndex(uint32_t x, uint32_t y, uint32_t z) {
  return x + kCanopyBrickVoxels * (y + kCanopyBrickVoxels * z);
}

// Empty-cell masks: derived by the reader, not stored in the file. A brick's node is cut into
// kCanopyEmptyCells^3 cells; cell (jx, jy, jz) is the node-local box [j/n, (j+1)/n) on each axis
// (n = kCanopyEmptyCells, 8/n brick voxels wide), where a trilinear sample (canopySampleBrick)
// reads only stored voxels 8j/n .. 8(j+1)/n + 1 on each axis. Bit i = jx + n (jy + n jz) of the
// mask (word i / 64, bit i % 64) is set when all of those voxels have density 0, so the density is
// exactly 0 everywhere in the cell. A set bit is a proof; a clear one proves nothing (a page
// without masks reads as all clear).
constexpr uint32_t kCanopyEmptyCells = 8;  // 4: 1.08x slower forest orbit (docs/performance.md, 'Empty cells inside bricks')
constexpr uint32_t kCanopyEmptyWords = (kCanopyEmptyCells * kCanopyEmptyCells * kCanopyEmptyCells + 63) / 64;

inline void canopyBrickEmptyCells(CanopyBrickView b, uint64_t mask[kCanopyEmptyWords]) {
  constexpr uint32_t n = kCanopyEmptyCells, w = kCanopyBrickSize / n;
  for (uint32_t i = 0; i < kCanopyEmptyWords; ++i) mask[i] = 0;
  for (uint32_t jz = 0; jz < n; ++jz)
    for (uint32_t jy = 0; jy < n; ++jy)
      for (uint32_t jx = 0; jx < n; ++jx) {
        bool empty = true;
        for (uint32_t z = w * jz; empty && z < w * jz + w + 2; ++z)
          for (uint32_t y = w * jy; empty && y < w * jy + w + 2; ++y)
            for (uint32_t x = w * jx; empty && x < w * jx + w + 2; ++x) empty = b.density[canopyVoxelIndex(x, y, z)] == 0.0f;
        const uint32_t i = jx + n * (jy + n * jz);
        if (empty) mask[i / 64] |= 1ull << (i % 64);
      }
}

// Whether cell (x, y, z) of canopyBrickEmptyCells is empty, from a sparse brick's occupancy mask
// (n = 8: the cell's trilinear samples read stored voxels x..x+2, y..y+2, z..z+2).
static_assert(kCanopyEmptyCells == kCanopyBrickSize, "empty cells one voxel wide");
CANOPY_HD inline bool canopySparseCellEmpty(const uint32_t* occupancy, uint32_t x, uint32_t y, uint32_t z) {
  uint32_t any = 0;
  for (uint32_t dz = 0; dz < 3; ++dz)
    for (uint32_t dy = 0; dy < 3; ++dy)
      for (uint32_t dx = 0; dx < 3; ++dx) {
        const uint32_t v = canopyVoxelIndex(x + dx, y + dy, z + dz);
        any |= occupancy[v >> 5] >> (v & 31u);
      }
  return (any & 1u) == 0;
}

// Where a page image keeps its bricks' masks (kCanopyEmptyWords x 8 bytes per brick slot, after
// the last brick's payload, in the page's zero padding), or 0 when the padding cannot hold them.
inline uint32_t canopyBrickMaskOffset(uint32_t pageBytes, uint32_t bricksPerPage) {
  const uint64_t off = sizeof(CanopyPageHeader) + uint64_t(bricksPerPage) * kCanopyBrickBytes;
  return off + 8ull * kCanopyEmptyWords * bricksPerPage <= pageBytes ? uint32_t(off) : 0u;
}

// Fills a verified brick page image's masks (a reader does this after the checksum, so the image
// no longer matches the file's bytes there; nothing checks them again). Other kinds: unchanged.
inline void canopyFillBrickMasks(void* page, uint32_t pageBytes, uint32_t bricksPerPage) {
  CanopyPageHeader ph;
  std::memcpy(&ph, page, sizeof ph);
  const uint32_t off = canopyBrickMaskOffset(pageBytes, bricksPerPage);
  if (ph.kind != uint32_t(CanopyPageKind::Brick) || off == 0) return;
  unsigned char* masks = static_cast<unsigned char*>(page) + off;
  for (uint32_t i = 0; i < bricksPerPage; ++i) {
    uint64_t m[kCanopyEmptyWords] = {};
    if (i < ph.itemCount) canopyBrickEmptyCells(canopyBrickInPage(page, i), m);
    std::memcpy(masks + 8 * kCanopyEmptyWords * i, m, sizeof m);
  }
}

// Converts a verified light page image of a file before 4.0 (float16 planes: half [19][3][216] per
// item, 24624 B) in place to 4.0's items (uint32 [19][216] shared-exponent words, 16416 B) at 4.0's
// stride, so that the sampler knows one form. NaN and negative halves become 0 (canopy/rgb9e5.h).
inline void canopyConvertHalfLightPage(void* page) {
  CanopyPageHeader ph;
  std::memcpy(&ph, page, sizeof ph);
  unsigned char* payload = static_cast<unsigned char*>(page) + sizeof(CanopyPageHeader);
  uint16_t half[kCanopyLightItemBytesHalf / 2];
  for (uint32_t i = 0; i < ph.itemCount; ++i) {  // item i's new bytes end before item i + 1's old bytes begin
    std::memcpy(half, payload + size_t(i) * kCanopyLightItemBytesHalf, sizeof half);
    for (uint32_t b = 0; b < kCanopyLightBases; ++b)
      for (uint32_t v = 0; v < kCanopyLightVoxelCount; ++v) {
        const uint16_t* rgb = half + size_t(3 * b) * kCanopyLightVoxelCount + v;
        const uint32_t w = rgb9e5Encode(halfToFloat(rgb[0]), halfToFloat(rgb[kCanopyLightVoxelCount]), halfToFloat(rgb[2 * kCanopyLightVoxelCount]));
        std::memcpy(payload + size_t(i) * kCanopyLightItemBytes + 4 * (size_t(b) * kCanopyLightVoxelCount + v), &w, 4);
      }
  }
}

// What a loader does to a verified page image (CanopyFile::readPage) before a sampler reads it: a
// brick page gets its empty-cell masks (canopyFillBrickMasks), a light page of a file before 4.0
// its items in 4.0's form (canopyConvertHalfLightPage). Other pages are unchanged.
inline void canopyPreparePage(void* page, const CanopyFileHeader& h) {
  CanopyPageHeader ph;
  std::memcpy(&ph, page, sizeof ph);
  if (ph.kind == uint32_t(CanopyPageKind::Brick)) canopyFillBrickMasks(page, h.pageBytes, h.bricksPerPage);
  if (ph.kind == uint32_t(CanopyPageKind::Light) && h.lightItemBytes == kCanopyLightItemBytesHalf) canopyConvertHalfLightPage(page);
}

// ---- Sparse bricks (2.0: a detail model's detail levels; the item layout: canopy_layout.h) ------

// The stored voxels of an item: its mask's set bits, without the uniform flag.
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopySparseVoxelCount(const uint32_t* mask, const uint16_t* prefix) {
  return uint32_t(prefix[kCanopySparseMaskWords - 1]) + haar::popcount32(mask[kCanopySparseMaskWords - 1] & kCanopySparseLastVoxels);
}

struct CanopySparseBrickView {
  const uint32_t* mask;
  const uint16_t* prefix;
  const uint32_t* empty;  // the empty-cell bits (canopyBrickEmptyCells' cells, 32 per word)
  const float* density;
  const uint32_t* material;
  uint32_t densityRank;   // ~0u; 0 in a uniform item (3.0), whose voxels all hold density[0]
  // The stored voxel idx's values (0 and 0 where not stored). idx < 1000: the flag bit is never
  // tested nor counted.
  CANOPY_HD CANOPY_FORCEINLINE void load(uint32_t idx, float& d, uint32_t& m) const {
    const uint32_t w = mask[idx >> 5], bit = 1u << (idx & 31u);
    if (!(w & bit)) {
      d = 0.0f, m = 0u;
      return;
    }
    const uint32_t rank = uint32_t(prefix[idx >> 5]) + haar::popcount32(w & (bit - 1u));
    d = density[rank & densityRank], m = material[rank];
  }
};

// Item `item` of a sparse page image: the payload starts with uint32 offset[itemCount + 1].
CANOPY_HD CANOPY_FORCEINLINE CanopySparseBrickView canopySparseBrickInPage(const void* page, uint32_t item) {
  const unsigned char* payload = static_cast<const unsigned char*>(page) + sizeof(CanopyPageHeader);
  const unsigned char* p = payload + reinterpret_cast<const uint32_t*>(payload)[item];
  CanopySparseBrickView v;
  v.mask = reinterpret_cast<const uint32_t*>(p);
  v.prefix = reinterpret_cast<const uint16_t*>(p + kCanopySparseMaskWords * 4);
  v.empty = reinterpret_cast<const uint32_t*>(p + kCanopySparseMaskWords * 6);
  const uint32_t n = canopySparseVoxelCount(v.mask, v.prefix);
  const bool uniform = (v.mask[kCanopySparseMaskWords - 1] & kCanopySparseUniform) != 0;
  v.densityRank = uniform ? 0u : ~0u;
  v.density = reinterpret_cast<const float*>(p + kCanopySparseHeadBytes);
  v.material = reinterpret_cast<const uint32_t*>(p + kCanopySparseHeadBytes + 4u * (uniform ? 1u : n));
  return v;
}

// A dense brick's voxel loads, for canopySampleVoxels.
CANOPY_HD CANOPY_FORCEINLINE void canopyLoadVoxel(const CanopyBrickView& b, uint32_t idx, float& d, uint32_t& m) {
  d = canopyLoadRO(b.density + idx), m = canopyLoadRO(b.material + idx);
}
CANOPY_HD CANOPY_FORCEINLINE void canopyLoadVoxel(const CanopySparseBrickView& b, uint32_t idx, float& d, uint32_t& m) { b.load(idx, d, m); }

// Trilinear sample of a brick (either form) at node-local coordinates l in [0,1]^3 (0 = the node's
// lower corner). Density is interpolated; albedo and wood are density-weighted (the same weighting
// as the MIP), so empty voxels do not darken a leaf's colour. At the centre of an interior voxel the
// result is that voxel's stored value.
template <class Voxels>
CANOPY_HD inline CanopySample canopySampleVoxels(const Voxels& b, float lx, float ly, float lz) {
  const float l[3] = {lx, ly, lz};
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    // voxel centres at (i + 0.5) / 8 in node-local space map to stored index i + 1
    float t = l[a] * float(kCanopyBrickSize) + float(kCanopyBrickBorder) - 0.5f;
    const float hi = float(kCanopyBrickVoxels - 1) - 1e-6f;
    t = t < 0.0f ? 0.0f : (t > hi ? hi : t);
    const float fl = floorf(t);
    i0[a] = int(fl);
    f[a] = t - fl;
  }
  // The 16 loads first, unconditionally (every corner is inside the brick: i0 <= kCanopyBrickVoxels
  // - 2), so that the GPU has them all in flight at once; then every corner is summed without a
  // branch: one of weight 0 adds +0 to each sum (the sums that skipping it gave, for the finite,
  // non-negative densities a verified page holds).
  float cd[8];
  uint32_t cm[8];
  for (int c = 0; c < 8; ++c) {
    const uint32_t idx = canopyVoxelIndex(uint32_t(i0[0] + (c & 1)), uint32_t(i0[1] + ((c >> 1) & 1)), uint32_t(i0[2] + ((c >> 2) & 1)));
    canopyLoadVoxel(b, idx, cd[c], cm[c]);
  }
  float dens = 0.0f, w = 0.0f, r = 0.0f, g = 0.0f, bl = 0.0f, wsum = 0.0f;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const float wt = (dx ? f[0] : 1.0f - f[0]) * (dy ? f[1] : 1.0f - f[1]) * (dz ? f[2] : 1.0f - f[2]);
    const float d = cd[c];
    const CanopySample m = canopyUnpack(d, cm[c]);
    dens += wt * d;
    const float wd = wt * d;
    wsum += wd;
    w += wd * m.wood;
    r += wd * m.albedo[0];
    g += wd * m.albedo[1];
    bl += wd * m.albedo[2];
  }
  CanopySample s;
  s.density = dens;
  const float inv = wsum > 0.0f ? 1.0f / wsum : 0.0f;
  s.wood = w * inv;
  s.albedo[0] = r * inv;
  s.albedo[1] = g * inv;
  s.albedo[2] = bl * inv;
  return s;
}
CANOPY_HD inline CanopySample canopySampleBrick(CanopyBrickView b, float lx, float ly, float lz) { return canopySampleVoxels(b, lx, ly, lz); }
CANOPY_HD inline CanopySample canopySampleBrick(const CanopySparseBrickView& b, float lx, float ly, float lz) {
  return canopySampleVoxels(b, lx, ly, lz);
}
// A brick of either form in a page image: slot (dense) or item (sparse).
CANOPY_HD inline CanopySample canopySampleBrickInPage(const void* page, uint32_t slot, bool sparse, float lx, float ly, float lz) {
  return sparse ? canopySampleBrick(canopySparseBrickInPage(page, slot), lx, ly, lz) : canopySampleBrick(canopyBrickInPage(page, slot), lx, ly, lz);
}

// The light item `slot` (= item id % lightItemsPerPage) of a light page image: uint32 [19][216]
// shared-exponent words (a page of a file before 4.0 after canopyPreparePage).
CANOPY_HD CANOPY_FORCEINLINE const uint32_t* canopyLightInPage(const void* page, uint32_t slot) {
  return reinterpret_cast<const uint32_t*>(static_cast<const unsigned char*>(page) + sizeof(CanopyPageHeader) +
                                           size_t(slot) * kCanopyLightItemBytes);
}

// The trilinear corners of node-local l in [0,1]^3 in a light item: voxel indices and weights,
// computed once for all the bases sampled at one point (the player samples four).
struct CanopyLightCorners {
  uint32_t offset[8];  // voxel index of corner c (x + 6 (y + 6 z)), c = dx + 2 dy + 4 dz
  float weight[8];     // its trilinear weight (0: the corner adds +0)
};

CANOPY_HD inline CanopyLightCorners canopyLightCorners(float lx, float ly, float lz) {
  const float l[3] = {lx, ly, lz};
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    float t = l[a] * float(kCanopyLightSize) + 0.5f;  // light voxel centres (i + 0.5) / 4 -> index i + 1
    const float hi = float(kCanopyLightVoxels - 1) - 1e-6f;
    t = t < 0.0f ? 0.0f : (t > hi ? hi : t);
    const float fl = floorf(t);
    i0[a] = int(fl);
    f[a] = t - fl;
  }
  CanopyLightCorners k;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    k.weight[c] = (dx ? f[0] : 1.0f - f[0]) * (dy ? f[1] : 1.0f - f[1]) * (dz ? f[2] : 1.0f - f[2]);
    k.offset[c] = uint32_t((i0[0] + dx) + int(kCanopyLightVoxels) * ((i0[1] + dy) + int(kCanopyLightVoxels) * (i0[2] + dz)));
  }
  return k;
}

// Base `base` (0..18) of a light item at the corners k, RGB into rgb. The eight words are loaded
// before any is used, so that the GPU has them in flight at once. Every corner is summed, without a
// branch: one of weight 0 adds +0 (a decoded word is finite and >= 0), the sum that skipping it gave.
CANOPY_HD CANOPY_FORCEINLINE void canopySampleLightAt(const uint32_t* item, uint32_t base, const CanopyLightCorners& k,
                                                      float rgb[3]) {
  const uint32_t* plane = item + size_t(base) * kCanopyLightVoxelCount;
  uint32_t w[8];
  for (int c = 0; c < 8; ++c) w[c] = canopyLoadRO(plane + k.offset[c]);
  rgb[0] = rgb[1] = rgb[2] = 0.0f;
  for (int c = 0; c < 8; ++c) {
    float v[3];
    rgb9e5Decode(w[c], v);
    rgb[0] += k.weight[c] * v[0];
    rgb[1] += k.weight[c] * v[1];
    rgb[2] += k.weight[c] * v[2];
  }
}

// Trilinear sample of base `base` (0..18) of a light item at node-local l in [0,1]^3, RGB into rgb.
CANOPY_HD inline void canopySampleLight(const uint32_t* item, uint32_t base, float lx, float ly, float lz, float rgb[3]) {
  canopySampleLightAt(item, base, canopyLightCorners(lx, ly, lz), rgb);
}

// One step down the octree: x (the point in the current node, [0,1)^3) becomes the point in the
// child that holds it, lo and size (the node's corner and edge in octree unit space) become the
// child's. Returns the child index c = x + 2y + 4z. Shared by canopyDescend and the player.
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyStepDown(float x[3], float lo[3], float& size) {
  uint32_t c = 0;
  size *= 0.5f;
  for (int a = 0; a < 3; ++a) {
    const float t = x[a] * 2.0f;
    const uint32_t off = t >= 1.0f ? 1u : 0u;
    x[a] = t - float(off);
    c |= off << a;
    lo[a] += float(off) * size;
  }
  return c;
}

// The result of descending the octree to a point.
struct CanopyLookup {
  CanopyNode node;       // the node reached
  CanopyNode parent;     // its parent (== node at the root), for quadrilinear LOD blending
  uint32_t level;        // level of `node`
  float local[3];        // the point in node-local coordinates [0,1)^3
  float nodeMin[3];      // node's lower corner in octree unit space
  float nodeSize;        // node's edge in octree unit space (2^-level)
};

// Descends from the root towards unit-space point u (clamped into [0,1)) until `maxLevel`, the
// finest level, or a terminal node (constant, or a brick without children). `tiles` are the
// model's node tiles (model-relative child indices); `tileCount` bounds them: a child index out of
// range stops the descent (a verified file never has one).
CANOPY_HD inline CanopyLookup canopyDescend(const CanopyNode* tiles, uint32_t tileCount, CanopyNode root,
                                            uint32_t depth, float ux, float uy, float uz,
                                            uint32_t maxLevel) {
  float x[3] = {ux, uy, uz};
  for (int a = 0; a < 3; ++a) x[a] = x[a] < 0.0f ? 0.0f : (x[a] >= 1.0f ? 0.99999994f : x[a]);
  CanopyLookup r;
  r.node = root;
  r.parent = root;
  r.level = 0;
  r.nodeSize = 1.0f;
  r.nodeMin[0] = r.nodeMin[1] = r.nodeMin[2] = 0.0f;
  if (maxLevel > depth) maxLevel = depth;
  while (r.level < maxLevel && r.node.child != kCanopyNone && r.node.child < tileCount) {
    const uint32_t c = canopyStepDown(x, r.nodeMin, r.nodeSize);
    r.parent = r.node;
    r.node = tiles[size_t(r.node.child) * 8 + c];
    ++r.level;
  }
  for (int a = 0; a < 3; ++a) r.local[a] = x[a];
  return r;
}

// Lattice index space -> octree unit space for one model (see the comment above).
CANOPY_HD CANOPY_FORCEINLINE void canopyLatticeToUnit(const int32_t origin[3], uint32_t rootCells,
                                                      float px, float py, float pz, float u[3]) {
  const float inv = 1.0f / float(rootCells);
  u[0] = (px - float(origin[0]) + 0.5f) * inv;
  u[1] = (py - float(origin[1]) + 0.5f) * inv;
  u[2] = (pz - float(origin[2]) + 0.5f) * inv;
}

// p' = M p for a 3x4 row-major affine matrix (instances: model -> world; canopyModelToUnit).
CANOPY_HD CANOPY_FORCEINLINE void canopyTransformPoint(const float m[12], const float p[3], float out[3]) {
  for (int r = 0; r < 3; ++r) out[r] = m[4 * r] * p[0] + m[4 * r + 1] * p[1] + m[4 * r + 2] * p[2] + m[4 * r + 3];
}
// d' = M d (directions: no translation).
CANOPY_HD CANOPY_FORCEINLINE void canopyTransformDirection(const float m[12], const float d[3], float out[3]) {
  for (int r = 0; r < 3; ++r) out[r] = m[4 * r] * d[0] + m[4 * r + 1] * d[1] + m[4 * r + 2] * d[2];
}
// What a sampler needs of one Haar-lit model (resident): its HaarIndex entries and geometry.
struct CanopyHaarView {
  const uint32_t* index;  // the model's HaarIndex entries: group table, then 64 locations per group
  int32_t latticeMin[3];
  int32_t latticeMax[3];
  uint32_t groupDims[3];
  uint32_t firstPage;     // page index of the model's first Haar page
  uint32_t fp16;          // coefficients are float16 (else float32)
};

struct CanopyHaarLocation {
  uint32_t page;         // page holding the chaar brick, or kCanopyNone: no light there (every base 0)
  uint32_t item;         // item index in that page
  haar::BrickLookup at;  // the brick-local texel footprint and fractions (at.slot unused)
};

// Finds the chaar brick of lattice index point p (the rule of haar::chaarSample: p clamped to the
// lattice, brick floor(p - latticeMin) / 3) through the model's HaarIndex.
CANOPY_HD inline CanopyHaarLocation canopyHaarLocate(const CanopyHaarView& v, float px, float py, float pz) {
  int b[3];
  CanopyHaarLocation r;
  r.at = haar::locateInLattice(v.latticeMin, v.latticeMax, px, py, pz, b);
  r.page = kCanopyNone;
  r.item = 0;
  const uint32_t E = kCanopyHaarGroupEdge;
  const uint32_t g = (uint32_t(b[2]) / E * v.groupDims[1] + uint32_t(b[1]) / E) * v.groupDims[0] + uint32_t(b[0]) / E;
  const uint32_t block = v.index[g];
  if (block == kCanopyNone) return r;
  const uint32_t groups = v.groupDims[0] * v.groupDims[1] * v.groupDims[2];
  const uint32_t local = uint32_t(b[0]) % E + E * (uint32_t(b[1]) % E + E * (uint32_t(b[2]) % E));
  const uint32_t loc = v.index[groups + kCanopyHaarGroupBricks * block + local];
  if (loc == kCanopyNone) return r;
  r.page = v.firstPage + (loc >> kCanopyHaarItemBits);
  r.item = loc & (kCanopyHaarMaxItemsPerPage - 1u);
  return r;
}

// Item `item` of a Haar page image (pageBytes long, header included): its 19 records, then its
// coefficients.
CANOPY_HD CANOPY_FORCEINLINE const unsigned char* canopyHaarItemInPage(const void* page, uint32_t item) {
  const unsigned char* payload = static_cast<const unsigned char*>(page) + sizeof(CanopyPageHeader);
  return payload + reinterpret_cast<const uint32_t*>(payload)[item];
}

// A Haar item's coefficient entries in either precision (one instantiation of the sampler serves
// both: the branch is uniform per model).
struct CanopyHaarCoefReader {
  const unsigned char* p;
  uint32_t fp16;
  CANOPY_HD CANOPY_FORCEINLINE haar::Rgb operator()(uint64_t i) const {
    if (fp16) return haar::CoefReader16{reinterpret_cast<const uint16_t*>(p)}(i);
    return haar::CoefReader32{reinterpret_cast<const float*>(p)}(i);
  }
};

// Trilinear sample of base `base` of one Haar item at the footprint `at`: haar::sampleBrick on the
// item's record and coefficients, so it equals haar::chaarSample of the source .chaar bit for bit.
CANOPY_HD inline haar::Rgb canopyHaarSampleAt(const unsigned char* item, uint32_t fp16, uint32_t base, const haar::BrickLookup& at) {
  const haar::BrickRecord rec = reinterpret_cast<const haar::BrickRecord*>(item)[base];
  return haar::sampleBrick(rec, CanopyHaarCoefReader{item + kCanopyHaarRecordBytes, fp16}, at.lx, at.ly, at.lz, at.fx, at.fy, at.fz);
}

}  // namespace canopy
