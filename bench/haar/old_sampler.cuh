// old_sampler.cuh: the point sampler before the weighted sum (8 texels reconstructed as the decoder does, every candidate
// coefficient tested in a fully unrolled 4x4x4 loop), kept only so that bench_haar_gpu can measure
// the new sampler against it in one run. Not used by any tool.
#pragma once
#include "formats/haar_brick.h"
namespace canopy::haar::old {
// Coefficient c of a brick (zero when its mask bit is clear): the listing-5.5 popcount rule.
template <class Reader>
CANOPY_HD CANOPY_FORCEINLINE Rgb brickCoef(uint64_t mask, uint64_t first, const Reader& read, int c) {
  if (!((mask >> c) & 1u)) return Rgb{};
  const uint64_t below = mask & ((uint64_t(1) << c) - 1u);
  return read(first + uint64_t(popcount64(below)));
}
// Folds coefficient/partial value c with axis index k into the reconstruction of position pos
// (0..3) along that axis, in the operation order of unlift4: ((s +- D) +- d_{pos/2}).
CANOPY_HD CANOPY_FORCEINLINE void foldAxis(float& acc, float c, int k, int pos) {
  if (k == 0)
    acc = c;
  else if (k == 1)
    acc = pos < 2 ? addRn(acc, c) : subRn(acc, c);
  else if (k - 2 == (pos >> 1))
    acc = (pos & 1) ? subRn(acc, c) : addRn(acc, c);
}
CANOPY_HD CANOPY_FORCEINLINE void foldAxis(Rgb& acc, const Rgb& c, int k, int pos) {
  foldAxis(acc.r, c.r, k, pos);
  foldAxis(acc.g, c.g, k, pos);
  foldAxis(acc.b, c.b, k, pos);
}
// Axis coefficient indices that influence positions l and l+1: always 0 and 1, plus d0 (k=2)
// for l <= 1 and d1 (k=3) for l >= 1.
CANOPY_HD CANOPY_FORCEINLINE bool axisNeeds(int k, int l) {
  return k < 2 || (k == 2 && l <= 1) || (k == 3 && l >= 1);
}

// Trilinear sample of one brick: (lx, ly, lz) in 0..2 is the lower texel of the 2^3 footprint
// (brick-local), (fx, fy, fz) in [0, 1] the fractions. Reconstructs just the 8 texels.
template <class Reader>
CANOPY_HD inline Rgb sampleBrick(const BrickRecord& rec, const Reader& read, int lx, int ly, int lz,
                                 float fx, float fy, float fz) {
  const uint64_t mask = rec.mask();
  if (mask == 0) return Rgb{};
  const uint32_t first = rec.first();
  if (mask == 1u && !rec.raw()) return read(first);  // only the average: the fast path
  Rgb v[2][2][2];  // [z][y][x]
  if (rec.raw()) {
    CANOPY_UNROLL
    for (int dz = 0; dz < 2; ++dz)
      CANOPY_UNROLL
      for (int dy = 0; dy < 2; ++dy)
        CANOPY_UNROLL
        for (int dx = 0; dx < 2; ++dx)
          v[dz][dy][dx] = brickCoef(mask, first, read, brickIndex(lx + dx, ly + dy, lz + dz));
  } else {
    CANOPY_UNROLL
    for (int kz = 0; kz < 4; ++kz) {
      if (!axisNeeds(kz, lz)) continue;
      Rgb w[2][2];  // [y][x]: x and y already unlifted, coefficient index kz along z
      CANOPY_UNROLL
      for (int ky = 0; ky < 4; ++ky) {
        if (!axisNeeds(ky, ly)) continue;
        Rgb u[2];  // [x]: x unlifted, coefficient indices (ky, kz)
        if ((mask >> brickIndex(0, ky, kz)) & 0xfu) {
          CANOPY_UNROLL
          for (int kx = 0; kx < 4; ++kx) {
            if (!axisNeeds(kx, lx)) continue;
            const Rgb c = brickCoef(mask, first, read, brickIndex(kx, ky, kz));
            foldAxis(u[0], c, kx, lx);
            foldAxis(u[1], c, kx, lx + 1);
          }
        } else {
          u[0] = u[1] = Rgb{};  // a row of zeros: unlifts to zeros
        }
        CANOPY_UNROLL
        for (int dy = 0; dy < 2; ++dy)
          CANOPY_UNROLL
          for (int dx = 0; dx < 2; ++dx) foldAxis(w[dy][dx], u[dx], ky, ly + dy);
      }
      CANOPY_UNROLL
      for (int dz = 0; dz < 2; ++dz)
        CANOPY_UNROLL
        for (int dy = 0; dy < 2; ++dy)
          CANOPY_UNROLL
          for (int dx = 0; dx < 2; ++dx) foldAxis(v[dz][dy][dx], w[dy][dx], kz, lz + dz);
    }
  }
  float ch[2][2][2];
  Rgb out;
  CANOPY_UNROLL
  for (int i = 0; i < 8; ++i) (&ch[0][0][0])[i] = (&v[0][0][0])[i].r;
  out.r = trilinear(ch, fx, fy, fz);
  CANOPY_UNROLL
  for (int i = 0; i < 8; ++i) (&ch[0][0][0])[i] = (&v[0][0][0])[i].g;
  out.g = trilinear(ch, fx, fy, fz);
  CANOPY_UNROLL
  for (int i = 0; i < 8; ++i) (&ch[0][0][0])[i] = (&v[0][0][0])[i].b;
  out.b = trilinear(ch, fx, fy, fz);
  return out;
}

}  // namespace canopy::haar::old
