// adaptive.h: adaptive sampling of a frame in warp-tile blocks (canopy-play --adaptive TOL), per
// element, for the CPU reference and the CUDA kernels alike.
//
// The pixels with an even x and an even y (the lattice: a quarter of the frame) are traced first,
// in warp tiles of the half-size grid. Every other pixel lies in a 2x2-pixel cell whose four
// corners are lattice pixels (x0, y0), (x0 + 2, y0), (x0, y0 + 2), (x0 + 2, y0 + 2) with
// x0 = x & ~1, y0 = y & ~1. The frame is then taken in blocks, the pixel kernel's warp tiles in the
// frame's own coordinates (tileW x tileH pixels, 4 x 8 by default: block (bx, by) holds the pixels
// [bx tileW, (bx + 1) tileW) x [by tileH, (by + 1) tileH)). Where the four corners of every cell
// that holds one of a block's off-lattice pixels differ by at most TOL in every channel
// (premultiplied linear RGBA: the colour, and the opacity, so that an edge of a crown against the
// sky is never smoothed over), the block's off-lattice pixels are their cells' bilinear means;
// the other blocks' off-lattice pixels are traced (on the GPU compacted in tile order, so that a
// warp's rays lie in one block and the next failing one). A cell that is not whole in the frame (the
// last column or row) fails its block.
//
// Why blocks: a warp costs about the union of its rays' work, so the pixels left to trace pay only
// where they come 32 neighbours to a warp. The form that traced each failing pixel on
// its own (the marks compacted, 32 scattered edge pixels to a warp) cost 2.6x a pixel's time and was
// slower than the full trace on five of six real-forest views (docs/performance.md, "adaptive
// sampling"). Within a block that passes, what a filled pixel misses is a feature narrower than
// two pixels between its cell's corners; bench/RESULTS.md gives the measured RMS.
//
// A crown seen closer than its voxels' resolution at the frame's pixel size (every voxel wider
// than a pixel, as at 3840x2160 anywhere in a forest of 0.2 m voxels within 380 m) is smooth
// within a cell except at its edges and where the march's sample phase differs between
// neighbouring rays: the test finds those, and the blocks between them are what it saves.
//
// A band of rows (tiles.h) traces the lattice rows that its blocks' cells need, beyond its own rows
// where its edges cut a block or a cell, and a block's test reads only lattice pixels, so the image
// does not depend on where the bands are. The passes (lattice; the blocks' tests; the fills and the failing
// blocks' trace) need no synchronisation inside a pass: a fill reads lattice pixels and writes its
// own off-lattice pixel, which no trace of the same pass writes.
#pragma once
#include <cmath>
#include <cstdint>

#include "canopy/hd.h"
#include "runtime/tiles.h"

namespace canopy::play {

CANOPY_HD inline bool adaptiveOnLattice(int x, int y) { return ((x | y) & 1) == 0; }

// The lattice's pixels that rows [y0, y1) of a frame `height` rows high need, as warp tiles of the
// half-size grid (lattice column lx = x / 2, row ly = y / 2): columns [0, (width + 1) / 2), rows
// [y0 / 2, the row below the cell of row y1 - 1], within the frame. A band traces those of its
// blocks' rows (adaptiveBlockRows), not only of its own.
CANOPY_HD inline int adaptiveLatticeWidth(int width) { return (width + 1) / 2; }
CANOPY_HD inline int adaptiveLatticeFirst(int y0) { return y0 / 2; }
CANOPY_HD inline int adaptiveLatticeEnd(int y1, int height) {
  const int end = (y1 - 1) / 2 + 2, frame = (height + 1) / 2;
  return end < frame ? end : frame;
}

// Launch position j over the band's lattice (warp tiles of the half-size grid, bandTilePixel's
// order, tilesX = ceil(adaptiveLatticeWidth / tileW)) -> its pixel (x, y); false past the lattice.
CANOPY_HD inline bool adaptiveLatticePixel(int64_t j, int tilesX, int tileW, int tileH, int width, int y0, int y1, int height, int& x,
                                           int& y) {
  int lx = 0, ly = 0;
  if (!bandTilePixel(j, tilesX, tileW, tileH, adaptiveLatticeWidth(width), adaptiveLatticeFirst(y0), adaptiveLatticeEnd(y1, height), lx, ly))
    return false;
  x = 2 * lx, y = 2 * ly;
  return true;
}

// True where the traced corners of the cell whose lower corner is (cx, cy) (both even) are whole in
// the frame and agree within tol in every channel of rgba (width x height pixels, 4 floats each).
CANOPY_HD inline bool adaptiveCellAgrees(const float* rgba, int width, int height, int cx, int cy, float tol) {
  if (cx + 2 >= width || cy + 2 >= height) return false;
  const float* c00 = rgba + (int64_t(cy) * width + cx) * 4;
  const float* c10 = c00 + 8;
  const float* c01 = c00 + int64_t(width) * 8;
  const float* c11 = c01 + 8;
  for (int k = 0; k < 4; ++k) {
    const float lo = fminf(fminf(c00[k], c10[k]), fminf(c01[k], c11[k]));
    const float hi = fmaxf(fmaxf(c00[k], c10[k]), fmaxf(c01[k], c11[k]));
    if (!(hi - lo <= tol) || !(c00[k] + c10[k] + c01[k] + c11[k] == c00[k] + c10[k] + c01[k] + c11[k]))
      return false;  // (fminf and fmaxf drop a NaN: a NaN corner fails its cell)
  }
  return true;
}

// Block (bx, by) of tileW x tileH pixels (clipped to the frame): true where every cell that holds
// one of its off-lattice pixels agrees (adaptiveCellAgrees): fill it; false: trace it.
CANOPY_HD inline bool adaptiveBlockAgrees(const float* rgba, int width, int height, int bx, int by, int tileW, int tileH, float tol) {
  const int x0 = bx * tileW, y0 = by * tileH;
  const int x1 = x0 + tileW < width ? x0 + tileW : width, y1 = y0 + tileH < height ? y0 + tileH : height;
  for (int cy = y0 & ~1; cy < y1; cy += 2)
    for (int cx = x0 & ~1; cx < x1; cx += 2) {
      // the cell's off-lattice pixels in the block: (cx + 1, cy), (cx, cy + 1), (cx + 1, cy + 1)
      const bool right = cx + 1 >= x0 && cx + 1 < x1, left = cx >= x0, up = cy >= y0, down = cy + 1 < y1;
      const bool off = (right && up) || (left && down) || (right && down);
      if (off && !adaptiveCellAgrees(rgba, width, height, cx, cy, tol)) return false;
    }
  return true;
}

// The bilinear mean of the traced corners of off-lattice pixel (x, y)'s cell, written to it.
CANOPY_HD inline void adaptiveFillPixel(float* rgba, int width, int x, int y) {
  const int cx = x & ~1, cy = y & ~1;
  const float* c00 = rgba + (int64_t(cy) * width + cx) * 4;
  const float* c10 = c00 + 8;
  const float* c01 = c00 + int64_t(width) * 8;
  const float* c11 = c01 + 8;
  const float fx = (x & 1) ? 0.5f : 0.0f, fy = (y & 1) ? 0.5f : 0.0f;
  float* o = rgba + (int64_t(y) * width + x) * 4;
  for (int k = 0; k < 4; ++k) {
    const float top = c00[k] + fx * (c10[k] - c00[k]), bottom = c01[k] + fx * (c11[k] - c01[k]);
    o[k] = top + fy * (bottom - top);
  }
}

// The blocks of a band [y0, y1): block rows [y0 / tileH, (y1 - 1) / tileH], (width + tileW - 1) /
// tileW per row; a block that a band edge cuts (bands lie on multiples of tileH rows only where the
// frame's height allows, tiles.h) is tested by both bands, each filling or tracing its own rows of
// it. Each band traces the lattice of its blocks' whole rows (adaptiveBlockRows), so both test it
// on the same lattice pixels, traced by each, and give the same answer.
CANOPY_HD inline int adaptiveBlockRowFirst(int y0, int tileH) { return y0 / tileH; }
CANOPY_HD inline int adaptiveBlockRowEnd(int y1, int tileH) { return (y1 - 1) / tileH + 1; }
// What tile position j of the band [y0, y1) (bandTilePixel's order; tilesX tiles a row, which are
// also the blocks a row) does once the band's blocks are tested (pass: 1 where the block passed,
// from block row blockRow0 on): kAdaptiveFill its off-lattice pixel (x, y) from its cell,
// kAdaptiveTrace it, or kAdaptiveSkip (a lattice pixel, or a position past the frame or the band).
// The CUDA fill kernel's element and the CPU's loop alike.
enum : int { kAdaptiveSkip = 0, kAdaptiveFill = 1, kAdaptiveTrace = 2 };
CANOPY_HD inline int adaptiveAction(int64_t j, int tilesX, int tileW, int tileH, int width, int y0, int y1, int blockRow0, const uint8_t* pass,
                                    int& x, int& y) {
  if (!bandTilePixel(j, tilesX, tileW, tileH, width, y0, y1, x, y) || adaptiveOnLattice(x, y)) return kAdaptiveSkip;
  return pass[int64_t(y / tileH - blockRow0) * tilesX + x / tileW] != 0 ? kAdaptiveFill : kAdaptiveTrace;
}

// The off-lattice pixels of rows [y0, y1) of a frame `width` pixels wide: an odd row is all off the
// lattice, an even row has its odd columns off it. The filled ones are these less those traced.
CANOPY_HD inline uint64_t adaptiveOffLattice(int width, int y0, int y1) {
  const uint64_t odd = uint64_t(y1 / 2 - y0 / 2), rows = uint64_t(y1 - y0);  // odd rows in [y0, y1): y1 / 2 - y0 / 2
  return odd * uint64_t(width) + (rows - odd) * uint64_t(width / 2);
}

// The pixel rows [r0, r1) of the band [y0, y1)'s blocks, within the frame.
CANOPY_HD inline void adaptiveBlockRows(int y0, int y1, int tileH, int height, int& r0, int& r1) {
  r0 = adaptiveBlockRowFirst(y0, tileH) * tileH;
  r1 = adaptiveBlockRowEnd(y1, tileH) * tileH;
  r1 = r1 < height ? r1 : height;
}

}  // namespace canopy::play
