// test_play_stereo.cpp: stereo pairs by reprojection (runtime/stereo.h), adaptive sampling
// (runtime/adaptive.h) and frames cut into bands over several renderers (runtime/tiles.h), on the
// CPU reference.
//
// The per-element reprojection is tested on hand-made rows whose answer is known (a wall moves by
// its disparity, an edge leaves a hole as wide as the disparity step, a spread or a translucent
// overlap is traced); the whole second eye against the same eye traced in full (its traced pixels
// bit for bit, the reprojected ones within a stated RMS); adaptive sampling's tests and fill per
// element and its frame against the full trace; bands against one band, bit for bit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "canopy/errors.h"
#include "formats/canopy_file.h"
#include "runtime/adaptive.h"
#include "runtime/image_io.h"
#include "runtime/player.h"
#include "runtime/stereo.h"
#include "runtime/tiles.h"
#include "tests/octreepack/synthetic.h"
#include "tests/play/adaptive_check.h"
#include "tests/play/resident.h"
#include "tests/play/scenes.h"
#include "tests/play/views.h"

namespace pl = canopy::play;
namespace pt = canopy::play::testing;
using canopy::Device;

namespace {

// One row of the traced eye: RGBA and layers per pixel (pixelLayers: front and back disparity,
// mean and spread; the front layer's RGBA).
struct Row {
  std::vector<float> rgba, layers;
  explicit Row(int w) : rgba(size_t(w) * 4, 0.0f), layers(size_t(w) * pl::kStereoPixelFloats, 0.0f) {}
  float* at(int x) { return layers.data() + size_t(x) * pl::kStereoPixelFloats; }
  // one layer: the front is the whole pixel, nothing behind it
  void set(int x, float value, float alpha, float d, float spread = 0.0f) {
    for (int c = 0; c < 3; ++c) rgba[size_t(4 * x + c)] = value * alpha;
    rgba[size_t(4 * x + 3)] = alpha;
    float* l = at(x);
    l[0] = d, l[1] = spread, l[2] = 0.0f, l[3] = 0.0f;
    for (int c = 0; c < 3; ++c) l[4 + c] = value * alpha;
    l[7] = alpha;
  }
  // two layers: a front of (value, alpha) at disparity d over a back of (backValue, backAlpha) at dBack
  void setLayers(int x, float value, float alpha, float d, float backValue, float backAlpha, float dBack) {
    set(x, value, alpha, d);
    for (int c = 0; c < 3; ++c) rgba[size_t(4 * x + c)] += (1.0f - alpha) * backValue * backAlpha;
    rgba[size_t(4 * x + 3)] += (1.0f - alpha) * backAlpha;
    at(x)[2] = dBack;
  }
};

// Reprojects one row on the CPU as the backends do (the nearest spans with max and count, then the
// spans behind them, then resolve); returns the hole mask and the right row. With `from`
// (stereoResolveHole, as the backends): a hole traced only behind its front is 2, from[x] its start.
std::vector<int> reprojectRow(const Row& row, int w, std::vector<float>& right, const pl::StereoParams& p = {},
                              std::vector<float>* from = nullptr) {
  std::vector<unsigned long long> keys(size_t(w), 0), behind(size_t(w), 0);
  std::vector<uint32_t> cover(size_t(w), 0);
  right.assign(size_t(w) * 4, -1.0f);
  const pl::StereoView v = pl::stereoView(row.rgba.data(), row.layers.data(), keys.data(), behind.data(), cover.data(), right.data(), w, p);
  for (int x = 0; x < w; ++x)
    pl::stereoSplatNearest(v, x, 0, [&](int64_t i, unsigned long long key, bool counts) {
      keys[size_t(i)] = std::max(keys[size_t(i)], key);
      cover[size_t(i)] += counts ? 1u : 0u;
    });
  for (int x = 0; x < w; ++x)
    pl::stereoSplatBehind(v, x, 0, [&](int64_t i, unsigned long long key) { behind[size_t(i)] = std::max(behind[size_t(i)], key); });
  std::vector<int> hole(static_cast<size_t>(w));
  if (from) from->assign(size_t(w), -1.0f);
  for (int x = 0; x < w; ++x) {
    if (!from) {
      hole[size_t(x)] = pl::stereoResolve(v, x, 0) ? 0 : 1;
      continue;
    }
    float* f = from->data() + x;
    hole[size_t(x)] = pl::stereoResolveHole(v, x, 0, f) ? 0 : (*f > 0.0f ? 2 : 1);
  }
  return hole;
}

// 12 synthetic plants on a 4 x 3 grid, 2.5 apart: crowns at several depths, sky between them.
const std::string& groveFile() {
  static const std::string path = [] {
    const std::string p = pt::tmpDir("stereo") + "/grove.canopy";
    std::vector<canopy::CanopyInstance> inst;
    for (int i = 0; i < 12; ++i)
      inst.push_back(pt::instanceAt(uint32_t(i % 2), float(i % 4) * 2.5f - 3.75f, 0, float(i / 4) * 2.5f - 2.5f, 1.0f, 0.5f * float(i)));
    pt::writeScene(p, {canopy::octreepack::testing::syntheticPlant(40, 0, "a", 4), canopy::octreepack::testing::syntheticPlant(32, 0, "b", 3)},
                   inst);
    return p;
  }();
  return path;
}

pl::PlayOptions groveView(int w, int h) { return pt::convergedView(groveFile(), w, h, "orbit:elevation=8,distance=9,fov=60"); }

// The grove's stereo pair (IPD 0.5) with every page resident, the ground under it and shadows off
// (the map is a backend's pass; nothing here depends on it): the scene's view and the two eyes.
struct GroveStereo {
  pl::PlayOptions o;
  pt::FrameView frame;
  const pl::ShadeParams& shade = frame.shade;
  const pl::SceneView& v = frame.v;
  pl::CameraView left{}, right{};
  float scale = 0.0f;  // the eyes' disparity scale

  GroveStereo(int w, int h) : o(withIpd(groveView(w, h))), frame(o) {
    pl::stereoEyes(frame.camera, o.stereoIpd, left, right);
    scale = pl::stereoDisparityScale(left, o.stereoIpd);
  }
  GroveStereo(const GroveStereo&) = delete;
  GroveStereo& operator=(const GroveStereo&) = delete;
  static pl::PlayOptions withIpd(pl::PlayOptions o) {
    o.stereoIpd = 0.5f;
    return o;
  }
};

}  // namespace

// ---------------------------------------------------------------------------------------------
// Bands (tiles.h)
// ---------------------------------------------------------------------------------------------

TEST(Tiles, EqualBandsCoverTheFrameOnAlignedRows) {
  const auto b = pl::equalBands(1080, 3, 4);
  ASSERT_EQ(b.size(), 3u);
  EXPECT_EQ(b[0].y0, 0);
  EXPECT_EQ(b[2].y1, 1080);
  for (size_t k = 0; k + 1 < b.size(); ++k) {
    EXPECT_EQ(b[k].y1, b[k + 1].y0);
    EXPECT_EQ(b[k].y1 % 4, 0);
    EXPECT_NEAR(b[k].rows(), 360, 4);
  }
  // more bands than aligned rows allow: every band keeps a row
  const auto tiny = pl::equalBands(5, 4, 4);
  ASSERT_EQ(tiny.size(), 4u);
  for (const auto& t : tiny) EXPECT_GE(t.rows(), 1);
  EXPECT_EQ(tiny.back().y1, 5);
  EXPECT_EQ(pl::equalBands(3, 8, 4).size(), 3u);  // never more bands than rows
}

// The CUDA kernels' launch positions over a band (tiles.h bandTilePixel): every pixel of the band
// exactly once, none outside it, for warp tiles of 8x4, 4x8 and 32x1 over bands whose last tile row
// reaches past the band (3 rows, 10 rows starting inside a tile row's span) and a width that is not
// a multiple of the tile's.
TEST(Tiles, WarpTilePositionsCoverTheBandOnce) {
  const int width = 37;
  for (const auto& [tw, th] : {std::pair<int, int>{8, 4}, {4, 8}, {32, 1}})
    for (const pl::Band band : {pl::Band{0, 3}, pl::Band{3, 13}, pl::Band{13, 40}}) {
      const int tilesX = (width + tw - 1) / tw, tilesY = (band.rows() + th - 1) / th;
      std::vector<int> hits(size_t(width) * 40, 0);
      for (int64_t j = 0; j < int64_t(tilesX) * tilesY * tw * th; ++j) {
        int x = -1, y = -1;
        if (!pl::bandTilePixel(j, tilesX, tw, th, width, band.y0, band.y1, x, y)) continue;
        ASSERT_TRUE(x >= 0 && x < width && y >= band.y0 && y < band.y1) << x << "," << y;
        ++hits[size_t(y) * width + x];
      }
      for (int y = 0; y < 40; ++y)
        for (int x = 0; x < width; ++x)
          ASSERT_EQ(hits[size_t(y) * width + x], y >= band.y0 && y < band.y1 ? 1 : 0) << tw << "x" << th << " " << x << "," << y;
    }
}

TEST(Tiles, BalancingConvergesToEqualSharesOfAnUnevenCost) {
  // A frame whose top 200 rows cost 10x the rest per row (sky below a crown, say); 3 renderers.
  const int height = 1080;
  auto rowCost = [](int y) { return y < 200 ? 10.0 : 1.0; };
  auto bandCost = [&](const pl::Band& b) {
    double c = 0;
    for (int y = b.y0; y < b.y1; ++y) c += rowCost(y);
    return c;
  };
  std::vector<pl::Band> bands = pl::equalBands(height, 3, 4);
  double total = 0;
  for (int y = 0; y < height; ++y) total += rowCost(y);
  std::vector<double> cost;
  for (int frame = 0; frame < 30; ++frame) {
    cost.clear();
    for (const auto& b : bands) cost.push_back(bandCost(b));
    bands = pl::balanceBands(bands, cost, height, 4);
    ASSERT_EQ(bands.front().y0, 0);
    ASSERT_EQ(bands.back().y1, height);
    for (size_t k = 0; k + 1 < bands.size(); ++k) ASSERT_EQ(bands[k].y1, bands[k + 1].y0);
  }
  for (const auto& b : bands) EXPECT_NEAR(bandCost(b) / total, 1.0 / 3.0, 0.02) << b.y0 << ".." << b.y1;
  // the first frame's split was far off: the top band held 2/3 of the cost
  EXPECT_GT(bandCost(pl::equalBands(height, 3, 4)[0]) / total, 0.6);
}

TEST(Tiles, BalancingWithoutMeasuredCostKeepsTheBandsAndNeverEmptiesOne) {
  const auto b = pl::equalBands(100, 4, 4);
  EXPECT_EQ(pl::balanceBands(b, {0, 0, 0, 0}, 100, 4)[1].y0, b[1].y0);
  // all the cost in the last band: the others shrink towards a tile row each, never to nothing
  std::vector<pl::Band> bands = b;
  for (int i = 0; i < 40; ++i) bands = pl::balanceBands(bands, {0, 0, 0, 1.0}, 100, 4);
  for (const auto& t : bands) EXPECT_GE(t.rows(), 4);
  EXPECT_EQ(bands.back().y1, 100);
}

TEST(Render, BandsOnSeveralRenderersGiveTheSameImageAsOne) {
  // Three bands, each its own renderer, cache and loader, rebalanced after every frame: converged
  // frames are the one-band frames bit for bit (every pixel is the same function of the scene).
  pl::PlayOptions o = groveView(64, 45);
  o.frames = 3;
  o.camera = "orbit:elevation=8,distance=9,fov=60,turns=0.1";
  std::vector<float> one, three;
  const nlohmann::json r1 = pl::play(o, Device{}, &one);
  o.tiles = 3;
  const nlohmann::json r3 = pl::play(o, Device{}, &three);
  ASSERT_EQ(r3["bands"].size(), 3u) << r3.dump();
  ASSERT_EQ(one.size(), three.size());
  EXPECT_EQ(std::memcmp(one.data(), three.data(), one.size() * sizeof(float)), 0) << "rms " << pt::imageRms(one, three);
  int rows = 0;
  for (const auto& b : r3["bands"]) rows += int(b["rows"][1]) - int(b["rows"][0]);
  EXPECT_EQ(rows, 45);
}

// ---------------------------------------------------------------------------------------------
// Reprojection, per element (stereo.h)
// ---------------------------------------------------------------------------------------------

TEST(Stereo, AnOpaqueWallMovesByItsDisparityAndLeavesTheFrameEdgeToTrace) {
  const int w = 32;
  Row row(w);
  for (int x = 0; x < w; ++x) row.set(x, 0.1f * float(x % 7), 1.0f, 3.0f);
  std::vector<float> right;
  const std::vector<int> hole = reprojectRow(row, w, right);
  for (int x = 0; x < w; ++x) {
    if (x + 3 < w) {
      ASSERT_EQ(hole[size_t(x)], 0) << x;
      for (int c = 0; c < 4; ++c) EXPECT_FLOAT_EQ(right[size_t(4 * x + c)], row.rgba[size_t(4 * (x + 3) + c)]) << x;
    } else {
      EXPECT_EQ(hole[size_t(x)], 1) << x;  // seen by the right eye only
    }
  }
}

TEST(Stereo, AStretchedSurfaceIsInterpolatedWithoutCracks) {
  // disparity falling by 0.5 px per pixel (a slanted surface): consecutive centres 1.5 px apart in
  // the right eye; every right pixel between them is covered and interpolated
  const int w = 24;
  Row row(w);
  for (int x = 0; x < w; ++x) row.set(x, float(x) / w, 1.0f, 12.0f - 0.5f * float(x));
  std::vector<float> right;
  const std::vector<int> hole = reprojectRow(row, w, right);
  int covered = 0;
  for (int x = 0; x < w; ++x) {
    if (hole[size_t(x)]) continue;
    ++covered;
    // the source position u between pixels: x + 1/2 = s + 1/2 - d(s) with d linear in s
    const float s = (float(x) + 12.0f) / 1.5f;  // x = s - (12 - s/2) = 1.5 s - 12
    EXPECT_NEAR(right[size_t(4 * x + 3)], 1.0f, 1e-6f);
    EXPECT_NEAR(right[size_t(4 * x)], s / w, 1e-5f) << x;
  }
  // the row maps onto right-eye x in [-12, 22.5]: columns 0..22 covered, 23 a hole (edge)
  EXPECT_EQ(covered, 23);
  EXPECT_EQ(hole[23], 1);
}

TEST(Stereo, TheRegionAnEdgeUncoversIsAHoleAsWideAsTheDisparityStep) {
  // background wall at disparity 2, foreground at disparity 10 on pixels [8, 16): in the right eye
  // the foreground covers [-2, 6), the background reappears at [14, 22) from pixels [16, 24) and at
  // [0, 14) from [2, 16) except where the foreground lies; right pixels [6, 14) see background that
  // the left eye's foreground hid: holes.
  const int w = 32;
  Row row(w);
  for (int x = 0; x < w; ++x) row.set(x, 0.25f, 1.0f, 2.0f);
  for (int x = 8; x < 16; ++x) row.set(x, 0.75f, 1.0f, 10.0f);
  std::vector<float> right;
  const std::vector<int> hole = reprojectRow(row, w, right);
  for (int x = 0; x < 6; ++x) EXPECT_FLOAT_EQ(right[size_t(4 * x)], 0.75f) << x;
  for (int x = 6; x < 14; ++x) EXPECT_EQ(hole[size_t(x)], 1) << x;
  for (int x = 14; x < 30; ++x) {
    EXPECT_EQ(hole[size_t(x)], 0) << x;
    EXPECT_FLOAT_EQ(right[size_t(4 * x)], 0.25f) << x;
  }
  EXPECT_EQ(hole[30], 1);
  EXPECT_EQ(hole[31], 1);
}

TEST(Stereo, SpreadPixelsAndTranslucentOverlapsAreTracedAndSkyIsNot) {
  const int w = 16;
  pl::StereoParams p;
  // a translucent crown (alpha 0.5, disparity 6) in front of sky: reprojected (nothing behind)
  Row sky(w);
  for (int x = 4; x < 10; ++x) sky.set(x, 0.6f, 0.5f, 6.0f);
  std::vector<float> right;
  std::vector<int> hole = reprojectRow(sky, w, right, p);
  // pixels 4..9 move to 0..3 (over sky the left eye saw there); the sky they hid is uncovered at 4..9
  for (int x = 0; x < w; ++x) EXPECT_EQ(hole[size_t(x)], x >= 4 && x < 10 ? 1 : 0) << x;
  EXPECT_FLOAT_EQ(right[size_t(4 * 0 + 3)], 0.5f);  // pixel 6 -> 0
  // the same crown in front of an opaque wall at disparity 2: the right eye sees the wall through
  // it. Where the left eye saw that part of the wall (right pixels 0 and 1: wall pixels 2 and 3,
  // behind crown pixels 6 and 7) it is composited behind the crown; where the crown hid it from the
  // left eye (2 and 3: wall at left pixels 4 and 5), traced.
  Row wall = sky;
  for (int x = 0; x < w; ++x)
    if (x < 4 || x >= 10) wall.set(x, 0.2f, 1.0f, 2.0f);
  hole = reprojectRow(wall, w, right, p);
  for (int x = 0; x < 2; ++x) {
    ASSERT_EQ(hole[size_t(x)], 0) << x;
    EXPECT_FLOAT_EQ(right[size_t(4 * x)], 0.6f * 0.5f + 0.5f * 0.2f) << x;
    EXPECT_FLOAT_EQ(right[size_t(4 * x + 3)], 1.0f) << x;
  }
  for (int x = 2; x < 4; ++x) EXPECT_EQ(hole[size_t(x)], 1) << x;
  // the crown's pixels hold the wall behind them as their back layer: then the right eye's view of
  // the wall through the crown is known everywhere; only the frame edge is traced
  Row layered = wall;
  for (int x = 4; x < 10; ++x) layered.setLayers(x, 0.6f, 0.5f, 6.0f, 0.2f, 1.0f, 2.0f);
  hole = reprojectRow(layered, w, right, p);
  for (int x = 0; x < w - 2; ++x) {
    ASSERT_EQ(hole[size_t(x)], 0) << x;
    const bool crown = x < 4;  // crown pixels 4..9 land on right pixels 0..3
    EXPECT_NEAR(right[size_t(4 * x)], crown ? 0.6f * 0.5f + 0.5f * 0.2f : 0.2f, 1e-6f) << x;
    EXPECT_NEAR(right[size_t(4 * x + 3)], 1.0f, 1e-6f) << x;
  }
  EXPECT_EQ(hole[size_t(w - 2)], 1);
  EXPECT_EQ(hole[size_t(w - 1)], 1);
  // a translucent front layer behind the crown that has matter behind it in its own pixel: traced
  Row deep = wall;
  for (int x = 0; x < 4; ++x) deep.setLayers(x, 0.2f, 0.5f, 2.0f, 0.9f, 1.0f, 1.0f);
  hole = reprojectRow(deep, w, right, p);
  for (int x = 0; x < 2; ++x) EXPECT_EQ(hole[size_t(x)], 1) << x;
  // a crown pixel that holds matter behind the crown too (spread): the right eye may see that matter
  // through the crown next to it
  Row hidden = sky;
  hidden.set(5, 0.6f, 0.7f, 5.0f, 2.0f);
  hole = reprojectRow(hidden, w, right, p);
  for (int x = 0; x < 4; ++x) EXPECT_EQ(hole[size_t(x)], 1) << x;  // pixel 5 lies between each and its source
  // a pixel whose samples spread over more than maxSpread pixels of disparity: traced
  Row spread(w);
  for (int x = 0; x < w; ++x) spread.set(x, 0.3f, 1.0f, 1.0f, x == 8 ? 2.0f : 0.1f);
  hole = reprojectRow(spread, w, right, p);
  EXPECT_EQ(hole[7], 1);  // pixel 8 -> 7: its spans are traced
  EXPECT_EQ(hole[5], 0);
  p.maxSpread = 3.0f;
  hole = reprojectRow(spread, w, right, p);
  EXPECT_EQ(hole[7], 0);
}

TEST(Stereo, ALayerJustBehindItsFrontIsCompositedAndAPixelSolidThroughItsBackHidesWhatIsBehindIt) {
  const int w = 16;
  std::vector<float> right;
  // crown pixels 4..9: a front (0.6, alpha 0.5, disparity 6) over their own solid back only 0.7 px
  // behind it (less than maxJump): the right eye sees the crown over that back
  Row near(w);
  for (int x = 4; x < 10; ++x) near.setLayers(x, 0.6f, 0.5f, 6.0f, 0.2f, 1.0f, 5.3f);
  std::vector<int> hole = reprojectRow(near, w, right);
  for (int x = 0; x < 4; ++x) {
    ASSERT_EQ(hole[size_t(x)], 0) << x;
    EXPECT_NEAR(right[size_t(4 * x)], 0.6f * 0.5f + 0.5f * 0.2f, 1e-6f) << x;
    EXPECT_NEAR(right[size_t(4 * x + 3)], 1.0f, 1e-6f) << x;
  }
  // a wall at disparity 1 behind a translucent crown at pixels 12, 13 (disparity 12, landing on right
  // pixels 0, 1), and at pixel 5 a translucent front over a solid back (disparity 7 and 6.8): the
  // right eye's rays at 0 and 1 cross column 5 behind that pixel, where the left eye saw nothing:
  // traced, as behind a solid front
  Row pole(w);
  for (int x = 0; x < w; ++x) pole.set(x, 0.2f, 1.0f, 1.0f);
  pole.set(12, 0.6f, 0.5f, 12.0f);
  pole.set(13, 0.6f, 0.5f, 12.0f);
  pole.setLayers(5, 0.1f, 0.5f, 7.0f, 0.9f, 1.0f, 6.8f);
  hole = reprojectRow(pole, w, right);
  EXPECT_EQ(hole[0], 1);
  EXPECT_EQ(hole[1], 1);
  Row solid = pole;
  solid.set(5, 0.9f, 1.0f, 7.0f);
  hole = reprojectRow(solid, w, right);
  EXPECT_EQ(hole[0], 1);
  EXPECT_EQ(hole[1], 1);
}

TEST(Stereo, ATranslucentSurfaceWithUnknownMatterBehindIsTracedOnlyBehindItsFront) {
  const int w = 16;
  // crown pixels 4..9: a front (0.6, alpha 0.5, disparity 6, its far side at disparity 5) over a
  // back layer that spreads (disparity 2, spread 2: trees at many depths): the right eye's pixels
  // 0..3 (front pairs from pixels 6..9) see the front, and behind it matter the left eye cannot
  // place
  Row crown(w);
  for (int x = 4; x < 10; ++x) {
    crown.setLayers(x, 0.6f, 0.5f, 6.0f, 0.2f, 1.0f, 2.0f);
    crown.at(x)[3] = 2.0f;
    crown.at(x)[8] = 5.0f;
  }
  std::vector<float> right, from;
  // stereoResolve (no behind fill): holes, nothing written
  std::vector<int> hole = reprojectRow(crown, w, right);
  for (int x = 0; x < 4; ++x) {
    EXPECT_EQ(hole[size_t(x)], 1) << x;
    EXPECT_EQ(right[size_t(4 * x + 3)], -1.0f) << x;
  }
  // the backends' resolve: traced only behind the front, from its far side, the front written;
  // but at right pixel 3, the crown's edge (pixel 9's own half width, no pair): traced in full
  hole = reprojectRow(crown, w, right, {}, &from);
  EXPECT_EQ(hole[3], 1);
  for (int x = 0; x < 3; ++x) {
    ASSERT_EQ(hole[size_t(x)], 2) << x;
    EXPECT_EQ(from[size_t(x)], 5.0f) << x;
    EXPECT_FLOAT_EQ(right[size_t(4 * x)], 0.6f * 0.5f) << x;
    EXPECT_FLOAT_EQ(right[size_t(4 * x + 3)], 0.5f) << x;
  }
  // the far side interpolated along the pair span, as the colour: pixel 7's far side at 4.5, and
  // pixel 8's front a little denser (within the alpha gate)
  crown.at(7)[8] = 4.5f;
  hole = reprojectRow(crown, w, right, {}, &from);
  EXPECT_EQ(from[0], 5.0f);  // right centre 0.5: the pair (6, 7) at pixel 6's centre
  EXPECT_EQ(from[1], 4.5f);  // right centre 1.5: the pair (7, 8) at pixel 7's centre
  Row slanted(w);            // a surface whose disparity falls by 0.5 px per pixel: centres between pixels
  for (int x = 4; x < 10; ++x) {
    const float d = 6.0f - 0.5f * float(x - 4);
    slanted.setLayers(x, 0.6f, x == 8 ? 0.55f : 0.5f, d, 0.2f, 1.0f, 1.0f);
    slanted.at(x)[3] = 2.0f;
    slanted.at(x)[8] = d - 1.0f;
  }
  hole = reprojectRow(slanted, w, right, {}, &from);
  // right pixel 2 (centre 2.5): pixel 7 lands at 7.5 - 4.5 = 3.0, pixel 6 at 6.5 - 5 = 1.5: the pair
  // (6, 7) at u = 2/3
  ASSERT_EQ(hole[2], 2);
  EXPECT_NEAR(from[2], 4.0f - 0.5f * (2.0f / 3.0f), 1e-5f);
  EXPECT_NEAR(right[4 * 2 + 3], 0.5f, 1e-6f);
  // right pixel 4 (centre 4.5): pixel 8 lands at 8.5 - 4 = 4.5, its own centre (alpha 0.55)
  ASSERT_EQ(hole[4], 2);
  EXPECT_NEAR(right[4 * 4 + 3], 0.55f, 1e-6f);
  EXPECT_NEAR(from[4], 3.0f, 1e-5f);
  // fronts that differ in alpha by more than kStereoBehindAlphaStep: neither is the right eye's front
  Row uneven = crown;
  uneven.set(7, 0.6f, 0.5f + 2.0f * pl::kStereoBehindAlphaStep, 6.0f);
  uneven.at(7)[2] = 2.0f, uneven.at(7)[3] = 2.0f, uneven.at(7)[8] = 5.0f;
  hole = reprojectRow(uneven, w, right, {}, &from);
  EXPECT_EQ(hole[0], 1);  // the pair (6, 7)
  EXPECT_EQ(hole[1], 1);  // the pair (7, 8)
  EXPECT_EQ(hole[2], 2);  // the pair (8, 9)
  // a front that never opened (its far side not known): traced in full
  Row faint = crown;
  for (int x = 4; x < 10; ++x) faint.at(x)[8] = 0.0f;
  hole = reprojectRow(faint, w, right, {}, &from);
  for (int x = 0; x < 3; ++x) EXPECT_EQ(hole[size_t(x)], 1) << x;
}

TEST(Stereo, TheTracedEyesFrontLayerNeverSpreadsAndTheLayersGiveThePixelBack) {
  // The grove's traced eye (every page resident, the ground under it): per covered pixel the front
  // layer spans 2 x --stereo-spread px of disparity from its opening sample, so it spreads at most
  // --stereo-spread but for the faint samples before that one; the back layer lies behind it; the
  // front layer is a share of the pixel.
  const GroveStereo g(96, 54);
  const pl::PlayOptions& o = g.o;
  ASSERT_FLOAT_EQ(g.shade.stereoLayer, 2.0f * o.stereo.maxSpread);
  const pl::CameraView& left = g.left;
  const int64_t n = int64_t(left.width) * left.height;
  std::vector<float> rgba(size_t(n) * 4), layers(size_t(n) * pl::kStereoPixelFloats);
  int covered = 0, split = 0, wide = 0;
  for (int64_t i = 0; i < n; ++i) {
    pl::renderPixel(g.v, left, i, rgba.data(), layers.data(), g.scale);
    const float* px = rgba.data() + 4 * i;
    const float* l = layers.data() + pl::kStereoPixelFloats * i;
    if (px[3] < o.stereo.faintAlpha) continue;
    ++covered;
    wide += l[1] > o.stereo.maxSpread * 1.001f ? 1 : 0;        // the front layer's spread
    ASSERT_LE(l[7], px[3] + 1e-6f) << i;                       // its alpha, a share of the pixel's
    for (int c = 0; c < 3; ++c) ASSERT_LE(l[4 + c], px[c] + 1e-6f) << i;
    if (px[3] - l[7] < 0.01f) continue;
    ++split;
    // the back layer lies behind the front's far side, which lies behind the front's mean (by no
    // set margin: the front's mean may lie near its far side)
    EXPECT_LT(l[2], l[8]) << i;
    EXPECT_LE(l[8], l[0]) << i;
  }
  std::printf("grove traced eye: %d covered pixels, %d with a back layer, %d front layers spread wider\n", covered, split, wide);
  EXPECT_GT(covered, int(n / 2));
  EXPECT_LE(wide, covered / 100);  // faint samples before the opening one: 1 of 3264 measured (2026-12-04)
  EXPECT_GT(split, covered / 50);  // crowns in front of crowns and of the ground: 4.0 % measured (2026-12-04)
}

TEST(Stereo, AHoleTracedBehindItsFrontAddsWhatTheRayMeetsFromThereOn) {
  // The grove's right eye (every page resident, the ground under it): a hole traced behind a front
  // F from a depth in front of all matter is F over the full trace (the same march, with what F
  // lets through: it stops where the whole ray's transmittance falls below --stop-opacity's, so
  // within that of F + (1 - F alpha) x full; bit for bit where F is empty); from behind all matter
  // (or under the ground) it is F alone.
  // Steps that grow behind dense matter (--step-growth) follow the whole ray's transmittance, front
  // included, so behind F they grow earlier than in the full trace: off here, where the identity
  // is the march's.
  const GroveStereo g(64, 36);
  pl::SceneView v = g.v;
  v.shade.stepGrowthT = 0.0f;
  const pl::CameraView& right = g.right;
  const float scale = g.scale;
  const int64_t n = int64_t(right.width) * right.height;
  const float front[4] = {0.05f, 0.1f, 0.02f, 0.4f};
  std::vector<float> full(size_t(n) * 4), near(size_t(n) * 4), clear(size_t(n) * 4, 0.0f), far(size_t(n) * 4);
  std::vector<float> fromNear(size_t(n), scale / 0.5f), fromFar(size_t(n), scale / 1.0e4f);  // depths 0.5 and 10 km
  for (int64_t i = 0; i < n; ++i) {
    for (int c = 0; c < 4; ++c) near[size_t(4 * i + c)] = far[size_t(4 * i + c)] = front[c];
    pl::renderPixel(v, right, i, full.data());
    pl::renderPixel(v, right, i, near.data(), nullptr, scale, fromNear.data());
    pl::renderPixel(v, right, i, clear.data(), nullptr, scale, fromNear.data());
    pl::renderPixel(v, right, i, far.data(), nullptr, scale, fromFar.data());
  }
  const float stopT = g.o.stopTransmittance;
  int covered = 0, underGround = 0;
  for (int64_t i = 0; i < n; ++i) {
    covered += full[size_t(4 * i + 3)] > 0.02f ? 1 : 0;
    float fp;
    const pl::V3 d = pl::cameraRay(right, int(i % right.width), int(i / right.width), fp);
    underGround += pl::groundHit(v.shade, right.position, d) < 1.0e4f ? 1 : 0;  // far: the ground before the start
    for (int c = 0; c < 4; ++c) {
      ASSERT_EQ(clear[size_t(4 * i + c)], full[size_t(4 * i + c)]) << i << " " << c;
      ASSERT_NEAR(near[size_t(4 * i + c)], front[c] + (1.0f - front[3]) * full[size_t(4 * i + c)], 1.0e-5f + stopT) << i << " " << c;
      ASSERT_FLOAT_EQ(far[size_t(4 * i + c)], front[c]) << i << " " << c;  // alpha: 1 - (1 - a)
    }
  }
  EXPECT_GT(covered, int(n / 2));  // crowns and the ground: the march behind the front was not empty
  // far took both ways: rays under the ground before their start, and rays marched from 10 km
  EXPECT_GT(underGround, 0);
  EXPECT_LT(underGround, int(n));
}

// Stereo's kernels come in three path sets (stereoPaths): "every path" (the far field, the detail
// levels, the descent table) must march a frame that uses none of them as the others do. The grove's
// pair with a far field present but never reached (its start off), against the same view without
// one: the traced eye's RGBA and layers and the holes' RGBA (traced in full, and behind a front at
// 0.5 m) bit for bit.
TEST(Stereo, TheEveryPathSetOfTheStereoKernelsMarchesAFrameWithoutThosePathsAlike) {
  const GroveStereo g(64, 36);
  pl::SceneView all = g.v;
  std::vector<float> unread(pl::kFarFieldChannels, 0.0f);
  all.far.values = unread.data();  // present, so scenePaths has kPathFar; never read with the start off
  all.shade.farStart = -1.0f;
  ASSERT_EQ(pl::stereoPaths(pl::scenePaths(all)), pl::kAllPaths);
  ASSERT_NE(pl::stereoPaths(pl::scenePaths(g.v)), pl::kAllPaths);
  const int64_t n = int64_t(g.left.width) * g.left.height;
  std::vector<float> rgba(size_t(n) * 4), rgbaAll(size_t(n) * 4), layers(size_t(n) * pl::kStereoPixelFloats),
      layersAll(size_t(n) * pl::kStereoPixelFloats);
  const float front[4] = {0.05f, 0.1f, 0.02f, 0.4f};
  std::vector<float> holes(size_t(n) * 4), holesAll(size_t(n) * 4), from(static_cast<size_t>(n), 0.0f);
  int covered = 0;
  for (int64_t i = 0; i < n; ++i) {
    pl::renderPixel(g.v, g.left, i, rgba.data(), layers.data(), g.scale);
    pl::renderPixel(all, g.left, i, rgbaAll.data(), layersAll.data(), g.scale);
    covered += rgba[size_t(4 * i + 3)] > 0.02f ? 1 : 0;
    from[size_t(i)] = i % 2 ? g.scale / 0.5f : 0.0f;  // behind a front at 0.5 m, or traced in full
    for (int c = 0; c < 4; ++c) holes[size_t(4 * i + c)] = holesAll[size_t(4 * i + c)] = i % 2 ? front[c] : 0.0f;
    pl::renderPixel(g.v, g.right, i, holes.data(), nullptr, g.scale, from.data());
    pl::renderPixel(all, g.right, i, holesAll.data(), nullptr, g.scale, from.data());
  }
  EXPECT_GT(covered, int(n / 2));
  EXPECT_EQ(std::memcmp(rgba.data(), rgbaAll.data(), rgba.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(layers.data(), layersAll.data(), layers.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(holes.data(), holesAll.data(), holes.size() * sizeof(float)), 0);
}

TEST(Stereo, PixelDisparityIsTheWeightedMeanAndSpreadOfInverseDepth) {
  // two samples of equal weight at t = 2 and t = 4 on the axis: 1/z = 0.5 and 0.25
  const float sums[3] = {1.0f, 0.5f * 0.5f + 0.5f * 0.25f, 0.5f * 0.25f + 0.5f * 0.0625f};
  float out[2];
  pl::pixelDisparity(sums, 1.0f, 100.0f, out);
  EXPECT_NEAR(out[0], 37.5f, 1e-4f);
  EXPECT_NEAR(out[1], 12.5f, 1e-3f);
  const float none[3] = {0, 0, 0};
  pl::pixelDisparity(none, 1.0f, 100.0f, out);
  EXPECT_EQ(out[0], 0.0f);
  EXPECT_EQ(out[1], 0.0f);
}

// ---------------------------------------------------------------------------------------------
// The second eye, whole (player)
// ---------------------------------------------------------------------------------------------

// The halves the CUDA backend lists the holes in (stereoHoleHalf): one in tile order; in kind
// order the holes traced in full first, those traced behind a front after them.
TEST(Stereo, HoleHalvesPutTheHolesTracedInFullFirst) {
  EXPECT_EQ(pl::stereoHoleHalf(pl::kHoleOrderTile, false), 0);
  EXPECT_EQ(pl::stereoHoleHalf(pl::kHoleOrderTile, true), 0);
  EXPECT_EQ(pl::stereoHoleHalf(pl::kHoleOrderKind, false), 0);
  EXPECT_EQ(pl::stereoHoleHalf(pl::kHoleOrderKind, true), 1);
}

TEST(Render, ReprojectedEyeMatchesTheTracedEyeAndTracesOnlyItsHoles) {
  // The grove at 160x90 from 9 m with a 0.5 m eye separation (a large one: 8 px of disparity at
  // 9 m, so that edges uncover real holes at this size).
  pl::PlayOptions o = groveView(160, 90);
  o.stereoIpd = 0.5f;
  std::vector<float> left, right, leftRef, rightRef;
  const nlohmann::json r = pl::play(o, Device{}, &left, &right);
  o.stereoFill = "trace";
  const nlohmann::json rt = pl::play(o, Device{}, &leftRef, &rightRef);
  // the traced eye is the same either way (recording the disparity does not change a bit)
  ASSERT_EQ(left.size(), leftRef.size());
  EXPECT_EQ(std::memcmp(left.data(), leftRef.data(), left.size() * sizeof(float)), 0);
  const double traced = double(r["stereo"]["traced_fraction_mean"]);
  EXPECT_GT(traced, 0.0);
  EXPECT_LT(traced, 0.5) << r["stereo"].dump();
  EXPECT_DOUBLE_EQ(double(rt["stereo"]["traced_fraction_mean"]), 1.0);
  // The reprojected eye against the traced one: premultiplied RGBA RMS (values in [0, 1]). Measured
  // 2026-12-04 on this scene: 5.3 % of the pixels traced, RMS 0.0042 with two layers per pixel
  // (6.0 % and 0.0097 with one); bounds at about 1.5x.
  const double e = pt::imageRms(right, rightRef);
  const double behind = double(r["stereo"]["traced_behind_fraction_mean"]);
  std::printf("reprojected right eye: traced %.3f of the pixels (%.4f behind a reprojected front), RMS %.5f against the traced eye\n", traced,
              behind, e);
  EXPECT_GT(behind, 0.0);  // 0.6 % measured (2026-12-05)
  EXPECT_LT(behind, traced);
  EXPECT_LT(traced, 0.08);
  EXPECT_LT(e, 0.0065);
  // and it is a different picture from the left eye (the reprojection moved things)
  EXPECT_GT(pt::imageRms(right, left), 2.0 * e);
  // the second eye's time splits into the reprojection and the holes' trace (none without holes)
  const double reproject = r["stereo"]["reproject_ms_median"], second = r["stereo"]["second_eye_ms_median"];
  EXPECT_GT(reproject, 0.0);
  EXPECT_LE(reproject, second);
  EXPECT_DOUBLE_EQ(double(rt["stereo"]["reproject_ms_median"]), 0.0);
}

// Stereo's kernels are compiled per path set (cone.h renderPixelOfPaths, stereoPaths): the traced
// eye's and the holes' with the descent tables (the default) and without them give both eyes bit
// for bit alike, and the reprojection traces the same holes.
TEST(Render, StereoPairIsTheSameWithAndWithoutTheDescentTables) {
  pl::PlayOptions o = groveView(160, 90);
  o.stereoIpd = 0.5f;
  o.countWork = true;
  std::vector<float> left, right, leftRoot, rightRoot;
  const nlohmann::json r = pl::play(o, Device{}, &left, &right);
  EXPECT_GT(double(r["work"]["table_descents"]), 0.0);  // the tables served descents
  o.descentTable = false;
  const nlohmann::json rr = pl::play(o, Device{}, &leftRoot, &rightRoot);
  ASSERT_EQ(left.size(), leftRoot.size());
  ASSERT_EQ(right.size(), rightRoot.size());
  EXPECT_EQ(std::memcmp(left.data(), leftRoot.data(), left.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(right.data(), rightRoot.data(), right.size() * sizeof(float)), 0);
  EXPECT_GT(double(r["stereo"]["traced_fraction_mean"]), 0.0);  // holes were traced (the holes' kernel ran)
  EXPECT_DOUBLE_EQ(double(r["stereo"]["traced_fraction_mean"]), double(rr["stereo"]["traced_fraction_mean"]));
  EXPECT_EQ(double(rr["work"]["table_descents"]), 0.0);
}

TEST(Render, StereoSideBySideAndSeparateOutputs) {
  pl::PlayOptions o = groveView(32, 18);
  o.stereoIpd = 0.1f;
  o.output = pt::tmpDir("stereo") + "/pair.exr";
  std::vector<float> left, right;
  pl::play(o, Device{}, &left, &right);
  int w = 0, h = 0;
  const std::vector<float> sbs = pl::readExrRgba(o.output, w, h);
  EXPECT_EQ(w, 64);
  EXPECT_EQ(h, 18);
  // the left half is the left eye, the right half the right eye (EXR: half floats)
  for (int y = 0; y < h; y += 5)
    for (int x = 0; x < 32; x += 3)
      for (int c = 0; c < 4; ++c) {
        EXPECT_NEAR(sbs[size_t(4 * (y * 64 + x) + c)], left[size_t(4 * (y * 32 + x) + c)], 2e-3f);
        EXPECT_NEAR(sbs[size_t(4 * (y * 64 + 32 + x) + c)], right[size_t(4 * (y * 32 + x) + c)], 2e-3f);
      }
  o.output = pt::tmpDir("stereo") + "/left.png";
  o.rightOutput = pt::tmpDir("stereo") + "/right.png";
  pl::play(o, Device{});
  pl::readPngRgb(o.output, w, h);
  EXPECT_EQ(w, 32);
  pl::readPngRgb(o.rightOutput, w, h);
  EXPECT_EQ(w, 32);
  // --right-output without --stereo is a usage error
  o.stereoIpd = 0.0f;
  try {
    pl::play(o, Device{});
    FAIL() << "expected a usage error";
  } catch (const canopy::Error& e) {
    EXPECT_EQ(e.code(), canopy::ExitCode::Usage) << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Adaptive sampling (adaptive.h)
// ---------------------------------------------------------------------------------------------

TEST(Adaptive, ACellAgreesWithinTheToleranceInEveryChannelAndFillsWithTheBilinearMean) {
  const int w = 5, h = 5;
  std::vector<float> img(size_t(w) * h * 4, -1.0f);  // -1: not written
  auto px = [&](int x, int y) { return img.data() + (size_t(y) * w + x) * 4; };
  auto set = [&](int x, int y, float v, float a) { float* p = px(x, y); p[0] = p[1] = p[2] = v, p[3] = a; };
  // the cell (0, 0)-(2, 2): corners 0.2, 0.3, 0.4, 0.5 (alpha 1)
  set(0, 0, 0.2f, 1.0f), set(2, 0, 0.3f, 1.0f), set(0, 2, 0.4f, 1.0f), set(2, 2, 0.5f, 1.0f);
  EXPECT_FALSE(pl::adaptiveCellAgrees(img.data(), w, h, 0, 0, 0.29f));  // 0.3 apart
  EXPECT_TRUE(pl::adaptiveCellAgrees(img.data(), w, h, 0, 0, 0.3f));
  pl::adaptiveFillPixel(img.data(), w, 1, 1);
  EXPECT_FLOAT_EQ(px(1, 1)[0], 0.35f);  // the four corners' mean
  EXPECT_FLOAT_EQ(px(1, 1)[3], 1.0f);
  pl::adaptiveFillPixel(img.data(), w, 1, 0);
  EXPECT_FLOAT_EQ(px(1, 0)[0], 0.25f);  // on a lattice row: between its two neighbours
  pl::adaptiveFillPixel(img.data(), w, 0, 1);
  EXPECT_FLOAT_EQ(px(0, 1)[0], 0.3f);
  // the opacity counts as a channel: a crown's edge against the sky is traced
  set(2, 2, 0.5f, 0.5f);
  EXPECT_FALSE(pl::adaptiveCellAgrees(img.data(), w, h, 0, 0, 0.3f));
  EXPECT_TRUE(pl::adaptiveCellAgrees(img.data(), w, h, 0, 0, 0.5f));
  // a NaN corner fails its cell
  px(2, 2)[1] = std::nanf("");
  EXPECT_FALSE(pl::adaptiveCellAgrees(img.data(), w, h, 0, 0, 1e30f));
  // a cell not whole in the frame (the last column and row of a 4 x 4 frame) fails
  std::vector<float> flat(size_t(4) * 4 * 4, 0.25f);
  EXPECT_TRUE(pl::adaptiveCellAgrees(flat.data(), 4, 4, 0, 0, 0.0f));
  EXPECT_FALSE(pl::adaptiveCellAgrees(flat.data(), 4, 4, 2, 0, 1.0f));
  EXPECT_FALSE(pl::adaptiveCellAgrees(flat.data(), 4, 4, 0, 2, 1.0f));
}

TEST(Adaptive, ABlockPassesOnlyWhereEveryCellOfItsOffLatticePixelsAgrees) {
  // A 17 x 13 frame of lattice values that agree everywhere but at one corner, moved around: a
  // block fails exactly where one of its off-lattice pixels has that corner in its cell (checked
  // against the per-pixel rule), and blocks at the last column or row, whose cells are not whole.
  const int w = 17, h = 13;
  for (const int tileW : {1, 2, 4, 8, 16, 32}) {
    const int tileH = 32 / tileW;
    for (const int bad : {0, 2 * w + 4, 4 * w + 8, 6 * w + 14, 12 * w + 16}) {
      std::vector<float> img(size_t(w) * h * 4, 0.5f);
      for (int k = 0; k < 4; ++k) img[size_t(bad) * 4 + k] = 0.9f;
      const int bx0 = bad % w, by0 = bad / w;
      ASSERT_TRUE(pl::adaptiveOnLattice(bx0, by0));
      for (int by = 0; by * tileH < h; ++by)
        for (int bx = 0; bx * tileW < w; ++bx) {
          bool expect = true;
          for (int y = by * tileH; y < std::min(h, (by + 1) * tileH); ++y)
            for (int x = bx * tileW; x < std::min(w, (bx + 1) * tileW); ++x) {
              if (pl::adaptiveOnLattice(x, y)) continue;
              const int cx = x & ~1, cy = y & ~1;
              const bool whole = cx + 2 < w && cy + 2 < h;
              const bool hasBad = (bx0 == cx || bx0 == cx + 2) && (by0 == cy || by0 == cy + 2);
              expect = expect && whole && !hasBad;
            }
          EXPECT_EQ(pl::adaptiveBlockAgrees(img.data(), w, h, bx, by, tileW, tileH, 0.1f), expect)
              << "tile " << tileW << "x" << tileH << " bad " << bx0 << "," << by0 << " block " << bx << "," << by;
        }
    }
  }
}

TEST(Adaptive, OffLatticeCountsEveryPixelOffTheLattice) {
  for (const int w : {1, 2, 7, 8})
    for (int y0 = 0; y0 < 6; ++y0)
      for (int y1 = y0 + 1; y1 < 10; ++y1) {
        uint64_t n = 0;
        for (int y = y0; y < y1; ++y)
          for (int x = 0; x < w; ++x) n += !pl::adaptiveOnLattice(x, y);
        EXPECT_EQ(pl::adaptiveOffLattice(w, y0, y1), n) << w << " [" << y0 << "," << y1 << ")";
      }
}

TEST(Adaptive, EachBandTracesTheLatticeOfItsCellsAndOfItsBlocksTests) {
  // Every off-lattice pixel of a band whose cell is whole in the frame has its four corners among
  // the lattice pixels that band traces, no lattice pixel is traced twice by one band, and every
  // block the band tests (its block rows, which a band edge off a multiple of tileH cuts) reads
  // only pixels the band traced: the test on a frame where the others are NaN gives the answer of
  // a frame traced everywhere (every cell whole in the frame passes).
  for (const int height : {10, 11, 45, 90})
    for (const int width : {13, 16})
      for (const int tileW : {1, 4, 8}) {
        const int tileH = 32 / tileW;
        const int n = std::max(2, height / 3);  // n tileH > height: bands on single rows (tiles.h)
        for (const std::vector<pl::Band>& bands : {pl::equalBands(height, 1, tileH), pl::equalBands(height, 3, tileH), pl::equalBands(height, 4, 1),
                                                   pl::equalBands(height, n, tileH)}) {
          for (const pl::Band& b : bands) {
            int r0 = 0, r1 = 0;
            pl::adaptiveBlockRows(b.y0, b.y1, tileH, height, r0, r1);
            const int tilesX = (pl::adaptiveLatticeWidth(width) + tileW - 1) / tileW;
            const int rows = pl::adaptiveLatticeEnd(r1, height) - pl::adaptiveLatticeFirst(r0);
            const int64_t positions = int64_t(tilesX) * ((rows + tileH - 1) / tileH) * tileW * tileH;
            std::vector<int> traced(size_t(width) * height, 0);
            std::vector<float> seen(size_t(width) * height * 4, std::nanf("")), all(size_t(width) * height * 4, 0.5f);
            for (int64_t j = 0; j < positions; ++j) {
              int x = -1, y = -1;
              if (!pl::adaptiveLatticePixel(j, tilesX, tileW, tileH, width, r0, r1, height, x, y)) continue;
              ASSERT_TRUE(x >= 0 && x < width && y >= 0 && y < height && pl::adaptiveOnLattice(x, y)) << x << "," << y;
              ++traced[size_t(y) * width + x];
              for (int k = 0; k < 4; ++k) seen[(size_t(y) * width + x) * 4 + k] = 0.5f;
            }
            for (int y = b.y0; y < b.y1; ++y)
              for (int x = 0; x < width; ++x) {
                if (pl::adaptiveOnLattice(x, y)) {
                  EXPECT_EQ(traced[size_t(y) * width + x], 1) << height << ": " << x << "," << y;
                  continue;
                }
                const int cx = x & ~1, cy = y & ~1;
                if (cx + 2 >= width || cy + 2 >= height) continue;
                for (int c = 0; c < 4; ++c)
                  EXPECT_EQ(traced[size_t(cy + 2 * (c / 2)) * width + cx + 2 * (c % 2)], 1) << height << " band " << b.y0 << ": " << x << "," << y;
              }
            for (int by = pl::adaptiveBlockRowFirst(b.y0, tileH); by < pl::adaptiveBlockRowEnd(b.y1, tileH); ++by)
              for (int bx = 0; bx * tileW < width; ++bx)
                EXPECT_EQ(pl::adaptiveBlockAgrees(seen.data(), width, height, bx, by, tileW, tileH, 0.1f),
                          pl::adaptiveBlockAgrees(all.data(), width, height, bx, by, tileW, tileH, 0.1f))
                    << width << "x" << height << " tile " << tileW << " band [" << b.y0 << "," << b.y1 << ") block " << bx << "," << by;
          }
        }
      }
}

TEST(Render, AdaptiveSamplingFillsOrTracesEachBlockAsItsTestSays) {
  // The grove: the lattice (a quarter) plus the blocks whose cells' corners differ, against every
  // pixel traced; each block is either the full trace's bit for bit or its cells' bilinear means of
  // the full trace's corners, as adaptiveBlockAgrees on the full trace says (expectAdaptiveBlocks),
  // and the report counts the filled pixels. At 160x90 with 4x8 blocks, at 161x91 (odd: the last
  // column and row fail) with 8x4 and 1x32 ones. Measured 2026-12-06: 160x90 at 0.02, 55.3 % traced,
  // RMS 5.7e-5; at 1e-4, 57.2 % and 1.4e-7.
  for (const int tileW : {4, 8, 1}) {
    const int w = tileW == 4 ? 160 : 161, h = tileW == 4 ? 90 : 91, tileH = 32 / tileW;
    pl::PlayOptions o = groveView(w, h);
    o.warpTileWidth = tileW;
    std::vector<float> full, loose, tight, bands;
    pl::play(o, Device{}, &full);
    o.adaptive = "0.02";
    const nlohmann::json r = pl::play(o, Device{}, &loose);
    o.adaptive = "1e-4";
    const nlohmann::json rt = pl::play(o, Device{}, &tight);
    const double f = r["adaptive"]["traced_fraction_mean"], ft = rt["adaptive"]["traced_fraction_mean"];
    const double e = pt::imageRms(loose, full), et = pt::imageRms(tight, full);
    std::printf("adaptive %dx%d, %dx%d blocks: 0.02: traced %.3f, RMS %.3g; 1e-4: traced %.3f, RMS %.3g\n", w, h, tileW, tileH, f, e, ft, et);
    EXPECT_DOUBLE_EQ(double(r["adaptive"]["tolerance"]), double(0.02f));
    EXPECT_GE(f, 0.25);  // the lattice at least
    EXPECT_LT(f, 0.9);
    EXPECT_GT(ft, f);
    EXPECT_LT(et, e);
    EXPECT_GT(e, 0.0);
    EXPECT_LT(e, 1e-3);
    int passing = 0, failing = 0;
    const uint64_t filled = pt::expectAdaptiveBlocks(loose, full, w, h, tileW, tileH, 0.02f, passing, failing);
    EXPECT_GT(passing, 0);
    EXPECT_GT(failing, 0);
    EXPECT_DOUBLE_EQ(f, 1.0 - double(filled) / (double(w) * h));
    // bands give the same image (each band traces the lattice rows of its blocks): three on block
    // rows, and 40 on single rows (40 x tileH > h), which cut blocks
    o.adaptive = "0.02";
    for (const int tiles : {3, 40}) {
      o.tiles = tiles;
      const nlohmann::json rb = pl::play(o, Device{}, &bands);
      ASSERT_EQ(rb["bands"].size(), size_t(tiles));
      ASSERT_EQ(bands.size(), loose.size());
      EXPECT_EQ(std::memcmp(bands.data(), loose.data(), loose.size() * sizeof(float)), 0) << tiles << " bands: rms " << pt::imageRms(bands, loose);
      EXPECT_DOUBLE_EQ(double(rb["adaptive"]["traced_fraction_mean"]), f);
    }
    o.tiles = 0;
  }
  // one eye only, and a tolerance >= 0
  pl::PlayOptions o = groveView(32, 18);
  o.adaptive = "0.02";
  o.stereoIpd = 0.1f;
  EXPECT_THROW(pl::play(o, Device{}), canopy::Error);
  o.stereoIpd = 0.0f;
  o.adaptive = "-0.1";
  EXPECT_THROW(pl::play(o, Device{}), canopy::Error);
  o.adaptive = "nan";
  EXPECT_THROW(pl::play(o, Device{}), canopy::Error);
  o.adaptive = "0.02x";
  EXPECT_THROW(pl::play(o, Device{}), canopy::Error);
}

// --adaptive auto (the default): kAdaptiveAutoTolerance from 3840x2160's pixel count on, one eye,
// without --converge; off below, with --stereo and with --converge. An explicit tolerance is taken as
// given at any size, and refused with --stereo.
TEST(Render, AdaptiveAutoSamplesAdaptivelyFrom3840x2160On) {
  pl::PlayOptions o;
  EXPECT_EQ(o.adaptive, "auto");
  o.width = 3840, o.height = 2160;
  EXPECT_EQ(pl::adaptiveTolerance(o), pl::kAdaptiveAutoTolerance);
  EXPECT_EQ(pl::kAdaptiveAutoTolerance, 0.08f);
  o.width = 4096;  // more pixels
  EXPECT_EQ(pl::adaptiveTolerance(o), pl::kAdaptiveAutoTolerance);
  o.width = 3839;  // one column fewer than 3840x2160
  EXPECT_EQ(pl::adaptiveTolerance(o), 0.0f);
  o.width = 1920, o.height = 1080;
  EXPECT_EQ(pl::adaptiveTolerance(o), 0.0f);
  o.width = 2160, o.height = 3840;  // portrait
  EXPECT_EQ(pl::adaptiveTolerance(o), pl::kAdaptiveAutoTolerance);
  o.converge = true;
  EXPECT_EQ(pl::adaptiveTolerance(o), 0.0f);
  o.converge = false;
  o.stereoIpd = 0.064f;
  EXPECT_EQ(pl::adaptiveTolerance(o), 0.0f);
  o.adaptive = "0.04";
  EXPECT_THROW(pl::adaptiveTolerance(o), canopy::Error);
  o.stereoIpd = 0.0f;
  EXPECT_EQ(pl::adaptiveTolerance(o), 0.04f);
  o.width = 16, o.height = 9;
  EXPECT_EQ(pl::adaptiveTolerance(o), 0.04f);
  for (const char* off : {"off", "0", "0.0"}) {
    o.adaptive = off;
    EXPECT_EQ(pl::adaptiveTolerance(o), 0.0f) << off;
  }
  o.width = 3840, o.height = 2160, o.adaptive = "off";
  EXPECT_EQ(pl::adaptiveTolerance(o), 0.0f);
  for (const char* bad : {"", "Auto", "on", "-1", "1001", "inf", "0.08 "}) {
    o.adaptive = bad;
    EXPECT_THROW(pl::adaptiveTolerance(o), canopy::Error) << "'" << bad << "'";
  }
}

// The default reaches the renderer: a 3840x2160 frame of the grove (without --converge) is sampled
// adaptively at kAdaptiveAutoTolerance, the report says so, and "off" traces every pixel. The camera
// is far away and the ground off, so that most rays miss the scene (a cheap 4K frame on the CPU):
// its blocks pass (a quarter of the pixels traced and a few more) and the pixels of the grove match.
TEST(Render, AdaptiveAutoSamplesA3840x2160FrameAdaptively) {
  pl::PlayOptions o = groveView(3840, 2160);
  o.converge = false;
  o.camera = "orbit:elevation=8,distance=150,fov=60";
  o.ground = "none";
  std::vector<float> adaptive, full;
  const nlohmann::json r = pl::play(o, Device{}, &adaptive);
  ASSERT_TRUE(r.contains("adaptive"));
  EXPECT_EQ(double(r["adaptive"]["tolerance"]), double(pl::kAdaptiveAutoTolerance));
  EXPECT_EQ(r["adaptive"]["option"], "auto");
  const double f = r["adaptive"]["traced_fraction_mean"];
  std::printf("auto at 3840x2160: %.4f of the pixels traced\n", f);
  EXPECT_GE(f, 0.25);
  EXPECT_LT(f, 0.3);
  o.adaptive = "off";
  const nlohmann::json rf = pl::play(o, Device{}, &full);
  EXPECT_FALSE(rf.contains("adaptive"));
  ASSERT_EQ(adaptive.size(), full.size());
  EXPECT_GT(pt::imageRms(adaptive, full), 0.0);  // some block was filled where the grove is
  EXPECT_LT(pt::imageRms(adaptive, full), 1e-3);
}
