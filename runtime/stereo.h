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
// A volume pixel has no single depth. The traced eye records, per pixel, the mean and the spread
// (standard deviation) of the disparity of its samples, weighted by their share of the pixel
// (pixelDisparity, cone.h). Reprojection then treats each row of the traced eye as a line of
// pixels in the right eye's row coordinate (a pixel's centre x + 1/2 moves to x + 1/2 - disparity):
//   - two neighbours whose disparities differ by at most maxJump are one surface: the span between
//     their centres is covered, colours interpolated (no cracks where a surface stretches);
//   - elsewhere a pixel covers one pixel width around its centre;
//   - where spans overlap, the nearest (largest disparity) wins (a 64-bit key: disparity bits, then
//     the source, so the choice is the same in any order: atomicMax on the GPU, max on the CPU).
// A right-eye pixel is traced (a hole) where
//   - no span covers its centre (a region the left eye does not see: disocclusion, the frame edge);
//   - the winning pixel's content spreads over more than maxSpread pixels of disparity (a
//     semi-transparent crown over a farther one: its parts would move apart);
//   - the winning pixel is not solid (alpha < solidAlpha) and something may lie behind it in the
//     right eye that its colour lacks (stereoClearBehind: another span covers the centre, or the
//     left eye does not see sky there, or a left pixel between has matter at two depths).
// Faint pixels (alpha < faintAlpha: sky, the frame background) have disparity 0 (infinitely far).
#pragma once
#include <cstdint>

#include "runtime/cone.h"

namespace canopy::play {

struct StereoParams {
  float maxSpread = 0.5f;    // disparity spread (px) above which a pixel is traced in the second eye
  float maxJump = 1.0f;      // neighbours closer than this in disparity (px) are one surface
  float solidAlpha = 0.98f;  // a pixel at least this opaque hides what lies behind it
  float faintAlpha = 0.02f;  // a pixel less opaque than this is sky (disparity 0)
};

// One row band's data: the traced eye's RGBA and disparity (mean, spread per pixel), the right eye's
// keys and cover counts (zeroed before the splat), and the right eye's RGBA.
struct StereoView {
  const float* left = nullptr;
  const float* disparity = nullptr;
  unsigned long long* keys = nullptr;
  uint32_t* cover = nullptr;
  float* right = nullptr;
  int width = 0;
  StereoParams p;
};

inline StereoView stereoView(const float* left, const float* disparity, unsigned long long* keys, uint32_t* cover, float* right, int width,
                             const StereoParams& p) {
  StereoView v;
  v.left = left;
  v.disparity = disparity;
  v.keys = keys;
  v.cover = cover;
  v.right = right;
  v.width = width;
  v.p = p;
  return v;
}

constexpr unsigned long long kStereoKeyValid = 1ull;
constexpr unsigned long long kStereoKeyPair = 2ull;

// The disparity a pixel moves by (0 for faint pixels).
CANOPY_HD CANOPY_FORCEINLINE float stereoShift(const StereoView& v, int64_t i) {
  return v.left[4 * i + 3] < v.p.faintAlpha ? 0.0f : v.disparity[2 * i];
}
CANOPY_HD CANOPY_FORCEINLINE bool stereoFaint(const StereoView& v, int64_t i) { return v.left[4 * i + 3] < v.p.faintAlpha; }
// Whether a pixel's content moves as one (faint pixels do).
CANOPY_HD CANOPY_FORCEINLINE bool stereoCoherent(const StereoView& v, int64_t i) {
  return stereoFaint(v, i) || v.disparity[2 * i + 1] <= v.p.maxSpread;
}
// Whether pixels i and i + 1 of a row are one surface.
CANOPY_HD CANOPY_FORCEINLINE bool stereoJoined(const StereoView& v, int64_t i) {
  const float a = stereoShift(v, i), b = stereoShift(v, i + 1);
  return stereoFaint(v, i) == stereoFaint(v, i + 1) && (a > b ? a - b : b - a) <= v.p.maxJump;
}
// A span's key at a covered centre: the disparity there, then source column and kind.
CANOPY_HD CANOPY_FORCEINLINE unsigned long long stereoKey(float disparity, int source, bool pair) {
  return (static_cast<unsigned long long>(floatBits(disparity)) << 32) | (static_cast<unsigned long long>(source) << 2) |
         (pair ? kStereoKeyPair : 0ull) | kStereoKeyValid;
}

// The first right-eye column whose centre (x + 1/2) is >= a, as an int clamped to [0, width].
CANOPY_HD CANOPY_FORCEINLINE int stereoFirstColumn(float a, int width) {
  const float c = ceilf(a - 0.5f);
  return c <= 0.0f ? 0 : (c >= float(width) ? width : int(c));
}

// Emits the spans of pixel x of row y of the traced eye: emit(rightIndex, key, counts) for every
// right-eye pixel whose centre the pixel's spans cover; counts: the pixel is not faint (cover).
template <class Emit>
CANOPY_HD inline void stereoSplat(const StereoView& v, int x, int y, Emit&& emit) {
  const int64_t row = int64_t(y) * v.width, i = row + x;
  const float d0 = stereoShift(v, i);
  const float p0 = float(x) + 0.5f - d0;
  const bool counts = !stereoFaint(v, i);
  const bool joinedLeft = x > 0 && stereoJoined(v, i - 1);
  const bool joinedRight = x + 1 < v.width && stereoJoined(v, i);
  if (!joinedLeft) {  // the left half of the pixel's own width
    const int c1 = stereoFirstColumn(p0, v.width);
    for (int c = stereoFirstColumn(p0 - 0.5f, v.width); c < c1; ++c) emit(row + c, stereoKey(d0, x, false), counts);
  }
  if (joinedRight) {  // to the next centre, interpolated
    const float d1 = stereoShift(v, i + 1);
    const float p1 = float(x) + 1.5f - d1;
    const int c1 = stereoFirstColumn(p1, v.width);
    for (int c = stereoFirstColumn(p0, v.width); c < c1; ++c) {
      const float u = (float(c) + 0.5f - p0) / (p1 - p0);
      emit(row + c, stereoKey(d0 + (d1 - d0) * u, x, true), counts);
    }
  } else {  // the right half of the pixel's own width
    const int c1 = stereoFirstColumn(p0 + 0.5f, v.width);
    for (int c = stereoFirstColumn(p0, v.width); c < c1; ++c) emit(row + c, stereoKey(d0, x, false), counts);
  }
}

// Whether nothing the left eye saw lies behind a translucent winner at right-eye pixel x, whose
// source is left column `source`: the right eye's ray behind it meets depth z at left column
// x + disparity(z), in [x, source). Clear when no other non-faint span covers x, the left eye sees
// sky at column x (infinitely far: what the ray meets last), and every left pixel in (x, source) is
// sky or coherent (a pixel with matter at two depths, the winner's and one behind, is not).
CANOPY_HD inline bool stereoClearBehind(const StereoView& v, int64_t row, int x, int source) {
  if (v.cover[row + x] >= 2u || !stereoFaint(v, row + x)) return false;
  for (int c = x + 1; c < source && c < v.width; ++c)
    if (!stereoCoherent(v, row + c)) return false;
  return true;
}

// Right-eye pixel x of row y from its key: writes its RGBA and returns true, or returns false (a
// hole, to be traced; nothing written).
CANOPY_HD inline bool stereoResolve(const StereoView& v, int x, int y) {
  const int64_t row = int64_t(y) * v.width, i = row + x;
  const unsigned long long key = v.keys[i];
  if (!(key & kStereoKeyValid)) return false;
  const int source = int(uint32_t(key) >> 2);
  const int64_t j0 = row + source;
  float rgba[4];
  if (key & kStereoKeyPair) {
    const int64_t j1 = j0 + 1;
    if (!stereoCoherent(v, j0) || !stereoCoherent(v, j1)) return false;
    const float p0 = float(source) + 0.5f - stereoShift(v, j0), p1 = float(source) + 1.5f - stereoShift(v, j1);
    float u = (float(x) + 0.5f - p0) / (p1 - p0);
    u = u < 0.0f ? 0.0f : (u > 1.0f ? 1.0f : u);
    for (int c = 0; c < 4; ++c) rgba[c] = v.left[4 * j0 + c] + (v.left[4 * j1 + c] - v.left[4 * j0 + c]) * u;
  } else {
    if (!stereoCoherent(v, j0)) return false;
    for (int c = 0; c < 4; ++c) rgba[c] = v.left[4 * j0 + c];
  }
  if (rgba[3] < v.p.solidAlpha && !stereoClearBehind(v, row, x, source)) return false;
  for (int c = 0; c < 4; ++c) v.right[4 * i + c] = rgba[c];
  return true;
}

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
