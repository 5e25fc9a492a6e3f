// haar_encode.h: the CPU encoder of .chaar files (no OpenVDB: it works on dense arrays).
//
// Per base: split the lattice into bricks (3^3 cells + forward border, haar_brick.h), lift each
// non-empty brick once (double precision, rounded to float), then encode at a threshold T: keep the
// average and every detail coefficient with max(|R|,|G|,|B|) > T, round the kept ones to the
// storage precision, and measure the error by decoding with the same decoder the readers use.
// A brick is stored raw (its nonzero values, no transform) instead when that is no larger and no
// less exact, and at T = 0 whenever raw has the smaller error, so threshold 0 reproduces fp32 input
// exactly (a float Haar round trip is not always exact).
//
// Error measures (per base, against the input values, channel-wise):
//   maxError  max |decoded - input| over every stored texel (each brick's 4^3, borders included),
//             so it bounds the error of any trilinear sample taken from the file;
//   rmsError  sqrt(sum over lattice cells and channels of (decoded - input)^2 / (3 * cells)),
//             each cell decoded from the brick that owns it, empty space counted (volume RMS);
//   psnr      20 log10(valueMax / rmsError) dB, valueMax = the largest input value of the base.
// searchThreshold(E) finds a threshold whose measured maxError <= E (bisection over the distinct
// coefficient magnitudes, every probe measured; the result is one that was measured feasible).
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "formats/chaar.h"

namespace canopy::haar {

struct LatticeGeom {
  int32_t min[3] = {0, 0, 0};
  int32_t max[3] = {0, 0, 0};
  int64_t dims[3] = {1, 1, 1};
  int32_t brickDims[3] = {1, 1, 1};
  uint64_t cells = 1;
  uint64_t bricks = 1;
  // Throws invalidInput(name + ...) for empty or absurd bounds.
  static LatticeGeom fromBounds(const int32_t min[3], const int32_t max[3], const std::string& name);
};

// One base over the whole lattice box: 3 floats per cell, x fastest.
struct DenseLight {
  std::vector<float> rgb;
  uint64_t activeVoxels = 0;  // voxels the input file stored (for the "sparse bytes" figure)
};

// One base encoded at one threshold.
struct BaseCode {
  float threshold = 0;
  std::vector<BrickRecord> bricks;  // one per brick of the lattice (mask 0 = empty), running `first`
  std::vector<float> coefs;         // 3 per kept coefficient, already rounded to the precision
  uint64_t coefCount = 0;
  uint32_t brickCount = 0, rawBrickCount = 0;
  double maxError = 0, sumSqError = 0;  // sumSqError over lattice cells and channels
  // Quant: per brick of the lattice its record (running bit offsets; `bricks` then holds the same
  // masks), the base's bit stream (without the end word) and its step (= threshold).
  std::vector<QuantRecord> quant;
  std::vector<uint64_t> words;
  // Bytes of this base's COEFS share (Quant: its words and the end word).
  uint64_t coefBytes(Precision p) const {
    return p == Precision::Quant ? (words.size() + 1) * 8 : coefCount * (p == Precision::Fp16 ? 6 : 12);
  }
};

class LiftedBase {
 public:
  // Validates the values (finite; within fp16 range for fp16) and lifts every non-empty brick.
  // `name` ("file.vdb grid B03") prefixes errors.
  LiftedBase(const LatticeGeom& geom, const DenseLight& light, Precision precision, std::string name);

  // Quant: `threshold` is the step T (haar_brick.h); it must be at least minQuantStep().
  BaseCode encode(float threshold) const;
  // Quant: the smallest step at which every coefficient fits kQuantMaxLevel (0 for an all-zero base).
  float minQuantStep() const { return minQuantStep_; }
  // Largest probed threshold with maxError <= maxError. Throws unsupported if even threshold 0
  // cannot meet it (fp16 rounding). `probes` receives the number of encodes tried.
  float searchThreshold(float maxError, int* probes = nullptr) const;

  double valueMax() const { return valueMax_; }
  uint64_t activeVoxels() const { return light_.activeVoxels; }
  const std::vector<uint8_t>& nonEmpty() const { return nonEmpty_; }  // per brick of the lattice

 private:
  struct Result {
    uint64_t mask;
    bool raw;
    double err;
    double sumSq;
  };
  Result encodeBrick(size_t k, float threshold, float* coefOut) const;
  // Quant: quantises brick k with the base's steps (quantSteps), as a raw brick where its Haar
  // form keeps more than kQuantRawAbove coefficients; fills the record's mask, widths and raw flag
  // and writes its fields from bit 0 of `words` (which must hold kQuantBrickWords zeroed words).
  Result encodeQuantBrick(size_t k, const float step[kQuantSteps], QuantRecord& rec, uint64_t* words) const;
  BaseCode encodeQuant(float step) const;
  float searchQuantStep(float maxError, int* probes) const;
  void gather(int64_t brick, float out[3][kBrickValues], uint8_t* coreInside) const;

  const LatticeGeom& geom_;
  const DenseLight& light_;
  Precision precision_;
  std::string name_;
  double valueMax_ = 0;
  std::vector<uint8_t> nonEmpty_;
  std::vector<int64_t> brickIds_;  // non-empty bricks in brick order
  std::vector<float> lifted_;      // 3*64 per non-empty brick: [ch][c] (Quant: of Y, R-Y, B-Y)
  float minQuantStep_ = 0;
};

struct BaseReport {
  uint32_t base = 0;
  int32_t direction[3] = {0, 0, 0};
  float threshold = 0;
  double maxError = 0, rmsError = 0, psnr = 0, valueMax = 0;  // psnr: +inf when rms == 0
  uint64_t denseBytes = 0, sparseBytes = 0, compressedBytes = 0;
  uint32_t bricks = 0, rawBricks = 0;
  uint64_t coefficients = 0;
  int probes = 0;
};

struct OverallReport {
  uint64_t denseBytes = 0, sparseBytes = 0, fileBytes = 0;
  double maxError = 0, rmsError = 0, psnr = 0, valueMax = 0;
  uint32_t slots = 0;
};

// Assembles encoded bases into a ChaarData (slot table = bricks non-empty in any base).
struct ChaarAssembly {
  LatticeGeom geom;
  Precision precision = Precision::Fp32;
  double indexToModel[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  float threshold = -1, maxErrorTarget = -1;
  std::string meta = "{}";
  std::vector<BaseCode> codes;
  std::vector<std::array<int32_t, 3>> directions;
  std::vector<uint32_t> flags;  // ChaarBaseFlags per base (empty: none)
  std::vector<double> valueMax;
};
ChaarData assembleChaar(const ChaarAssembly& a);

// Reports for an assembled file (bytes after = this base's records + coefficients; overall =
// the whole file). activeVoxels per base for the sparse figure.
std::vector<BaseReport> baseReports(const ChaarData& d, const ChaarAssembly& a,
                                    const std::vector<uint64_t>& activeVoxels, uint64_t fileBytes,
                                    OverallReport& overall);

// Exact file size the assembly would serialize to, without building it (for sweeps): coefBytes =
// the sum of the bases' BaseCode::coefBytes.
uint64_t chaarFileSize(uint32_t baseCount, uint64_t bricks, uint32_t slots, uint64_t coefBytes,
                       Precision precision, size_t metaBytes);

double psnrOf(double peak, double rms);

}  // namespace canopy::haar
