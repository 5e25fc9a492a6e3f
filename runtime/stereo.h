// stereo.h: the second eye of a stereo pair by reprojection (seed 002 ch. 5: render one eye,
// reproject its samples to the other, trace only the holes), per element, for the CPU reference and
// the CUDA kernels alike.
//
// The two eyes are parallel cameras a distance `ipd` apart along the camera's right axis; the traced
// (left) eye sits at -ipd/2, the reprojected (right) eye at +ipd/2. A point at depth z along the view
// axis is seen disparityScale / z pixels further left by the right eye (disparityScale = ipd x the
// focal length in pixels), on the same row: reprojection never leaves a row, so a band of rows
// (one GPU's tile, tiles.h) reprojects on its own.
//
// A volume pixel has no single depth. The traced eye keeps, per pixel, two layers (pixelLayers,
// cone.h): the front layer, its samples from the first one on while they stay within
// ShadeParams::stereoLayer = 2 maxSpread pixels of disparity of the first one of 2 % of the pixel
// or more (kLayerOpenWeight; fainter ones before it join the front), and the back
// layer, all the samples behind it. Per layer: the mean and the spread (standard deviation) of the
// disparity of its samples, weighted by their share of the pixel, and its colour (the front's
// RGBA; the back's is what the front lets through: (pixel - front) / (1 - front alpha)); and the
// disparity of the front layer's far side, where the back begins.
// Reprojection treats each row of the traced eye as a line of pixels in the right eye's row
// coordinate (a pixel's centre x + 1/2 moves to x + 1/2 - disparity), layer by layer:
//   - two neighbours whose layers' disparities differ by at most maxJump are one surface: the span
//     between their centres is covered, colours interpolated (no cracks where a surface stretches);
//   - elsewhere a layer covers one pixel width around its centre;
//   - per right-eye pixel, the nearest (largest disparity) span of either layer wins (keys: a 64-bit
//     key, disparity bits, then the source and kind, so the choice is the same in any order:
//     atomicMax on the GPU, max on the CPU), and then the nearest span behind it by more than
//     maxJump (behind: what the winner lets through).
// A right-eye pixel is traced (a hole) where
//   - no span covers its centre (a region the left eye does not see: disocclusion, the frame edge);
//   - the winning span's layer spreads over more than maxSpread pixels of disparity (its parts would
//     move apart);
//   - the winner is not solid (alpha < solidAlpha) and what lies behind it is not known: the span
//     behind spreads, or is translucent itself (behind it the right eye's ray leaves the left eye's
//     ray it came from) and not the sky, or the left eye did not see all that the right eye's ray
//     crosses between the two (stereoClearBetween: a layer that spreads over that depth, or the
//     hidden side of a solid front), or nothing lies behind and the left eye does not see sky at
//     that column (stereoClearBehind).
// Where the winner is the front layer of a translucent surface that reprojects (a pair span whose
// two pixels' fronts are alike) and only what lies behind it is not known, the hole is traced only
// behind that layer's far side and composited under it (stereoResolveHole, stereoFillBehind).
// A translucent winner is composited over the solid layer or the sky behind it. Faint layers
// (alpha < faintAlpha: sky, the frame background) have disparity 0 (infinitely far). A back layer
// whose front is solid is not known (it hides it), and a faint one (nothing behind the front) is
// no surface: neither makes a span.
#pragma once
#include <cstdint>

#include "runtime/cone.h"

namespace canopy::play {

struct StereoParams {
  float maxSpread = 0.65f;   // disparity spread (px) above which a layer is traced in the second eye (bench/RESULTS.md: the default)
  float maxJump = 1.0f;      // neighbours closer than this in disparity (px) are one surface
  float solidAlpha = 0.98f;  // a layer at least this opaque hides what lies behind it
  float faintAlpha = 0.02f;  // a layer less opaque than this is sky (disparity 0)
};

// One row band's data: the traced eye's RGBA and layers (kStereoPixelFloats per pixel), the right
// eye's keys, keys behind and cover counts (zeroed before the splats), and the right eye's RGBA.
struct StereoView {
  const float* left = nullptr;
  const float* layers = nullptr;
  unsigned long long* keys = nullptr;
  unsigned long long* behind = nullptr;
  uint32_t* cover = nullptr;
  float* right = nullptr;
  int width = 0;
  StereoParams p;
};

inline StereoView stereoView(const float* left, const float* layers, unsigned long long* keys, unsigned long long* behind, uint32_t* cover,
                             float* right, int width, const StereoParams& p) {
  StereoView v;
  v.left = left;
  v.layers = layers;
  v.keys = keys;
  v.behind = behind;
  v.cover = cover;
  v.right = right;
  v.width = width;
  v.p = p;
  return v;
}

constexpr unsigned long long kStereoKeyValid = 1ull;
constexpr unsigned long long kStereoKeyPair = 2ull;
constexpr unsigned long long kStereoKeyBack = 4ull;
constexpr int kStereoFront = 0, kStereoBack = 1;
// A back layer is known only where its front lets at least 1e-3 through (1 / (1 - front alpha)
// would otherwise turn rounding into colour; --stereo-solid may be 1).
constexpr float kStereoBackVisible = 1.0f - 1e-3f;

CANOPY_HD CANOPY_FORCEINLINE const float* stereoLayers(const StereoView& v, int64_t i) { return v.layers + kStereoPixelFloats * i; }
// Layer L's alpha (the back's: its share of what the front lets through).
CANOPY_HD CANOPY_FORCEINLINE float stereoAlpha(const StereoView& v, int64_t i, int L) {
  const float fa = stereoLayers(v, i)[7];
  if (L == kStereoFront) return fa;
  const float b = (v.left[4 * i + 3] - fa) / (1.0f - fa);
  return b < 0.0f ? 0.0f : (b > 1.0f ? 1.0f : b);
}
// Whether layer L is known: the front always, the back where the front is not solid (a sky pixel
// has no back).
CANOPY_HD CANOPY_FORCEINLINE bool stereoKnown(const StereoView& v, int64_t i, int L) {
  const float fa = stereoLayers(v, i)[7];
  return L == kStereoFront || (fa < v.p.solidAlpha && fa < kStereoBackVisible && v.left[4 * i + 3] >= v.p.faintAlpha);
}
// Whether layer L is faint (the front: the pixel is sky; the back: nothing behind the front).
CANOPY_HD CANOPY_FORCEINLINE bool stereoFaint(const StereoView& v, int64_t i, int L) {
  return (L == kStereoFront ? v.left[4 * i + 3] : stereoAlpha(v, i, L)) < v.p.faintAlpha;
}
// The disparity layer L moves by (0 for faint layers).
CANOPY_HD CANOPY_FORCEINLINE float stereoShift(const StereoView& v, int64_t i, int L) {
  return stereoFaint(v, i, L) ? 0.0f : stereoLayers(v, i)[2 * L];
}
// Whether layer L's content moves as one (faint layers do).
CANOPY_HD CANOPY_FORCEINLINE bool stereoCoherent(const StereoView& v, int64_t i, int L) {
  return stereoFaint(v, i, L) || stereoLayers(v, i)[2 * L + 1] <= v.p.maxSpread;
}
// Layer L's premultiplied RGBA.
CANOPY_HD CANOPY_FORCEINLINE void stereoRgba(const StereoView& v, int64_t i, int L, float rgba[4]) {
  const float* f = stereoLayers(v, i) + 4;
  if (L == kStereoFront) {
    for (int c = 0; c < 4; ++c) rgba[c] = f[c];
    return;
  }
  const float inv = 1.0f / (1.0f - f[3]);
  for (int c = 0; c < 3; ++c) {
    const float b = v.left[4 * i + c] - f[c];
    rgba[c] = (b > 0.0f ? b : 0.0f) * inv;
  }
  rgba[3] = stereoAlpha(v, i, L);
}
// Whether layer L of pixels i and i + 1 of a row are one surface.
CANOPY_HD CANOPY_FORCEINLINE bool stereoJoined(const StereoView& v, int64_t i, int L) {
  if (!stereoKnown(v, i, L) || !stereoKnown(v, i + 1, L)) return false;
  const float a = stereoShift(v, i, L), b = stereoShift(v, i + 1, L);
  return stereoFaint(v, i, L) == stereoFaint(v, i + 1, L) && (a > b ? a - b : b - a) <= v.p.maxJump;
}
// A span's key at a covered centre: the disparity there, then source column, layer and kind.
CANOPY_HD CANOPY_FORCEINLINE unsigned long long stereoKey(float disparity, int source, int L, bool pair) {
  return (static_cast<unsigned long long>(floatBits(disparity)) << 32) | (static_cast<unsigned long long>(source) << 3) |
         (L == kStereoBack ? kStereoKeyBack : 0ull) | (pair ? kStereoKeyPair : 0ull) | kStereoKeyValid;
}
CANOPY_HD CANOPY_FORCEINLINE float stereoKeyDisparity(unsigned long long key) { return canopyFloatFromBits(uint32_t(key >> 32)); }
CANOPY_HD CANOPY_FORCEINLINE int stereoKeySource(unsigned long long key) { return int(uint32_t(key) >> 3); }
CANOPY_HD CANOPY_FORCEINLINE int stereoKeyLayer(unsigned long long key) { return (key & kStereoKeyBack) ? kStereoBack : kStereoFront; }

// The first right-eye column whose centre (x + 1/2) is >= a, as an int clamped to [0, width].
CANOPY_HD CANOPY_FORCEINLINE int stereoFirstColumn(float a, int width) {
  const float c = ceilf(a - 0.5f);
  return c <= 0.0f ? 0 : (c >= float(width) ? width : int(c));
}

// Emits the spans of layer L of pixel x of row y of the traced eye (nothing for a layer that is
// not known): emit(rightIndex, key, counts) for every right-eye pixel whose centre they cover;
// counts: a front layer that is not faint (cover).
template <class Emit>
CANOPY_HD inline void stereoSplat(const StereoView& v, int x, int y, int L, Emit&& emit) {
  const int64_t row = int64_t(y) * v.width, i = row + x;
  // a faint back layer is no surface: it only says that the left eye's ray saw nothing behind the front
  if (!stereoKnown(v, i, L) || (L == kStereoBack && stereoFaint(v, i, L))) return;
  const float d0 = stereoShift(v, i, L);
  const float p0 = float(x) + 0.5f - d0;
  const bool counts = L == kStereoFront && !stereoFaint(v, i, L);
  const bool joinedLeft = x > 0 && stereoJoined(v, i - 1, L);
  const bool joinedRight = x + 1 < v.width && stereoJoined(v, i, L);
  if (!joinedLeft) {  // the left half of the pixel's own width
    const int c1 = stereoFirstColumn(p0, v.width);
    for (int c = stereoFirstColumn(p0 - 0.5f, v.width); c < c1; ++c) emit(row + c, stereoKey(d0, x, L, false), counts);
  }
  if (joinedRight) {  // to the next centre, interpolated
    const float d1 = stereoShift(v, i + 1, L);
    const float p1 = float(x) + 1.5f - d1;
    const int c1 = stereoFirstColumn(p1, v.width);
    for (int c = stereoFirstColumn(p0, v.width); c < c1; ++c) {
      const float u = (float(c) + 0.5f - p0) / (p1 - p0);
      emit(row + c, stereoKey(d0 + (d1 - d0) * u, x, L, true), counts);
    }
  } else {  // the right half of the pixel's own width
    const int c1 = stereoFirstColumn(p0 + 0.5f, v.width);
    for (int c = stereoFirstColumn(p0, v.width); c < c1; ++c) emit(row + c, stereoKey(d0, x, L, false), counts);
  }
}

// The spans of both layers of pixel x of row y (into keys, nearest wins; cover).
template <class Emit>
CANOPY_HD inline void stereoSplatNearest(const StereoView& v, int x, int y, Emit&& emit) {
  stereoSplat(v, x, y, kStereoFront, emit);
  stereoSplat(v, x, y, kStereoBack, emit);
}

// After the first splat (keys complete): the spans of both layers of pixel x of row y that lie
// behind the winning span of the right-eye pixel they cover by more than maxJump (a back layer
// behind a front winner: at all): emit(rightIndex, key) (into behind, nearest wins).
template <class Emit>
CANOPY_HD inline void stereoSplatBehind(const StereoView& v, int x, int y, Emit&& emit) {
  for (int L = kStereoFront; L <= kStereoBack; ++L)
    stereoSplat(v, x, y, L, [&](int64_t r, unsigned long long key, bool) {
      const unsigned long long front = v.keys[r];
      if (!(front & kStereoKeyValid)) return;
      // a back layer behind a front one lies behind it by construction (its own pixel's back may be
      // less than maxJump behind it); other spans must be more than maxJump behind
      const bool backOfFront = stereoKeyLayer(key) == kStereoBack && stereoKeyLayer(front) == kStereoFront && key < front;
      if (backOfFront || stereoKeyDisparity(key) < stereoKeyDisparity(front) - v.p.maxJump) emit(r, key);
    });
}

// Where right-eye pixel x of the row lies along the pair span `key`: 0 at its first pixel's centre,
// 1 at the second's (clamped).
CANOPY_HD CANOPY_FORCEINLINE float stereoPairU(const StereoView& v, int64_t row, unsigned long long key, int x) {
  const int source = stereoKeySource(key), L = stereoKeyLayer(key);
  const int64_t j0 = row + source;
  const float p0 = float(source) + 0.5f - stereoShift(v, j0, L), p1 = float(source) + 1.5f - stereoShift(v, j0 + 1, L);
  const float u = (float(x) + 0.5f - p0) / (p1 - p0);
  return u < 0.0f ? 0.0f : (u > 1.0f ? 1.0f : u);
}

// The RGBA a span key gives right-eye pixel x of the row: its layer's colour (interpolated between
// the two pixels of a pair span); false where that layer spreads (a hole).
CANOPY_HD inline bool stereoSpanRgba(const StereoView& v, int64_t row, unsigned long long key, int x, float rgba[4]) {
  const int source = stereoKeySource(key), L = stereoKeyLayer(key);
  const int64_t j0 = row + source;
  if (!stereoCoherent(v, j0, L)) return false;
  stereoRgba(v, j0, L, rgba);
  if (!(key & kStereoKeyPair)) return true;
  const int64_t j1 = j0 + 1;
  if (!stereoCoherent(v, j1, L)) return false;
  float b[4];
  stereoRgba(v, j1, L, b);
  const float u = stereoPairU(v, row, key, x);
  for (int c = 0; c < 4; ++c) rgba[c] += (b[c] - rgba[c]) * u;
  return true;
}

// Whether the left eye saw all that the right eye's ray at x meets between the winner (from left
// column `source`) and what lies behind it (disparity `behind`). The ray crosses left column c at
// disparity c - x, and the left eye's ray there saw its layers and nothing else; a layer that does
// not spread and lies at c - x would have made a span at x (behind, or the winner). Not seen: a
// layer that spreads over c - x (it made no trusted span), or what lies behind a solid front
// (its back is not known) or behind a pixel made solid by its back, where the crossing is behind it.
CANOPY_HD inline bool stereoClearBetween(const StereoView& v, int64_t row, int x, int source, float behind) {
  for (int c = x + 1; c < source && c < v.width; ++c) {
    const float dc = float(c - x);
    if (dc <= behind + v.p.maxJump) continue;
    const int64_t j = row + c;
    // the hidden side of a solid front, or of a solid back behind a translucent front
    if (!stereoKnown(v, j, kStereoBack) && stereoShift(v, j, kStereoFront) > dc + v.p.maxJump) return false;
    if (stereoKnown(v, j, kStereoBack) && v.left[4 * j + 3] >= v.p.solidAlpha && !stereoFaint(v, j, kStereoBack) &&
        stereoShift(v, j, kStereoBack) > dc + v.p.maxJump)
      return false;
    for (int L = kStereoFront; L <= kStereoBack; ++L) {
      if (!stereoKnown(v, j, L) || stereoCoherent(v, j, L)) continue;
      const float* s = stereoLayers(v, j) + 2 * L;
      const float off = dc > s[0] ? dc - s[0] : s[0] - dc;
      if (off <= 2.0f * s[1] + v.p.maxJump) return false;
    }
  }
  return true;
}

// Whether nothing the left eye saw lies behind a translucent winner at right-eye pixel x where no
// span lies behind it: no other non-faint front span covers x and the left eye sees sky at column
// x (infinitely far: what the ray meets last).
CANOPY_HD CANOPY_FORCEINLINE bool stereoClearBehind(const StereoView& v, int64_t row, int x) {
  return v.cover[row + x] < 2u && stereoFaint(v, row + x, kStereoFront);
}

// How a right-eye pixel is filled (stereoResolveFill).
constexpr int kStereoResolved = 0, kStereoHole = 1, kStereoHoleBehind = 2;
// A pair span whose two pixels' front layers differ in alpha by more than this is not used as
// the front of a hole traced behind it (kStereoHoleBehind): the two pixels' fronts hold different
// shares of the matter there (a sub-pixel crown edge), and neither is what the right eye's ray
// crosses (bench/RESULTS.md, "Holes traced behind their front": 0.05, 0.1, 0.2 and no gate).
constexpr float kStereoBehindAlphaStep = 0.1f;

// kStereoHoleBehind's test and fill for right-eye pixel x of the row whose winning span `key`, of
// colour `front` (stereoSpanRgba), is translucent with what lies behind it not known
// (stereoResolveFill): writes the front and *behindFrom (its far side interpolated along the pair
// span as its colour is), or returns kStereoHole.
CANOPY_HD inline int stereoFillBehind(const StereoView& v, int64_t row, int x, unsigned long long key, const float front[4],
                                      float* behindFrom) {
  if (stereoKeyLayer(key) != kStereoFront || !(key & kStereoKeyPair)) return kStereoHole;
  const int64_t j0 = row + stereoKeySource(key);
  const float da = stereoLayers(v, j0)[7] - stereoLayers(v, j0 + 1)[7];
  if (da > kStereoBehindAlphaStep || da < -kStereoBehindAlphaStep) return kStereoHole;
  const float f0 = stereoLayers(v, j0)[8], f1 = stereoLayers(v, j0 + 1)[8];
  if (!(f0 > 0.0f) || !(f1 > 0.0f)) return kStereoHole;  // a front that never opened: its far side is not known
  *behindFrom = f0 + (f1 - f0) * stereoPairU(v, row, key, x);
  for (int c = 0; c < 4; ++c) v.right[4 * (row + x) + c] = front[c];
  return kStereoHoleBehind;
}

// Right-eye pixel x of row y from its keys:
//   - kStereoResolved: its RGBA written;
//   - kStereoHole: to be traced in full (nothing written);
//   - kStereoHoleBehind (only where behindFrom is given, else kStereoHole): the winner is the
//     front layer of a surface that reprojects (a pair span that does not spread, its two pixels'
//     fronts alike) but is not solid, and what lies behind it is not known. The front layer is
//     written, and *behindFrom is the disparity of its far side (where the back layer begins), both
//     interpolated along the pair span: only the ray behind it is traced, and composited under it
//     (renderPixelT's kBehind).
CANOPY_HD inline int stereoResolveFill(const StereoView& v, int x, int y, float* behindFrom) {
  const int64_t row = int64_t(y) * v.width, i = row + x;
  const unsigned long long key = v.keys[i];
  if (!(key & kStereoKeyValid)) return kStereoHole;
  float rgba[4];
  if (!stereoSpanRgba(v, row, key, x, rgba)) return kStereoHole;
  if (rgba[3] < v.p.solidAlpha) {  // what lies behind shows through
    const unsigned long long back = v.behind[i];
    float b[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    float db = 0.0f;
    bool known;
    if (back & kStereoKeyValid) {
      // behind a translucent layer the right eye's ray leaves the left eye's ray it came from: only a
      // solid layer or the sky (a sky pixel's span) ends what the right eye sees
      const bool sky = stereoKeyLayer(back) == kStereoFront && stereoFaint(v, row + stereoKeySource(back), kStereoFront);
      known = stereoSpanRgba(v, row, back, x, b) && (b[3] >= v.p.solidAlpha || sky);
      db = stereoKeyDisparity(back);
    } else {
      known = stereoClearBehind(v, row, x);
    }
    known = known && stereoClearBetween(v, row, x, stereoKeySource(key), db);
    if (!known) return behindFrom ? stereoFillBehind(v, row, x, key, rgba, behindFrom) : kStereoHole;
    const float through = 1.0f - rgba[3];
    for (int c = 0; c < 4; ++c) rgba[c] += through * b[c];
  }
  for (int c = 0; c < 4; ++c) v.right[4 * i + c] = rgba[c];
  return kStereoResolved;
}

// Right-eye pixel x of row y from its keys: writes its RGBA and returns true, or returns false (a
// hole, to be traced; nothing written).
CANOPY_HD inline bool stereoResolve(const StereoView& v, int x, int y) { return stereoResolveFill(v, x, y, nullptr) == kStereoResolved; }

// Right-eye pixel x of row y: true where resolved (its RGBA written); else a hole, to be traced
// from disparity behind[0] on under the front written (> 0, kStereoHoleBehind) or in full (0).
CANOPY_HD inline bool stereoResolveHole(const StereoView& v, int x, int y, float* behind) {
  *behind = 0.0f;
  return stereoResolveFill(v, x, y, behind) == kStereoResolved;
}

// The order in which the holes are traced: the CUDA backend lists them in two halves, the half of
// each by stereoHoleHalf, in warp-tile order within a half. It does not change the image.
//   - kHoleOrderTile: one half, the tile order (a warp traces neighbouring holes);
//   - kHoleOrderKind: the holes traced in full, then those traced behind a front (a warp does not
//     mix rays that start at the eye with rays that start deep in the scene; bench/RESULTS.md,
//     "Where the second eye's time goes").
constexpr int kHoleOrderTile = 0, kHoleOrderKind = 1;
CANOPY_HD CANOPY_FORCEINLINE int stereoHoleHalf(int order, bool behind) { return order == kHoleOrderKind && behind ? 1 : 0; }

// The two eyes of a stereo pair around `centre`: parallel, `ipd` apart along its right axis.
inline void stereoEyes(const CameraView& centre, float ipd, CameraView& left, CameraView& right) {
  const V3 axis = normalize(centre.right);
  left = centre;
  right = centre;
  left.position = centre.position - axis * (0.5f * ipd);
  right.position = centre.position + axis * (0.5f * ipd);
}

// ipd x the focal length in pixels: the disparity (px) of a point at unit depth.
inline float stereoDisparityScale(const CameraView& c, float ipd) {
  return ipd * float(c.height) / (2.0f * length(c.up));  // |up| = tan(fov / 2)
}

}  // namespace canopy::play
