// adaptive_check.h: an adaptive frame (canopy-play --adaptive, runtime/adaptive.h) checked block by
// block against the full trace of the same view on the same backend (test_play_stereo.cpp on the
// CPU, test_play_cuda.cpp on the GPU).
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <vector>

#include "runtime/adaptive.h"

namespace canopy::play::testing {

// Every block of tileW x tileH pixels of the w x h frame `adaptive` (RGBA) against `full`: where
// the block passes adaptiveBlockAgrees on the full trace's lattice, its lattice pixels are the full
// trace's and its other pixels their cells' bilinear means of the full trace's corners, bit for
// bit; where it fails, every pixel is the full trace's, bit for bit. Returns the pixels filled
// (the passing blocks' off-lattice pixels), which the frame's report must count.
inline uint64_t expectAdaptiveBlocks(const std::vector<float>& adaptive, const std::vector<float>& full, int w, int h, int tileW, int tileH,
                                     float tol, int& passing, int& failing) {
  std::vector<float> mean = full;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (!adaptiveOnLattice(x, y) && (x & ~1) + 2 < w && (y & ~1) + 2 < h) adaptiveFillPixel(mean.data(), w, x, y);
  uint64_t filled = 0;
  passing = failing = 0;
  for (int by = 0; by * tileH < h; ++by)
    for (int bx = 0; bx * tileW < w; ++bx) {
      const bool passes = adaptiveBlockAgrees(full.data(), w, h, bx, by, tileW, tileH, tol);
      const std::vector<float>& want = passes ? mean : full;
      int wrong = 0;
      for (int y = by * tileH; y < std::min(h, (by + 1) * tileH); ++y)
        for (int x = bx * tileW; x < std::min(w, (bx + 1) * tileW); ++x) {
          const size_t i = (size_t(y) * w + x) * 4;
          wrong += std::memcmp(&adaptive[i], &want[i], 4 * sizeof(float)) != 0;
          filled += passes && !adaptiveOnLattice(x, y);
        }
      EXPECT_EQ(wrong, 0) << "block " << bx << "," << by << (passes ? " (filled)" : " (traced)") << " of " << tileW << "x" << tileH
                          << " in " << w << "x" << h;
      (passes ? passing : failing)++;
    }
  return filled;
}

}  // namespace canopy::play::testing
