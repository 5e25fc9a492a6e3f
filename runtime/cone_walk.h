// cone_walk.h: the instances along a ray: the 3D-DDA over the instance grid and the hit list of the
// lock-step march. Part of runtime/cone.h.
#pragma once
#include "runtime/cone_segment.h"

namespace canopy::play {

// ------------------------------------------------------------------------------------------------
// The lock-step march over every instance along a ray
// ------------------------------------------------------------------------------------------------
// The first 16 bytes are what every step reads of every hit (tin, hold.until, hold.end): one
// 16-byte load on the GPU (hitHead).
struct alignas(16) Hit {
  float tin;
  EmptyHold hold;  // primary march: its current empty leaf segment (until = -inf: none)
  uint32_t instance;
  float tout;
};
static_assert(offsetof(Hit, hold) == 4 && offsetof(EmptyHold, until) == 0 && offsetof(EmptyHold, end) == 4, "hitHead's layout");

// tin, hold.until and hold.end of a hit.
CANOPY_HD CANOPY_FORCEINLINE void hitHead(const Hit& h, float& tin, float& until, float& end) {
  const Words4 v = load16(&h);
  tin = canopyFloatFromBits(v.w[0]), until = canopyFloatFromBits(v.w[1]), end = canopyFloatFromBits(v.w[2]);
}

// 3D-DDA over the instance grid plus the hit list. The hits live in fixed slots (a bit of `live`
// each, visited in ascending slot order): a hit never moves, its descent cache sits beside it at
// the same index, and retiring one clears a bit instead of shifting the hits after it (local
// memory on the GPU). Retiring runs only once the march reaches the nearest exit (`minTout`), not
// at every step.
// A cell entered through a face adds only the instances that the cell behind the face does not
// list (SceneView::gridFaceItems): every other one was met in an earlier cell of the walk, and its
// interval along the ray, tested there, was added then or rejected for good (a rejection at an
// earlier, smaller tNow holds at a later one). An instance's cells form a box of cells and the
// walk's cells move monotonically along each axis, so an instance met in any earlier cell is
// listed by the cell just behind. So no membership scan is needed, except where a full list put a
// hit off or dropped one (below).
// A full list loses nothing: the farthest of its pending hits and the new one waits (the one that
// starts later), the march stops where it starts or at the cell's exit (tCellExit, the nearer),
// and walkAdvance adds the cell there (`rewind`: the current one again, or the next) with its
// whole list scanned against the live hits. Every waiting instance is met again from there: the
// ray enters its box at or after that point, in that cell or a later one, and every instance that
// a later cell lists was listed by the cell added whole or added through a face on the way. Only
// when every live hit and the new one are active at once (more than kHitCapacity boxes overlap
// where the march is) is a hit dropped for good (`dropped`): from then on each cell's whole list
// is scanned against the hits, as a dropped instance is found again from a later cell it overlaps.
// The slots themselves live apart from the walk's other state (HitSlots), reached through two
// pointers: indexed by a run-time slot they must be in local memory on the GPU, and in one
// aggregate with them nvcc kept the walk's scalars (live, the DDA, the exits) there too, loaded at
// every step (the pixel kernel's local-memory loads on the real forest's walk, Nsight Compute).
struct HitSlots {
  Hit hits[kHitCapacity];
  DescentCache caches[kHitCapacity];  // caches[i]: hits[i]'s last descent along the ray (empty when added)
};
struct InstanceWalk {
  Hit* hits;                          // a HitSlots' (walkBegin)
  DescentCache* caches;
  uint32_t live;                      // bit i: hits[i] is pending or active
  float minTout;                      // <= every live hit's tout
  GridDda dda;       // the instance grid's cell and plane crossings (grid_dda.h)
  float tDelta[3];   // the ray's t across one cell on each axis
  float tCellExit;  // the march may advance up to here with the current list
  float tGridExit;
  bool done;
  bool rewind;   // at tCellExit the current cell is added whole: the first cell (walkBegin), or after a full list put a hit off
  bool dropped;  // a hit was dropped from a full list: cells add their whole lists with a membership scan
};
constexpr uint32_t kAllHitSlots = kHitCapacity >= 32 ? 0xFFFFFFFFu : (1u << kHitCapacity) - 1u;

// Index of the lowest set bit of a non-zero mask.
CANOPY_HD CANOPY_FORCEINLINE uint32_t lowestSetBit(uint32_t m) {
#if defined(__CUDA_ARCH__)
  return uint32_t(__ffs(int(m)) - 1);
#else
  return uint32_t(__builtin_ctz(m));
#endif
}

// Adds the instances of the current cell, entered through `face` (2 a for a step along +a, 2 a + 1
// along -a; -1: the walk's first cell).
CANOPY_HD inline void walkAddCell(const SceneView& s, InstanceWalk& w, V3 o, V3 d, float tNow, int face) {
  const int c = w.dda.cell[0] + s.gridDim[0] * (w.dda.cell[1] + s.gridDim[1] * w.dda.cell[2]);
  const bool scan = face < 0 || w.dropped;
  const uint32_t* items = scan ? s.gridItems : s.gridFaceItems;
  const uint32_t list = scan ? uint32_t(c) : uint32_t(6 * c + face);
  const uint32_t* start = scan ? s.gridStart : s.gridFaceStart;
  const uint32_t kEnd = start[list + 1];
  for (uint32_t k = start[list]; k < kEnd; ++k) {
    const uint32_t id = items[k];
    if (scan) {
      bool present = false;
      for (uint32_t m = w.live; m != 0; m &= m - 1u) present |= w.hits[lowestSetBit(m)].instance == id;
      if (present) continue;
    }
    const InstanceView& inst = s.instances[id];
    // the exact interval: the ray against the box of the model's matter in the instance's unit
    // space (an oriented box in world space; t is the same parameter in both spaces)
    float t0, t1;
    rayBox(applyPoint(inst.worldToUnit, o), applyVector(inst.worldToUnit, d), v3(inst.unitLo[0], inst.unitLo[1], inst.unitLo[2]),
           v3(inst.unitHi[0], inst.unitHi[1], inst.unitHi[2]), t0, t1);
    if (t0 < tNow) t0 = tNow;
    if (!(t1 > t0)) continue;
    uint32_t slot;
    if (w.live == kAllHitSlots) {  // full: the farthest pending hit or this one waits (or is dropped)
      slot = 0;
      for (uint32_t m = w.live & (w.live - 1u); m != 0; m &= m - 1u) {
        const uint32_t h = lowestSetBit(m);
        slot = w.hits[h].tin > w.hits[slot].tin ? h : slot;
      }
      const float tLater = w.hits[slot].tin > t0 ? w.hits[slot].tin : t0;
      if (tLater > tNow) {  // it starts ahead of the march: the walk adds this cell again there
        w.rewind = true;
        w.tCellExit = tLater < w.tCellExit ? tLater : w.tCellExit;
        CANOPY_PLAY_COUNT(s, hitRewinds, 1);
      } else {  // all active at once: this one or the farthest is found again from a later cell only
        w.dropped = true;
        CANOPY_PLAY_COUNT(s, hitDrops, 1);
      }
      if (w.hits[slot].tin <= t0) continue;
    } else {
      slot = lowestSetBit(~w.live & kAllHitSlots);
      w.live |= 1u << slot;
    }
    w.hits[slot] = Hit{t0, EmptyHold{-3.0e38f, 0.0f, 0u}, id, t1};
    w.caches[slot].d.maxLevel = kNoLevel;
    w.minTout = t1 < w.minTout ? t1 : w.minTout;
  }
}

// Bounds the march by the current cell's exit and adds the cell's instances (walkAddCell, which
// may bound it further).
CANOPY_HD CANOPY_FORCEINLINE void walkEnterCell(const SceneView& s, InstanceWalk& w, V3 o, V3 d, float tNow, int face) {
  const float tx = gridExit(w.dda);
  w.tCellExit = tx < w.tGridExit ? tx : w.tGridExit;
  walkAddCell(s, w, o, d, tNow, face);
}

// Starts the walk for the ray o + t d, t in [tStart, tEnd], its hits in `slots`.
CANOPY_HD inline void walkBegin(const SceneView& s, InstanceWalk& w, HitSlots& slots, V3 o, V3 d, float tStart, float tEnd) {
  w.hits = slots.hits;
  w.caches = slots.caches;
  w.live = 0;
  w.minTout = 3.0e38f;
  w.done = true;
  w.dropped = false;
  w.tCellExit = tEnd;
  w.rewind = false;
  if (s.instanceCount == 0) return;
  const V3 lo = v3(s.gridLo[0], s.gridLo[1], s.gridLo[2]);
  const V3 hi = v3(s.gridLo[0] + s.gridCell[0] * float(s.gridDim[0]), s.gridLo[1] + s.gridCell[1] * float(s.gridDim[1]),
                   s.gridLo[2] + s.gridCell[2] * float(s.gridDim[2]));
  float t0, t1;
  rayBox(o, d, lo, hi, t0, t1);
  t0 = t0 > tStart ? t0 : tStart;
  t1 = t1 < tEnd ? t1 : tEnd;
  if (!(t1 > t0)) return;
  w.done = false;
  w.tGridExit = t1;
  for (int a = 0; a < 3; ++a) {  // (no step on an axis gridStart leaves with step 0)
    const float da = fabsf(comp(d, a));
    w.tDelta[a] = da < 1e-30f ? 3.0e38f : s.gridCell[a] / da;
  }
  const V3 p = o + d * t0;
  int cell[3];
  for (int a = 0; a < 3; ++a) {
    const int c = int(floorf((comp(p, a) - s.gridLo[a]) / s.gridCell[a]));
    cell[a] = c < 0 ? 0 : (c >= s.gridDim[a] ? s.gridDim[a] - 1 : c);
  }
  gridStart(w.dda, cell, s.gridLo, s.gridCell, o, d);
  // The first cell's instances are added by the march's first walkAdvance, at t0 (its whole list,
  // as after a full list): one inlined copy of walkAddCell fewer in each march.
  w.rewind = true;
  w.tCellExit = t0;
}

// Advances the DDA one cell (when the march reached tCellExit). After a full list put a hit off
// (`rewind`), the cell the march is in is added with its whole list: the current one again if the
// march stopped inside it (where the hit put off starts), else the next one. One call of
// walkEnterCell for all: the kernels' code is the smaller (code size costs these kernels time,
// docs/performance.md).
CANOPY_HD inline void walkAdvance(const SceneView& s, InstanceWalk& w, V3 o, V3 d, float tNow) {
  if (w.done) return;
  const bool whole = w.rewind;
  w.rewind = false;
  int face = -1;
  if (!whole || !(tNow < gridExit(w.dda))) {
    if (w.tCellExit >= w.tGridExit) {
      w.done = true;
      return;
    }
    face = onAxis(gridAxis(w.dda), [&](auto axis) {  // constant indices (grid_dda.h onAxis)
      constexpr int a = decltype(axis)::value;
      w.dda.cell[a] += w.dda.step[a];
      w.dda.tNext[a] += w.tDelta[a];
      if (w.dda.cell[a] < 0 || w.dda.cell[a] >= s.gridDim[a]) return -1;
      return 2 * a + (w.dda.step[a] > 0 ? 0 : 1);
    });
    if (face < 0) {
      w.done = true;
      w.tCellExit = w.tGridExit;
      return;
    }
    face = whole ? -1 : face;
  }
  walkEnterCell(s, w, o, d, tNow, face);
}

// Drops hits that ended before t (tout <= t); nothing to do before the nearest exit.
CANOPY_HD inline void walkRetire(InstanceWalk& w, float t) {
  if (t < w.minTout) return;
  w.minTout = 3.0e38f;
  for (uint32_t m = w.live; m != 0; m &= m - 1u) {
    const uint32_t h = lowestSetBit(m);
    const float tout = w.hits[h].tout;
    if (!(tout > t)) {
      w.live &= ~(1u << h);
      continue;
    }
    w.minTout = tout < w.minTout ? tout : w.minTout;
  }
}

}  // namespace canopy::play
