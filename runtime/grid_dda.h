// grid_dda.h: the 3D-DDA (Amanatides and Woo) that the ray's grid walks share: the instance grid
// (cone_walk.h, walkBegin / walkAdvance) and a brick's empty cells (cone_segment.h, emptyRunEnd).
// Part of runtime/cone.h.
//
// A walk holds its cell, its step per axis and where the ray o + t d crosses the next cell plane on
// each axis. It leaves the cell through the nearest crossing (a tie goes to the lower axis). The
// crossing of a plane is computed from the plane itself (gridCrossing); the instance grid then moves
// it on by one cell's width in t per step (GridDda::tDelta), the empty-cell walk computes each one
// from its plane again (so that a walk started in a later cell of a run ends at the same value).
#pragma once
#include <math.h>

#include <type_traits>

#include "runtime/cone_math.h"

namespace canopy::play {

struct GridDda {
  int cell[3];
  int step[3];      // +1, -1, or 0 (the ray is parallel to that axis's planes)
  float tNext[3];   // where the ray crosses the next plane on each axis (3e38: never)
};

// Where the ray o + t d (on one axis: o, d) crosses the plane ahead of cell c of a grid whose cells
// are `size` wide from `lo`, for a walk that steps by `step` (+1 or -1) on that axis.
CANOPY_HD CANOPY_FORCEINLINE float gridCrossing(float lo, float size, int c, int step, float o, float d) {
  return (lo + float(c + (step > 0)) * size - o) / d;
}

// Starts a walk in cell `cell` of the grid (lo, cells `size` wide on every axis; size[a] per axis).
CANOPY_HD CANOPY_FORCEINLINE void gridStart(GridDda& w, const int cell[3], const float lo[3], const float size[3], V3 o, V3 d) {
  for (int a = 0; a < 3; ++a) {
    const float da = comp(d, a);
    w.cell[a] = cell[a];
    w.step[a] = fabsf(da) < 1e-30f ? 0 : (da > 0.0f ? 1 : -1);
    w.tNext[a] = w.step[a] == 0 ? 3.0e38f : gridCrossing(lo[a], size[a], cell[a], w.step[a], comp(o, a), da);
  }
}

// The axis whose plane the ray crosses first.
CANOPY_HD CANOPY_FORCEINLINE int gridAxis(const GridDda& w) {
  const bool y = w.tNext[1] < w.tNext[0];  // constant indices only (onAxis)
  return w.tNext[2] < (y ? w.tNext[1] : w.tNext[0]) ? 2 : (y ? 1 : 0);
}

// f(std::integral_constant<int, a>{}) for the axis a (0, 1 or 2): the axis as a compile-time
// constant, so that a walk's per-axis update indexes its arrays by constants: indexed by a run-time
// axis, nvcc keeps a GridDda in local memory (the pixel kernel's empty-cell walk and instance-grid
// walk, docs/performance.md "The real forest's walk in Nsight").
template <class F>
CANOPY_HD CANOPY_FORCEINLINE auto onAxis(int a, F&& f) {
  using std::integral_constant;
  return a == 0 ? f(integral_constant<int, 0>{}) : (a == 1 ? f(integral_constant<int, 1>{}) : f(integral_constant<int, 2>{}));
}

// Where the ray leaves the current cell.
CANOPY_HD CANOPY_FORCEINLINE float gridExit(const GridDda& w) {
  const float t = w.tNext[0] < w.tNext[1] ? w.tNext[0] : w.tNext[1];
  return t < w.tNext[2] ? t : w.tNext[2];
}

}  // namespace canopy::play
