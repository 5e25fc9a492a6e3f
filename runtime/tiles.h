// tiles.h: one frame spread over several renderers (GPUs): the frame is cut into bands of whole
// rows, one per renderer, and the bands are moved after every frame so that each renderer's share
// of the last frame's cost is the same.
//
// Bands of rows rather than square tiles: stereo reprojection moves pixels along rows only
// (stereo.h), so each renderer reprojects its own band without its neighbours' pixels; and a band
// is one rectangle per renderer (one launch, one read-back).
#pragma once
#include <cstdint>
#include <vector>

#include "canopy/hd.h"

namespace canopy::play {

struct Band {
  int y0 = 0, y1 = 0;  // rows [y0, y1)
  int rows() const { return y1 - y0; }
};

// n bands of (nearly) equal height over `height` rows; every band has at least one row
// (n <= height), boundaries on multiples of `align` rows where the height allows.
std::vector<Band> equalBands(int height, int n, int align);

// The next frame's bands from this frame's and each band's measured cost (seconds, >= 0). The cost
// is taken as spread evenly over a band's rows; the new boundaries cut the total into equal shares
// (each boundary moving half way there, so that noise in one frame's times does not make the bands
// swing), on multiples of `align` rows, every band keeping at least one row (align rows where the
// height allows). Bands with no measured cost (all zero) are left as they are.
std::vector<Band> balanceBands(const std::vector<Band>& bands, const std::vector<double>& cost, int height, int align);

// A warp's tile by default: kDefaultWarpTileWidth x (32 / it) pixels, 4 wide and 8 tall
// (PlayOptions::warpTileWidth, Backend::setPixelTile; docs/performance.md, "Warp tiles").
constexpr int kDefaultWarpTileWidth = 4;

// Warp tiles (the CUDA kernels of render_cuda.cu): launch position j over a band -> its pixel
// (x, y). The band's rows [y0, y1) are cut into tiles of tileW x tileH pixels, tilesX of them per
// tile row; position j is lane j % (tileW tileH), row-major, of tile j / (tileW tileH). False for
// a position past the frame's width or the band's last row (a band's last tile row may reach into
// the next band's rows, which are not this band's to write).
CANOPY_HD inline bool bandTilePixel(int64_t j, int tilesX, int tileW, int tileH, int width, int y0, int y1, int& x, int& y) {
  const int64_t tile = j / (tileW * tileH);
  const int lane = int(j % (tileW * tileH));
  x = int(tile % tilesX) * tileW + lane % tileW;
  y = y0 + int(tile / tilesX) * tileH + lane / tileW;
  return x < width && y < y1;
}

}  // namespace canopy::play
