// adaptive.h: adaptive sampling of a frame (canopy-play --adaptive TOL), per element, for the CPU
// reference and the CUDA kernels alike.
//
// The pixels with an even x and an even y (the lattice: a quarter of the frame) are traced first.
// Every other pixel lies in a 2x2-pixel cell whose four corners are lattice pixels (x0, y0),
// (x0 + 2, y0), (x0, y0 + 2), (x0 + 2, y0 + 2) with x0 = x & ~1, y0 = y & ~1. Where those four
// traced pixels differ by at most TOL in every channel (premultiplied linear RGBA: the colour, and
// the opacity, so an edge of a crown against the sky is never smoothed over), the pixel is their
// bilinear mean; elsewhere, and where the cell's corners are not all in the frame (the last row
// or column), it is traced too. A crown seen closer than the voxels' resolution at the frame's
// pixel size (docs/play.md, level of detail: every voxel wider than a pixel, as in a forest walked
// at eye level) is smooth within a cell except at its edges, which the test finds; the trace of
// the cells between them is what it saves. A filled pixel differs from its traced value only by
// what its cell's corners do not see (a feature narrower than two pixels between them;
// bench/RESULTS.md gives the measured RMS).
//
// A band of rows (tiles.h) traces the lattice rows its cells need, one or two beyond its own rows
// where its edge cuts a cell, so that the image does not depend on where the bands are.
// The order of the passes (lattice, then fill or mark, then the marked pixels' trace) needs no
// synchronisation inside a pass: a fill reads lattice pixels only and writes its own pixel.
#pragma once
#include <cmath>
#include <cstdint>

#include "canopy/hd.h"
#include "runtime/tiles.h"

namespace canopy::play {

CANOPY_HD inline bool adaptiveOnLattice(int x, int y) { return ((x | y) & 1) == 0; }

// The lattice's pixels that a band [y0, y1) of a frame `height` rows high traces, as warp tiles of
// the half-size grid (lattice column lx = x / 2, row ly = y / 2): columns [0, (width + 1) / 2),
// rows [y0 / 2, the row below the cell of the band's last row], within the frame.
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

// For a pixel (x, y) off the lattice, with its cell's corners traced into rgba (a frame of width x
// height pixels, 4 floats each): writes the bilinear mean of the corners and returns true where
// they agree within tol in every channel; false (the pixel is left alone): trace it.
CANOPY_HD inline bool adaptiveFill(float* rgba, int width, int height, int x, int y, float tol) {
  const int cx = x & ~1, cy = y & ~1;
  if (cx + 2 >= width || cy + 2 >= height) return false;
  const float* c00 = rgba + (int64_t(cy) * width + cx) * 4;
  const float* c10 = c00 + 8;
  const float* c01 = c00 + int64_t(width) * 8;
  const float* c11 = c01 + 8;
  for (int k = 0; k < 4; ++k) {
    const float lo = fminf(fminf(c00[k], c10[k]), fminf(c01[k], c11[k]));
    const float hi = fmaxf(fmaxf(c00[k], c10[k]), fmaxf(c01[k], c11[k]));
    if (!(hi - lo <= tol) || !(c00[k] + c10[k] + c01[k] + c11[k] == c00[k] + c10[k] + c01[k] + c11[k]))
      return false;  // (fminf and fmaxf drop a NaN: a NaN corner is traced around)
  }
  const float fx = (x & 1) ? 0.5f : 0.0f, fy = (y & 1) ? 0.5f : 0.0f;
  float* o = rgba + (int64_t(y) * width + x) * 4;
  for (int k = 0; k < 4; ++k) {
    const float top = c00[k] + fx * (c10[k] - c00[k]), bottom = c01[k] + fx * (c11[k] - c01[k]);
    o[k] = top + fy * (bottom - top);
  }
  return true;
}

}  // namespace canopy::play
