// haar_view.h: a POD view of a decoded-in-memory .chaar and the CANOPY_HD point sampler.
//
// ChaarView holds plain pointers (host memory for the CPU decoder, device memory for CUDA: see
// haar_cuda.cuh) and the lattice geometry, so a player kernel can take it by value and call
// chaarSample() from its own code. Nothing here allocates or throws; the view is only ever built
// from a ChaarData that the reader validated (every slot, mask and index is in range).
//
// Sampling convention: lattice node (i,j,k) holds its value at index-space point (i,j,k) (OpenVDB's
// convention). A sample at p takes i = floor(p), frac = p - i per axis and interpolates the 2^3
// nodes i..i+1 (dissertation eq. 4.4). p is first clamped to the lattice box [min, max]; nodes
// outside the lattice (the forward border of the last bricks) are zero, like an OpenVDB background.
#pragma once
#include <cstdint>

#include "formats/haar_brick.h"

namespace canopy::haar {

struct ChaarView {
  int32_t latticeMin[3] = {0, 0, 0};
  int32_t latticeMax[3] = {0, 0, 0};
  int32_t brickDims[3] = {0, 0, 0};  // ceil(lattice dim / 3) per axis
  uint32_t slotCount = 0;            // bricks with light in at least one base
  uint32_t baseCount = 0;
  Precision precision = Precision::Fp32;
  const uint32_t* slots = nullptr;        // [brickDims x*y*z], x fastest: slot or kEmptySlot
  const BrickRecord* records = nullptr;   // [base * slotCount + slot] (fp32, fp16)
  const void* coefs = nullptr;            // all bases' streams: float[3n], uint16_t[3n] or (Quant) uint64_t words
  uint64_t baseCoefOffset[kMaxBases] = {};  // first entry (Quant: first word) of each base's stream in coefs
  const QuantRecord* quantRecords = nullptr;  // [base * slotCount + slot] (Quant)
  float quantStep[kMaxBases][kQuantSteps] = {};  // each base's steps (quantSteps; Quant)
};

CANOPY_HD CANOPY_FORCEINLINE float clampf(float v, float lo, float hi) {
  // NaN-safe: a NaN coordinate clamps to lo.
  return v >= lo ? (v <= hi ? v : hi) : lo;
}

// Locates the brick and brick-local footprint of point (x,y,z) in index space. Returns the brick's
// slot (kEmptySlot where no base has light there).
struct BrickLookup {
  uint32_t slot;
  int lx, ly, lz;
  float fx, fy, fz;
};

// The brick coordinates b and the lookup of point (x,y,z) in a lattice [lmin, lmax] (slot unset):
// the one rule that chaarSample and the .canopy file's Haar light (canopy_layout.h, canopy_sample.h) share.
CANOPY_HD inline BrickLookup locateInLattice(const int32_t lmin[3], const int32_t lmax[3], float x, float y, float z, int b[3]) {
  const float p[3] = {x, y, z};
  int l[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    const float q = clampf(p[a], float(lmin[a]), float(lmax[a]));
#if defined(__CUDA_ARCH__)
    const float fl = floorf(q);
#else
    const float fl = __builtin_floorf(q);
#endif
    int i = int(fl) - lmin[a];  // 0 .. dim-1
    f[a] = q - fl;
    b[a] = i / kBrickCore;
    l[a] = i - b[a] * kBrickCore;
  }
  BrickLookup r;
  r.slot = kEmptySlot;
  r.lx = l[0];
  r.ly = l[1];
  r.lz = l[2];
  r.fx = f[0];
  r.fy = f[1];
  r.fz = f[2];
  return r;
}

CANOPY_HD inline BrickLookup locate(const ChaarView& v, float x, float y, float z) {
  int b[3];
  BrickLookup r = locateInLattice(v.latticeMin, v.latticeMax, x, y, z, b);
  r.slot = v.slots[(int64_t(b[2]) * v.brickDims[1] + b[1]) * v.brickDims[0] + b[0]];
  return r;
}

// Trilinear sample of base `base` (0 .. baseCount-1) at index-space point (x,y,z): one brick read.
CANOPY_HD inline Rgb chaarSample(const ChaarView& v, int base, float x, float y, float z) {
  const BrickLookup at = locate(v, x, y, z);
  if (at.slot == kEmptySlot) return Rgb{};
  const uint64_t off = v.baseCoefOffset[base];
  if (v.precision == Precision::Quant)
    return sampleQuantBrick(loadQuantRecord(v.quantRecords + uint64_t(base) * v.slotCount + at.slot),
                            static_cast<const uint64_t*>(v.coefs) + off, v.quantStep[base][0], v.quantStep[base][4],
                            at.lx, at.ly, at.lz, at.fx, at.fy, at.fz);
  const BrickRecord rec = v.records[uint64_t(base) * v.slotCount + at.slot];
  if (v.precision == Precision::Fp16) {
    const CoefReader16 read{static_cast<const uint16_t*>(v.coefs) + 3 * off};
    return sampleBrick(rec, read, at.lx, at.ly, at.lz, at.fx, at.fy, at.fz);
  }
  const CoefReader32 read{static_cast<const float*>(v.coefs) + 3 * off};
  return sampleBrick(rec, read, at.lx, at.ly, at.lz, at.fx, at.fy, at.fz);
}

// Decodes the brick in `slot` of base `base` into out[ch][c] (decodeBrick / decodeQuantBrick).
// Returns false, leaving out untouched, where the base has no light in that brick.
CANOPY_HD inline bool decodeSlot(const ChaarView& v, int base, uint32_t slot, float out[3][kBrickValues]) {
  const uint64_t off = v.baseCoefOffset[base];
  const uint64_t r = uint64_t(base) * v.slotCount + slot;
  if (v.precision == Precision::Quant) {
    const QuantRecord q = loadQuantRecord(v.quantRecords + r);
    if (q.mask() == 0) return false;
    decodeQuantBrick(q, static_cast<const uint64_t*>(v.coefs) + off, v.quantStep[base], out);
    return true;
  }
  const BrickRecord rec = v.records[r];
  if (rec.mask() == 0) return false;
  if (v.precision == Precision::Fp16)
    decodeBrick(rec, CoefReader16{static_cast<const uint16_t*>(v.coefs) + 3 * off}, out);
  else
    decodeBrick(rec, CoefReader32{static_cast<const float*>(v.coefs) + 3 * off}, out);
  return true;
}

}  // namespace canopy::haar
