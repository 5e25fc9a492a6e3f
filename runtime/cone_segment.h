// cone_segment.h: one instance's segment at a ray position: the footprint's level, the octree
// descent and its cache, held empty segments, runs of empty cells, the segment's light. Part of
// runtime/cone.h.
#pragma once
#include "runtime/cone_light.h"
#include "runtime/grid_dda.h"

namespace canopy::play {

// ------------------------------------------------------------------------------------------------
// One instance's segment at ray position t
// ------------------------------------------------------------------------------------------------
struct Segment {
  float k;          // extinction per world unit
  float albedo[3];
  float tEnd;       // the value holds on [t, tEnd)
  // shading segments with matter only: where the indirect light is sampled
  const uint32_t* lightItem;  // the light item (nullptr: density-only indirect term)
  float light[3];             // the sample's node-local coordinates in the light item's node (Haar: fx, fy, fz)
  float tSample;              // the sample's world ray parameter (scene factor)
  // Haar light (kHaarNone: not used): the item (nullptr: no light stored there) and the packed
  // footprint lx | ly << 2 | lz << 4 | fp16 << 6; light[] then holds the fractions.
  const unsigned char* haarItem;
  uint32_t haarLocal;
};
constexpr uint32_t kHaarNone = 0xFFFFFFFFu;

// The coarsest level whose voxel (2^(depth - L) lattice cells) is no wider than the footprint (the
// finest where even its voxel is wider), shifted by lodBias (docs/play.md, "Level of detail").
CANOPY_HD inline uint32_t levelForFootprint(uint32_t depth, float footprintCells, float lodBias) {
  const float fp = footprintCells > 1.0f ? footprintCells : 1.0f;
  float L = float(depth) - floorf(log2f(fp)) + lodBias;
  L = L < 0.0f ? 0.0f : (L > float(depth) ? float(depth) : L);
  return uint32_t(L);
}

// World t at which o + t d (unit space) leaves the node box [lo, lo + size).
CANOPY_HD inline float nodeExit(V3 uo, V3 ud, const float lo[3], float size) {
  float t = 3.0e38f;
  for (int a = 0; a < 3; ++a) {
    const float da = comp(ud, a);
    if (fabsf(da) < 1e-30f) continue;
    const float bound = da > 0.0f ? lo[a] + size : lo[a];
    const float ta = (bound - comp(uo, a)) / da;
    t = ta < t ? ta : t;
  }
  return t;
}

// Descends instance `inst` at unit point u to `maxLevel`, noting the deepest resident brick on the
// way (within kFallbackLevels of maxLevel). Returns the node reached.
//
// Compact (56 bytes): a ray keeps one per pending instance in local memory (DescentCache), where
// the GPU's L1 holds a warp's words of it beside the bricks and nodes it samples; a box on the
// descent path is stored as its level alone (levelBox: the box of that level that holds the node,
// exact since boxes are dyadic). Against the 120 bytes of pointers, boxes and sizes before it, it
// is the same descent, field for field.
constexpr uint8_t kNoLevel = 0xFF;
struct alignas(16) Descent {
  float lo[3];                 // its box: [lo, lo + levelSize(level))   (descentCovers reads these 16 bytes at once)
  uint8_t level;               // its level
  uint8_t maxLevel;            // the level asked for (kNoLevel: an empty DescentCache)
  uint8_t brickLevel;          // the brick to sample: the node's own if resident, else a resident ancestor's (level)
  uint8_t lightLevel;          // LB light (wantLight only): the deepest brick on the path whose light page is resident
  CanopyNode node;             // the node reached
  int32_t brickPoolSlot;       // its page's pool slot; -1: no brick resident
  uint32_t missingPage;        // the node's own page when it was missing, else kCanopyNone
  int32_t lightPoolSlot;       // -1: no light page resident on the path
  uint32_t missingLightPage;   // the deepest brick's light page when it was missing, else kCanopyNone
  uint32_t coarsestLightPage;  // the shallowest brick's light page (asked for on a cold start)
  uint16_t brickSlotInPage;    // the brick's slot in its page (< bricksPerPage)
  uint16_t lightSlotInPage;    // the light item's slot in its page (< lightItemsPerPage)
};
// The reader admits pages of at most 64 MiB (canopy_file.cpp), so slots in a page fit 16 bits.
static_assert(offsetof(Descent, level) == 12 && offsetof(Descent, maxLevel) == 13, "descentCovers' layout");
static_assert((1u << 26) / kCanopyBrickBytes <= 0xFFFFu && (1u << 26) / kCanopyLightItemBytes <= 0xFFFFu,
              "Descent's slots in a page are 16 bits");

// 2^e for |e| < 127, exact, from its exponent bits.
CANOPY_HD CANOPY_FORCEINLINE float pow2i(int e) { return canopyFloatFromBits(uint32_t(127 + e) << 23); }

// The edge of a node of `level` (unit space): 2^-level, as the descent's halvings make it.
CANOPY_HD CANOPY_FORCEINLINE float levelSize(uint32_t level) { return pow2i(-int(level)); }

// The box of `level` (<= d.level) on d's descent path: [lo, lo + size). Every box is dyadic, so
// this is exact: the same bits as the descent's own lo at that level.
CANOPY_HD CANOPY_FORCEINLINE float levelBox(const Descent& d, uint32_t level, float lo[3]) {
  const float size = levelSize(level), scale = pow2i(int(level));
  for (int a = 0; a < 3; ++a) lo[a] = floorf(d.lo[a] * scale) * size;
  return size;
}

// The brick page of d (nullptr: no brick resident), and its light item (nullptr: none resident).
CANOPY_HD CANOPY_FORCEINLINE const unsigned char* descentBrickPage(const SceneView& s, const Descent& d) {
  return d.brickPoolSlot >= 0 ? s.pool + size_t(d.brickPoolSlot) * s.pageBytes : nullptr;
}
CANOPY_HD CANOPY_FORCEINLINE const uint32_t* descentLightItem(const SceneView& s, const Descent& d) {
  return d.lightPoolSlot >= 0 ? canopyLightInPage(s.pool + size_t(d.lightPoolSlot) * s.pageBytes, d.lightSlotInPage) : nullptr;
}

// The pool slot of brick `brick`'s page (-1: not resident); its page and slot in the page. Here and
// below, kPaths without kPathDetail (scenePaths: no model has detail levels) compiles out what only
// such models use, and without kPathExact the Haar light of --light exact.
template <uint32_t kPaths = kAllPaths>
CANOPY_HD inline int32_t residentSlot(const SceneView& s, const ModelView& m, uint32_t brick, uint32_t& page, uint32_t& inPage) {
  if (!(kPaths & kPathDetail) || brick < m.denseBricks) {
    page = m.firstBrickPage + divide(s.bricksPerPage, brick, inPage);
  } else {  // a detail level's sparse brick (the reader checked the id's level and location)
    const uint32_t loc = m.sparseIndex[brick - m.denseBricks];
    page = m.firstSparsePage + (loc >> kCanopySparseItemBits);
    inPage = loc & (kCanopySparseMaxItemsPerPage - 1u);
  }
  return s.pageSlot[page];
}

// A node of a tile array, by load16ro (on the device every node is 16-byte aligned: the backend's
// tile arrays are device allocations of 16-byte nodes; the host's copy needs no alignment).
CANOPY_HD CANOPY_FORCEINLINE CanopyNode loadNode(const CanopyNode* p) {
  const Words4 v = load16ro(p);
  CanopyNode n;
  n.child = v.w[0], n.brick = v.w[1], n.density = canopyFloatFromBits(v.w[2]), n.material = v.w[3];
  return n;
}

// A descent's brick and light fields before any brick of its path is seen: none resident, none
// missing (descendResident and descendByTable start from it).
CANOPY_HD CANOPY_FORCEINLINE void clearDescentPages(Descent& d) {
  d.brickLevel = d.lightLevel = 0;
  d.brickPoolSlot = -1;
  d.brickSlotInPage = 0;
  d.missingPage = kCanopyNone;
  d.lightPoolSlot = -1;
  d.lightSlotInPage = 0;
  d.missingLightPage = kCanopyNone;
  d.coarsestLightPage = kCanopyNone;
}

template <uint32_t kPaths = kAllPaths>
CANOPY_HD inline Descent descendResident(const SceneView& s, const ModelView& m, V3 u, uint32_t maxLevel, bool wantLight) {
  float x[3] = {u.x, u.y, u.z};
  for (int a = 0; a < 3; ++a) x[a] = x[a] < 0.0f ? 0.0f : (x[a] >= 1.0f ? 0.99999994f : x[a]);
  Descent d;
  d.node = m.root;
  d.lo[0] = d.lo[1] = d.lo[2] = 0.0f;
  d.maxLevel = uint8_t(maxLevel);
  clearDescentPages(d);
  wantLight = wantLight && m.hasLight;
  const uint32_t firstFallback = maxLevel > kFallbackLevels ? maxLevel - kFallbackLevels : 0;
  float size = 1.0f;
  uint32_t level = 0;
  for (;;) {
    const bool last = !(level < maxLevel && d.node.child != kCanopyNone && d.node.child < m.tileCount);
    if (wantLight && d.node.brick != kCanopyNone && level <= m.lightDepth) {
      uint32_t inPage;
      const uint32_t lpage = m.firstLightPage + divide(s.lightItemsPerPage, d.node.brick, inPage);
      const int32_t lslot = s.pageSlot[lpage];
      if (d.coarsestLightPage == kCanopyNone) d.coarsestLightPage = lpage;
      if (lslot >= 0) {
        d.lightPoolSlot = lslot;
        d.lightSlotInPage = uint16_t(inPage);
        d.lightLevel = uint8_t(level);
        d.missingLightPage = kCanopyNone;
      } else {
        d.missingLightPage = lpage;
      }
    }
    if (d.node.brick != kCanopyNone && (level >= firstFallback || last)) {
      uint32_t page, inPage;
      const int32_t slot = residentSlot<kPaths>(s, m, d.node.brick, page, inPage);
      if (slot >= 0) {
        d.brickPoolSlot = slot;
        d.brickSlotInPage = uint16_t(inPage);
        d.brickLevel = uint8_t(level);
      } else if (last) {
        d.missingPage = page;
      }
    }
    if (last) break;
    const uint32_t c = canopyStepDown(x, d.lo, size);
    d.node = loadNode(m.tiles + size_t(d.node.child) * 8 + c);
    ++level;
  }
  d.level = uint8_t(level);
  return d;
}

// The descent of descendResident read from the model's descent table (ModelView::levelNodes): the
// node (one load, instead of a load per level), its level and the brick whose light the path ends
// with, where that is the same Descent field for field, or one that instanceSegment() uses alike:
// true and d set where
//   - the node has a brick and it is resident: every brick field is the full descent's (its own
//     brick overrides the ancestors');
//   - the node has no brick (an empty leaf, or a uniform node): instanceSegment() then returns its
//     constant segment, which reads the node, its box, its level and the light fields only; the
//     brick fields, which the full descent may have set from ancestors, are left unset;
// and, with light wanted from a lit model, the path's light brick (the node's own, or for a uniform
// node or a detail level's node the deepest brick ancestor at most at the light depth) has its
// light page resident (then missingLightPage is none and coarsestLightPage the root's, as the full
// descent finds them). Else false (a missing brick or light page, a level beyond the table), and
// the caller descends from the root.
template <uint32_t kPaths = kAllPaths>
CANOPY_HD inline bool descendByTable(const SceneView& s, const ModelView& m, V3 u, uint32_t maxLevel, bool wantLight, Descent& d) {
  if (maxLevel >= m.tableLevels) return false;
  float x[3] = {u.x, u.y, u.z};
  const float scale = pow2i(int(maxLevel));
  const uint32_t n = 1u << maxLevel;
  uint32_t c[3];
  for (int a = 0; a < 3; ++a) {
    x[a] = x[a] < 0.0f ? 0.0f : (x[a] >= 1.0f ? 0.99999994f : x[a]);
    c[a] = uint32_t(x[a] * scale);  // exact: a power-of-two scale, truncated (the descent's child bits)
  }
  // 32 bits: at most (8^kDescentTableLevels - 1) / 7 entries (in 64, the level's first entry was a
  // 64-bit division)
  const uint32_t e = ((1u << (3 * maxLevel)) - 1u) / 7u + c[0] + n * (c[1] + n * c[2]);
  const CanopyNode node = loadNode(m.levelNodes + e);
  const uint32_t levels = m.levelOf[e], level = levels & 15u;
  d.node = node;
  d.level = uint8_t(level);
  d.maxLevel = uint8_t(maxLevel);
  const float size = levelSize(level), up = pow2i(int(level));
  for (int a = 0; a < 3; ++a) d.lo[a] = floorf(x[a] * up) * size;  // the sum of the descent's halvings, exact
  clearDescentPages(d);
  if (node.brick != kCanopyNone) {
    uint32_t page, inPage;
    const int32_t slot = residentSlot<kPaths>(s, m, node.brick, page, inPage);
    if (slot < 0) return false;
    d.brickPoolSlot = slot;
    d.brickSlotInPage = uint16_t(inPage);
    d.brickLevel = uint8_t(level);
  } else if (node.density == 0.0f) {
    return true;  // an empty leaf: no segment of it is shaded
  }
  if (!(wantLight && m.hasLight)) return true;
  const uint32_t lightBrick = m.lightBricks[e];
  if (lightBrick == kCanopyNone || m.rootLightPage == kCanopyNone) return false;
  uint32_t lightInPage;
  const uint32_t lpage = m.firstLightPage + divide(s.lightItemsPerPage, lightBrick, lightInPage);
  const int32_t lslot = s.pageSlot[lpage];
  if (lslot < 0) return false;
  d.lightPoolSlot = lslot;
  d.lightSlotInPage = uint16_t(lightInPage);
  d.lightLevel = uint8_t(levels >> 4);
  d.coarsestLightPage = m.rootLightPage;
  return true;
}

// The last descent of one instance along one ray: a later point inside the node reached, with the
// same level asked for, reaches the same node with the same resident bricks (the page table does
// not change during a pass), so instanceSegment() reuses it instead of descending from the root
// again: a brick node is crossed in about 2 x 8 steps of half a voxel, one descent instead of ~16.
// The result is exactly that of a fresh descent (same node, same brick, same light item).
struct DescentCache {
  Descent d;  // d.maxLevel == kNoLevel: empty (a new hit)
};

// The point u (unit space, clamped as descendResident clamps it) is inside the cached node.
CANOPY_HD CANOPY_FORCEINLINE bool descentCovers(const DescentCache& c, V3 u, uint32_t maxLevel) {
  const Words4 v = load16(&c.d);  // lo, then level and maxLevel (little-endian bytes)
  const float lo[3] = {canopyFloatFromBits(v.w[0]), canopyFloatFromBits(v.w[1]), canopyFloatFromBits(v.w[2])};
  const uint32_t level = v.w[3] & 0xFFu, cachedMax = (v.w[3] >> 8) & 0xFFu;
  if (cachedMax != maxLevel) return false;  // also where empty: maxLevel <= a model's depth < kNoLevel
  const float size = levelSize(level);
  float x[3] = {u.x, u.y, u.z};
  bool in = true;
  for (int a = 0; a < 3; ++a) {
    x[a] = x[a] < 0.0f ? 0.0f : (x[a] >= 1.0f ? 0.99999994f : x[a]);
    in = in && x[a] >= lo[a] && x[a] < lo[a] + size;
  }
  return in;
}

// A shading segment's light at unit point um (world ray parameter tm): the descent's light item and
// the node-local coordinates of um in it. Light pages are used and asked for here, only by
// segments with matter (not by empty space).
template <uint32_t kPaths = kAllPaths>
CANOPY_HD inline void segmentLight(const SceneView& s, const ModelView& m, const Descent& d, V3 um, float tm, Segment& g) {
  g.haarLocal = kHaarNone;
  g.haarItem = nullptr;
  if ((kPaths & kPathExact) && s.shade.exactLight && m.haarLight && d.level >= m.lightDepth) {
    // --light exact, the light lattice's level and the detail levels below it of a Haar-lit model:
    // the chaar brick at the sample's light lattice point, if its page is resident (else it is
    // asked for and the light items serve).
    const float rc = float(m.lightRootCells);
    const CanopyHaarLocation at =
        canopyHaarLocate(m.haar, um.x * rc - 0.5f + float(m.origin[0]), um.y * rc - 0.5f + float(m.origin[1]), um.z * rc - 0.5f + float(m.origin[2]));
    const int32_t slot = at.page != kCanopyNone ? s.pageSlot[at.page] : -1;
    if (at.page == kCanopyNone || slot >= 0) {
      if (slot >= 0) {
        writeStamp(s.slotUsed + slot, s.stamp);
        g.haarItem = canopyHaarItemInPage(s.pool + size_t(slot) * s.pageBytes, at.item);
      }
      g.haarLocal = uint32_t(at.at.lx) | uint32_t(at.at.ly) << 2 | uint32_t(at.at.lz) << 4 | m.haar.fp16 << 6;
      g.light[0] = at.at.fx, g.light[1] = at.at.fy, g.light[2] = at.at.fz;
      g.lightItem = nullptr;
      g.tSample = tm;
      return;
    }
    writeStamp(s.pageWanted + at.page, s.stamp);
  }
  if (d.missingLightPage != kCanopyNone) writeStamp(s.pageWanted + d.missingLightPage, s.stamp);
  g.lightItem = descentLightItem(s, d);
  g.tSample = tm;
  if (g.lightItem) {
    writeStamp(s.slotUsed + d.lightPoolSlot, s.stamp);
    float lo[3];
    const float inv = 1.0f / levelBox(d, d.lightLevel, lo);
    g.light[0] = (um.x - lo[0]) * inv;
    g.light[1] = (um.y - lo[1]) * inv;
    g.light[2] = (um.z - lo[2]) * inv;
  } else {
    if (d.coarsestLightPage != kCanopyNone) writeStamp(s.pageWanted + d.coarsestLightPage, s.stamp);
    g.light[0] = g.light[1] = g.light[2] = 0.0f;
  }
}

// The indirect light of a shading segment of instance `inst` on the ray o + t dir: the LB light of
// its light item, else the density-only ambient term; each term times its scene factor at its sample.
// kWithLight = false: compiled without the LB light code, for scenes without lit models (where no
// segment has a light item, so the result is the same).
template <bool kWithLight = true, uint32_t kPaths = kAllPaths>
CANOPY_HD inline void segmentIndirect(const SceneView& s, const InstanceView& inst, const Segment& g, V3 o, V3 dir, float out[3]) {
  const SceneLightPair factor = sceneLightFactors(s.light, o + dir * g.tSample);
  if (kWithLight && (kPaths & kPathExact) && g.haarLocal != kHaarNone) {
    haar::BrickLookup at;
    at.slot = 0;
    at.lx = int(g.haarLocal & 3u), at.ly = int((g.haarLocal >> 2) & 3u), at.lz = int((g.haarLocal >> 4) & 3u);
    at.fx = g.light[0], at.fy = g.light[1], at.fz = g.light[2];
    const haar::Rgb sun = {s.shade.sun[0], s.shade.sun[1], s.shade.sun[2]};
    sampleHaarLbLight(g.haarItem, (g.haarLocal >> 6) & 1u, at, inst.sunWeights, sun, s.shade.ambient, factor.sun, factor.ambient, out);
    return;
  }
  if (!kWithLight || !g.lightItem) {
    ambientOnly(s, factor, out);
    return;
  }
  sampleLbLight(g.lightItem, inst.sunWeights, g.light[0], g.light[1], g.light[2], s.shade.sun, s.shade.ambient, factor, out);
}

// An instance's segment that stays what it is (k = 0, the same end) over later steps: the primary
// march keeps it instead of evaluating the instance again at each step of its neighbours (another
// instance's brick steps, while this one crosses an empty node). instanceSegment() fills it for an
// EMPTY LEAF (no children, no brick, density 0), and for a run of empty cells of a brick (the
// argument is at that code, emptyRunEnd's use): evaluating the instance again at any t' with
//   t' < until   and   the footprint's level at t' >= level (the leaf's level)
// descends to the same leaf (the point is inside it, and a leaf ends every descent that reaches its
// level) and returns k = 0 with the same end, bit for bit: `until` stops 3 epsilons (instanceSegment's
// eps at the segment's end, which bounds the eps at t') short of the end, far more than the float
// rounding of the point (a few ulps of unit coordinates, < 1e-3 cell) and of the exit. Everything
// else (bricks, uniform nodes, misses, shadow cones) is evaluated at every step as before. The
// primary march then folds the level condition into `until` (levelHoldsUntil: the footprint only
// grows along the ray, so the level condition holds below some t), and a held hit costs one
// comparison per step.
struct EmptyHold {
  float until;     // -inf: nothing held
  float end;       // the held segment's end (its tEnd)
  uint32_t level;  // the leaf's level
};

// The end of the run of empty cells (formats/canopy_sample.h, empty-cell masks) of a brick that
// the ray o + t d (unit space) crosses from unit point u on: false when u's cell is not empty, else
// true and tEnd = where the ray enters the first cell that is not, or leaves the brick ([brickLo,
// brickLo + brickSize), inv = 1 / brickSize). The grid walk (grid_dda.h) over the brick's n^3 cells; each plane's
// crossing is computed from the plane alone (as nodeExit does), so a walk that starts in a later
// cell of the same run ends at the same value.
// `empty(x, y, z)`: cell (x, y, z) of the n^3 is empty (a dense brick's mask bit, or a sparse
// brick's stored empty cells: EmptyCellBits below).
template <class Empty>
CANOPY_HD inline bool emptyRunEnd(const Empty& empty, V3 uo, V3 ud, V3 u, const float brickLo[3], float brickSize, float inv, float& tEnd) {
  constexpr int n = int(kCanopyEmptyCells);
  int j[3];
  for (int a = 0; a < 3; ++a) {
    const float q = floorf((comp(u, a) - brickLo[a]) * inv * float(n));
    j[a] = q < 0.0f ? 0 : (q > float(n - 1) ? n - 1 : int(q));
  }
  if (!empty(j[0], j[1], j[2])) return false;
  const float q = brickSize / float(n);
  const float cellSize[3] = {q, q, q};
  GridDda w;
  gridStart(w, j, brickLo, cellSize, uo, ud);
  for (;;) {
    const bool end = onAxis(gridAxis(w), [&](auto axis) {
      constexpr int a = decltype(axis)::value;
      tEnd = w.tNext[a];
      w.cell[a] += w.step[a];
      if (w.step[a] == 0 || w.cell[a] < 0 || w.cell[a] > n - 1 || !empty(w.cell[0], w.cell[1], w.cell[2])) return true;
      w.tNext[a] = gridCrossing(brickLo[a], q, w.cell[a], w.step[a], comp(uo, a), comp(ud, a));
      return false;
    });
    if (end) return true;
  }
}

// A brick's empty cells (formats/canopy_sample.h): bit i of 32-bit word i / 32, i = x + 8 (y + 8 z):
// a dense brick's mask in its page image (canopyFillBrickMasks, 64-bit words read as 32-bit ones:
// little-endian, the same bits) or a sparse brick's stored empty cells (format 2.0), so that a
// detail model marches exactly as its dense form would.
struct EmptyCellBits {
  const uint32_t* words;
  CANOPY_HD CANOPY_FORCEINLINE bool operator()(int x, int y, int z) const {
    const uint32_t i = uint32_t(x + int(kCanopyEmptyCells) * (y + int(kCanopyEmptyCells) * z));
    return ((canopyLoadRO(words + (i >> 5)) >> (i & 31u)) & 1u) != 0;
  }
};

// The octree level instanceSegment() picks for footprint (world) at instance `inst`.
CANOPY_HD CANOPY_FORCEINLINE uint32_t segmentLevel(const SceneView& s, const InstanceView& inst, uint32_t depth, float footprint) {
  return levelForFootprint(depth, footprint / inst.cellWorld, s.shade.lodBias);
}

// A ray parameter T such that the level of a primary cone (segmentLevel at footprint t *
// pixelAngle) is >= `level` at every t < T, so that a held segment's level condition (EmptyHold)
// can be folded into its `until` once, instead of being evaluated at every step. levelForFootprint
// gives depth - floor(log2 fp) + lodBias (fp = max(footprint / cellWorld, 1), clamped, truncated),
// which is >= level (level >= 1) exactly where floor(log2 fp) <= depth + lodBias - level, i.e.
// fp < 2^k with k = floor(depth + lodBias - level) + 1. T stops 1e-5 short of that relatively: far
// more than the rounding of t * pixelAngle / cellWorld and of log2f near 2^k (a few 1e-7), so
// every t < T has fp < 2^k in floats too. (k >= 1 wherever the hold was made: its level is at most
// the level at that t.) Level 0 holds everywhere.
CANOPY_HD inline float levelHoldsUntil(const SceneView& s, const InstanceView& inst, uint32_t depth, float pixelAngle, uint32_t level) {
  if (level == 0) return 3.0e38f;
  const float k = floorf(float(depth) + s.shade.lodBias - float(level)) + 1.0f;
  return ldexpf(inst.cellWorld / pixelAngle, int(k)) * 0.99999f;
}

// One instance's ray at ray position t in its octree's unit space, and the bounds of the segment
// that starts there.
struct SegmentRay {
  V3 uo, ud;            // the ray's origin and direction in the instance's unit space
  float t, tout;        // the segment's start and the end of the instance's box interval
  float eps;            // a thousandth of a cell, but at least a few float ulps of t
  float cellsPerWorld;  // lattice cells per world unit along the ray
  float tExit;          // where the ray leaves the descent's node (>= t + eps)
  float grow;           // the steps' growth (stepGrowth, >= 1): a brick step is grow x stepFactor voxels, a uniform node's piece grow x kMaxConstantCells cells
};

// Holds an empty segment that ends at tEnd (EmptyHold): a later step before `until` keeps k = 0
// without evaluating the instance again.
CANOPY_HD CANOPY_FORCEINLINE void holdEmpty(EmptyHold* hold, float tEnd, float cellsPerWorld, uint32_t level) {
  const float epsEnd = fmaxf(1e-3f / cellsPerWorld, fabsf(tEnd) * 1e-6f);
  hold->until = tEnd - 3.0f * epsEnd;
  hold->end = tEnd;
  hold->level = level;
}

// The segment of a node without a usable brick (a constant node, or a missing brick without a close
// resident ancestor): the node's mean up to the node's exit.
template <uint32_t kPaths>
CANOPY_HD CANOPY_FORCEINLINE Segment constantSegment(const SceneView& s, const ModelView& m, const Descent& d, const SegmentRay& r,
                                                     bool shading, EmptyHold* hold) {
  Segment g;
  const CanopySample c = canopyUnpack(d.node.density, d.node.material);
  g.k = s.shade.sigma * c.density * (r.cellsPerWorld * m.extinctionScale);
  g.albedo[0] = c.albedo[0], g.albedo[1] = c.albedo[1], g.albedo[2] = c.albedo[2];
  float tEnd = r.tExit;
  if (shading && c.density > 0.0f) {  // a shadow cone integrates it in one go
    const float maxLen = kMaxConstantCells * r.grow / r.cellsPerWorld;
    tEnd = tEnd < r.t + maxLen ? tEnd : r.t + maxLen;
  }
  g.tEnd = tEnd < r.tout ? tEnd : r.tout;
  if (shading && g.k > 0.0f) segmentLight<kPaths>(s, m, d, r.uo + r.ud * (0.5f * (r.t + g.tEnd)), 0.5f * (r.t + g.tEnd), g);
  if (hold && c.density == 0.0f && d.node.brick == kCanopyNone && !(d.node.child != kCanopyNone && d.node.child < m.tileCount))
    holdEmpty(hold, g.tEnd, r.cellsPerWorld, d.level);
  return g;
}

// Whether point up of the ray lies in an empty cell of the brick: then g is the empty segment up to
// the end of the run of empty cells (emptyRunEnd) and true is returned.
CANOPY_HD CANOPY_FORCEINLINE bool emptyCellSegment(const SceneView& s, const unsigned char* brickPage, const Descent& d, bool sparse,
                                                   const SegmentRay& r, V3 up, const float brickLo[3], float brickSize, float inv,
                                                   EmptyHold* hold, Segment& g) {
  float tEnd;
  const uint32_t* words = sparse ? canopySparseBrickInPage(brickPage, d.brickSlotInPage).empty
                                 : reinterpret_cast<const uint32_t*>(brickPage + s.brickMaskOffset) + 2 * kCanopyEmptyWords * d.brickSlotInPage;
  if (!emptyRunEnd(EmptyCellBits{words}, r.uo, r.ud, up, brickLo, brickSize, inv, tEnd)) return false;
  // k = 0 up to the empty run's end: the samples a march would take there all read 0
  CANOPY_PLAY_COUNT(s, emptyBlockSkips, 1);
  tEnd = tEnd > r.t + r.eps ? tEnd : r.t + r.eps;
  tEnd = tEnd < r.tExit ? tEnd : r.tExit;
  g.tEnd = tEnd < r.tout ? tEnd : r.tout;
  g.k = 0.0f;
  g.albedo[0] = g.albedo[1] = g.albedo[2] = 0.0f;
  // Evaluated again at t' < until with the footprint's level still >= d.level (so equal to it
  // where the node has children: the level only gets coarser along the ray), the descent
  // reaches the same node and brick, the point lies in a later cell of the same run, and
  // the walk from there ends at the same plane, computed alike (the argument of EmptyHold;
  // where the ray grazes a cell edge within float rounding, the point's cell may
  // be the diagonal neighbour of the walk's, and the two could differ).
  if (hold) holdEmpty(hold, g.tEnd, r.cellsPerWorld, d.level);
  return true;
}

// The segment of a brick: one trilinear sample at the middle of a step of stepFactor voxels of the
// descent's level (cut at the node's exit and the instance's end).
template <uint32_t kPaths>
CANOPY_HD CANOPY_FORCEINLINE Segment brickSegment(const SceneView& s, const ModelView& m, const Descent& d, const unsigned char* brickPage,
                                                  bool sparse, const SegmentRay& r, const float brickLo[3], float inv, bool shading) {
  Segment g;
  CANOPY_PLAY_COUNT(s, brickSamples, 1);
  const float voxelCells = float(m.rootCells >> 3) * levelSize(d.level);  // this level's voxel, in cells
  float tEnd = r.t + s.shade.stepFactor * r.grow * voxelCells / r.cellsPerWorld;
  tEnd = tEnd < r.tExit ? tEnd : r.tExit;
  tEnd = tEnd < r.tout ? tEnd : r.tout;
  const V3 um = r.uo + r.ud * (0.5f * (r.t + tEnd));
  const float lx = (um.x - brickLo[0]) * inv, ly = (um.y - brickLo[1]) * inv, lz = (um.z - brickLo[2]) * inv;
  const CanopySample c = canopySampleBrickInPage(brickPage, d.brickSlotInPage, sparse, lx, ly, lz);
  g.k = s.shade.sigma * c.density * (r.cellsPerWorld * m.extinctionScale);
  if (c.density == 0.0f) CANOPY_PLAY_COUNT(s, zeroBrickSamples, 1);
  g.albedo[0] = c.albedo[0], g.albedo[1] = c.albedo[1], g.albedo[2] = c.albedo[2];
  g.tEnd = tEnd;
  if (shading && g.k > 0.0f) segmentLight<kPaths>(s, m, d, um, 0.5f * (r.t + tEnd), g);
  return g;
}

// The segment of instance `inst` at ray position t (world), the cone footprint there being
// `footprint` (world units). tout is the end of the instance's box interval. `hold` (optional): set
// for an empty leaf's segment, else cleared (see EmptyHold).
template <uint32_t kPaths = kAllPaths>
CANOPY_HD inline Segment instanceSegment(const SceneView& s, const InstanceView& inst, V3 o, V3 dir, float t,
                                         float tout, float footprint, bool shading, DescentCache& cache,
                                         EmptyHold* hold = nullptr, float grow = 1.0f) {
  const ModelView& m = s.models[inst.model];
  SegmentRay r;
  r.uo = applyPoint(inst.worldToUnit, o);
  r.ud = applyVector(inst.worldToUnit, dir);
  r.t = t;
  r.tout = tout;
  r.grow = grow;
  r.cellsPerWorld = length(r.ud) * float(m.rootCells);
  r.eps = fmaxf(1e-3f / r.cellsPerWorld, fabsf(t) * 1e-6f);
  const uint32_t level = segmentLevel(s, inst, m.depth, footprint);
  const V3 up = r.uo + r.ud * (t + r.eps);
  if (hold) hold->until = -3.0e38f;
  CANOPY_PLAY_COUNT(s, segments, 1);
  if (!s.shade.descentCache || !descentCovers(cache, up, level)) {
    if ((kPaths & kPathTable) && s.shade.descentTable && descendByTable<kPaths>(s, m, up, level, shading, cache.d))
      CANOPY_PLAY_COUNT(s, tableDescents, 1);
    else
      cache.d = descendResident<kPaths>(s, m, up, level, shading);
    CANOPY_PLAY_COUNT(s, descents, 1);
  }
  const Descent& d = cache.d;
  r.tExit = nodeExit(r.uo, r.ud, d.lo, levelSize(d.level));
  if (r.tExit < t + r.eps) r.tExit = t + r.eps;
  if (d.missingPage != kCanopyNone) writeStamp(s.pageWanted + d.missingPage, s.stamp);
  const unsigned char* brickPage = descentBrickPage(s, d);
  if (d.node.brick == kCanopyNone || brickPage == nullptr) return constantSegment<kPaths>(s, m, d, r, shading, hold);
  writeStamp(s.slotUsed + d.brickPoolSlot, s.stamp);
  float brickLo[3];
  const float brickSize = levelBox(d, d.brickLevel, brickLo);
  const float inv = 1.0f / brickSize;
  const bool sparse = (kPaths & kPathDetail) && d.brickLevel > m.lightDepth;  // a detail level's brick (format 2.0)
  Segment g;
  if (s.shade.skipEmptyBlocks && (sparse || s.brickMaskOffset != 0) &&
      emptyCellSegment(s, brickPage, d, sparse, r, up, brickLo, brickSize, inv, hold, g))
    return g;
  return brickSegment<kPaths>(s, m, d, brickPage, sparse, r, brickLo, inv, shading);
}

}  // namespace canopy::play
