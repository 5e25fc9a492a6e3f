// haar_encode.cpp: see haar_encode.h.
#include "formats/haar_encode.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "canopy/errors.h"
#include "canopy/parallel.h"

namespace canopy::haar {

LatticeGeom LatticeGeom::fromBounds(const int32_t mn[3], const int32_t mx[3], const std::string& name) {
  LatticeGeom g;
  g.cells = 1;
  g.bricks = 1;
  for (int a = 0; a < 3; ++a) {
    g.min[a] = mn[a];
    g.max[a] = mx[a];
    g.dims[a] = int64_t(mx[a]) - mn[a] + 1;
    if (g.dims[a] < 1 || g.dims[a] > kMaxLatticeEdge)
      throw invalidInput(name + ": lattice edge " + std::to_string(g.dims[a]) + " on axis " +
                         std::to_string(a) + " is empty or larger than " +
                         std::to_string(kMaxLatticeEdge));
    if (std::abs(int64_t(mn[a])) >= (int64_t(1) << 24) || std::abs(int64_t(mx[a])) >= (int64_t(1) << 24))
      throw invalidInput(name + ": lattice bounds beyond +-2^24 (not exact in float)");
    g.brickDims[a] = int32_t((g.dims[a] + kBrickCore - 1) / kBrickCore);
    g.cells *= uint64_t(g.dims[a]);
    g.bricks *= uint64_t(g.brickDims[a]);
  }
  return g;
}

namespace {
float quantize(float v, Precision p) { return p == Precision::Fp16 ? halfToFloat(floatToHalf(v)) : v; }

// Words a quantised brick's fields can take (64 coefficients x 3 fields x 15 bits), plus the one a
// 64-bit window reads past them.
constexpr int kQuantBrickWords = (kBrickValues * 3 * kQuantMaxWidth + 63) / 64 + 1;

// Channel ch of the quantised codec's colour space at value c of a gathered brick: Y = G, R - Y,
// B - Y (exact in double).
double quantChannel(const float v[3][kBrickValues], int ch, int c) {
  return ch == 0 ? double(v[1][c]) : double(v[ch == 1 ? 0 : 2][c]) - double(v[1][c]);
}

// Two's-complement bits that hold q (0 for q = 0).
uint32_t fieldWidth(int32_t q) {
  if (q == 0) return 0;
  uint32_t w = 1;
  while (q < -(int32_t(1) << (w - 1)) || q > (int32_t(1) << (w - 1)) - 1) ++w;
  return w;
}

// A decoded brick against its input: the max |error| over all 4^3 texels and channels, and the sum
// of squared errors over the texels the brick owns (its core inside the lattice). Exact in double.
void brickError(const float dec[3][kBrickValues], const float orig[3][kBrickValues], const uint8_t inside[kBrickValues],
                double& maxErr, double& sumSq) {
  maxErr = 0;
  sumSq = 0;
  for (int ch = 0; ch < 3; ++ch)
    for (int c = 0; c < kBrickValues; ++c) {
      const double e = std::fabs(double(dec[ch][c]) - double(orig[ch][c]));
      maxErr = std::max(maxErr, e);
      if (inside[c]) sumSq += e * e;
    }
}

// ORs the low n (<= 64) bits of v into the stream at bit pos (the words there are zero).
void putBits(uint64_t* words, uint64_t pos, uint64_t v, uint32_t n) {
  if (n == 0) return;
  if (n < 64) v &= (uint64_t(1) << n) - 1u;
  const uint32_t sh = uint32_t(pos & 63u);
  words[pos >> 6] |= v << sh;
  if (sh && sh + n > 64) words[(pos >> 6) + 1] |= v >> (64u - sh);
}
}  // namespace

LiftedBase::LiftedBase(const LatticeGeom& geom, const DenseLight& light, Precision precision,
                       std::string name)
    : geom_(geom), light_(light), precision_(precision), name_(std::move(name)) {
  if (light.rgb.size() != 3 * geom.cells)
    throw runtimeError(name_ + ": dense light has " + std::to_string(light.rgb.size()) +
                       " floats, lattice needs " + std::to_string(3 * geom.cells));
  double vmax = 0;
  for (size_t i = 0; i < light.rgb.size(); ++i) {
    const float v = light.rgb[i];
    if (!std::isfinite(v)) {
      const uint64_t cell = i / 3;
      const int64_t x = int64_t(cell % uint64_t(geom.dims[0]));
      const int64_t y = int64_t(cell / uint64_t(geom.dims[0]) % uint64_t(geom.dims[1]));
      const int64_t z = int64_t(cell / uint64_t(geom.dims[0] * geom.dims[1]));
      throw invalidInput(name_ + ": non-finite value at (" + std::to_string(x + geom.min[0]) + "," +
                         std::to_string(y + geom.min[1]) + "," + std::to_string(z + geom.min[2]) + ")");
    }
    vmax = std::max(vmax, double(std::fabs(v)));
  }
  valueMax_ = vmax;
  if (precision == Precision::Fp16 && vmax > kHalfMax)
    throw unsupported(name_ + ": values up to " + formatNumber(vmax) +
                      " exceed the fp16 range (65504); use --precision fp32");

  nonEmpty_.assign(geom.bricks, 0);
  parallelFor(int64_t(geom.bricks), [&](int64_t b) {
    float v[3][kBrickValues];
    uint8_t inside[kBrickValues];
    gather(b, v, inside);
    for (int ch = 0; ch < 3 && !nonEmpty_[size_t(b)]; ++ch)
      for (int c = 0; c < kBrickValues; ++c)
        if (v[ch][c] != 0.0f) {
          nonEmpty_[size_t(b)] = 1;
          break;
        }
  }, 64);
  for (uint64_t b = 0; b < geom.bricks; ++b)
    if (nonEmpty_[b]) brickIds_.push_back(int64_t(b));
  lifted_.resize(brickIds_.size() * 3 * kBrickValues);
  std::vector<double> valuePeak(brickIds_.size(), 0.0);  // largest |value| of the brick (Quant: |Y|, |R-Y|, |B-Y|)
  parallelFor(int64_t(brickIds_.size()), [&](int64_t k) {
    float v[3][kBrickValues];
    uint8_t inside[kBrickValues];
    gather(brickIds_[size_t(k)], v, inside);
    for (int ch = 0; ch < 3; ++ch) {
      double d[kBrickValues];
      for (int c = 0; c < kBrickValues; ++c) {
        d[c] = precision_ == Precision::Quant ? quantChannel(v, ch, c) : double(v[ch][c]);
        valuePeak[size_t(k)] = std::max(valuePeak[size_t(k)], std::fabs(d[c]));
      }
      liftBrick(d);
      for (int c = 0; c < kBrickValues; ++c) lifted_[size_t(k) * 192 + ch * 64 + c] = float(d[c]);
    }
  }, 64);
  if (precision_ == Precision::Quant) {
    // The largest |coefficient| / sqrt(2)^(fine axes) (and |value| / kQuantRawFactor, should the
    // brick be stored raw), over kQuantMaxLevel - 1 (one level of margin for the rounding of the
    // steps): the smallest step at which every level fits 15 bits.
    double worst = 0;
    for (size_t k = 0; k < brickIds_.size(); ++k) {
      worst = std::max(worst, valuePeak[k] / double(kQuantRawFactor));
      for (int ch = 0; ch < 3; ++ch)
        for (int c = 0; c < kBrickValues; ++c)
          worst = std::max(worst, std::fabs(double(lifted_[k * 192 + size_t(ch) * 64 + size_t(c)])) /
                                      std::pow(kQuantFineFactor, int(fineDetailAxes(uint32_t(c)))));
    }
    minQuantStep_ = float(worst / double(kQuantMaxLevel - 1));
  }
}

void LiftedBase::gather(int64_t brick, float out[3][kBrickValues], uint8_t* coreInside) const {
  const int64_t bx = brick % geom_.brickDims[0];
  const int64_t by = brick / geom_.brickDims[0] % geom_.brickDims[1];
  const int64_t bz = brick / (int64_t(geom_.brickDims[0]) * geom_.brickDims[1]);
  for (int z = 0; z < kBrickEdge; ++z)
    for (int y = 0; y < kBrickEdge; ++y)
      for (int x = 0; x < kBrickEdge; ++x) {
        const int64_t gx = bx * kBrickCore + x, gy = by * kBrickCore + y, gz = bz * kBrickCore + z;
        const int c = brickIndex(x, y, z);
        const bool in = gx < geom_.dims[0] && gy < geom_.dims[1] && gz < geom_.dims[2];
        coreInside[c] = in && x < kBrickCore && y < kBrickCore && z < kBrickCore;
        for (int ch = 0; ch < 3; ++ch)
          out[ch][c] = in ? light_.rgb[size_t(3 * ((gz * geom_.dims[1] + gy) * geom_.dims[0] + gx) + ch)] : 0.0f;
      }
}

LiftedBase::Result LiftedBase::encodeBrick(size_t k, float threshold, float* coefOut) const {
  float orig[3][kBrickValues];
  uint8_t inside[kBrickValues];
  gather(brickIds_[k], orig, inside);
  const float* L = &lifted_[k * 192];

  auto measure = [&](uint64_t mask, bool raw, const float* q, Result& r) {
    BrickRecord rec;
    rec.set(mask, 0, raw);
    float dec[3][kBrickValues];
    decodeBrick(rec, CoefReader32{q}, dec);
    r.mask = mask;
    r.raw = raw;
    brickError(dec, orig, inside, r.err, r.sumSq);
  };

  // Haar: the average always, details with any channel above the threshold.
  uint64_t mask = 1;
  for (int c = 1; c < kBrickValues; ++c) {
    const float m = std::max(std::fabs(L[c]), std::max(std::fabs(L[64 + c]), std::fabs(L[128 + c])));
    if (m > threshold) mask |= uint64_t(1) << c;
  }
  float q[3 * kBrickValues];
  int n = 0;
  for (int c = 0; c < kBrickValues; ++c)
    if ((mask >> c) & 1u) {
      for (int ch = 0; ch < 3; ++ch) q[3 * n + ch] = quantize(L[ch * 64 + c], precision_);
      ++n;
    }
  Result best;
  measure(mask, false, q, best);

  {
    // The raw brick (its nonzero values, no transform) replaces the Haar one when it is no larger
    // and no less exact (typical for bricks at the edge of the light, mostly zeros), and at
    // threshold 0 (a lossless request) whenever it reconstructs better.
    uint64_t rmask = 0;
    float rq[3 * kBrickValues];
    int rn = 0;
    for (int c = 0; c < kBrickValues; ++c)
      if (orig[0][c] != 0.0f || orig[1][c] != 0.0f || orig[2][c] != 0.0f) {
        rmask |= uint64_t(1) << c;
        for (int ch = 0; ch < 3; ++ch) rq[3 * rn + ch] = quantize(orig[ch][c], precision_);
        ++rn;
      }
    Result raw;
    measure(rmask, true, rq, raw);
    const bool smallerAndAsGood = rn <= n && raw.err <= best.err;
    const bool losslessBetter = threshold == 0.0f && (raw.err < best.err || (raw.err == best.err && rn < n));
    if (smallerAndAsGood || losslessBetter) {
      best = raw;
      if (coefOut) std::memcpy(coefOut, rq, sizeof(float) * 3 * size_t(rn));
      return best;
    }
  }
  if (coefOut) std::memcpy(coefOut, q, sizeof(float) * 3 * size_t(n));
  return best;
}

LiftedBase::Result LiftedBase::encodeQuantBrick(size_t k, const float step[kQuantSteps], QuantRecord& rec,
                                                uint64_t* words) const {
  float orig[3][kBrickValues];
  uint8_t inside[kBrickValues];
  gather(brickIds_[k], orig, inside);
  const float* L = &lifted_[k * 192];
  int32_t q[kBrickValues][3];
  uint64_t mask = 0;
  for (int c = 0; c < kBrickValues; ++c) {
    const double st = double(step[fineDetailAxes(uint32_t(c))]);
    for (int ch = 0; ch < 3; ++ch) {
      const double v = double(L[ch * 64 + c]) / st;
      int64_t qi = std::fabs(v) < double(kQuantDeadZone) ? 0 : std::llround(v);
      qi = std::max<int64_t>(-kQuantMaxLevel, std::min<int64_t>(kQuantMaxLevel, qi));  // encode() checked the step
      q[c][ch] = int32_t(qi);
      if (qi) mask |= uint64_t(1) << c;
    }
  }
  // Dense bricks raw: their values (Y, R-Y, B-Y) at the raw step, rounded (a sample then needs at
  // most 8 fields; the coefficients' dead zone does not apply to values).
  const bool raw = popcount64(mask) > kQuantRawAbove;
  if (raw) {
    mask = 0;
    for (int c = 0; c < kBrickValues; ++c) {
      for (int ch = 0; ch < 3; ++ch) {
        const double v = quantChannel(orig, ch, c) / double(step[4]);
        const int64_t qi = std::max<int64_t>(-kQuantMaxLevel, std::min<int64_t>(kQuantMaxLevel, std::llround(v)));
        q[c][ch] = int32_t(qi);
        if (qi) mask |= uint64_t(1) << c;
      }
    }
  }
  // Widths: group 0 the average's (Haar), group 1 the details' or (raw) every value's.
  auto group = [&](int c) { return raw || c != 0 ? 1 : 0; };
  uint32_t w[2][3] = {};
  for (int c = 0; c < kBrickValues; ++c)
    if ((mask >> c) & 1u)
      for (int ch = 0; ch < 3; ++ch) w[group(c)][ch] = std::max(w[group(c)][ch], fieldWidth(q[c][ch]));
  rec = QuantRecord{};
  rec.maskLo = uint32_t(mask);
  rec.maskHi = uint32_t(mask >> 32);
  for (int g = 0; g < 2; ++g)
    for (int ch = 0; ch < 3; ++ch) rec.widths |= w[g][ch] << (4 * (3 * g + ch));
  if (raw) rec.widths |= kQuantRawBit;
  uint64_t pos = 0;
  for (int c = 0; c < kBrickValues; ++c)
    if ((mask >> c) & 1u)
      for (int ch = 0; ch < 3; ++ch) {
        putBits(words, pos, uint64_t(uint32_t(q[c][ch])), w[group(c)][ch]);
        pos += w[group(c)][ch];
      }
  // Measured with the readers' decoder.
  float dec[3][kBrickValues];
  decodeQuantBrick(rec, words, step, dec);
  Result r{mask, raw, 0.0, 0.0};
  brickError(dec, orig, inside, r.err, r.sumSq);
  return r;
}

BaseCode LiftedBase::encodeQuant(float T) const {
  if (!(T > 0) || !std::isfinite(T))
    throw unsupported(name_ + ": quantised coefficients need a threshold (their step) > 0, not " + formatNumber(T));
  if (T >= 1e30f)  // the reader's bound: 2^14 levels of sqrt(2)^3 T stay finite
    throw unsupported(name_ + ": quantisation step " + formatNumber(T) + " is 1e30 or more (values this large need "
                      "--precision fp32)");
  if (T < minQuantStep_)
    throw unsupported(name_ + ": threshold " + formatNumber(T) + " is below " + formatNumber(minQuantStep_) +
                      ", where a quantised coefficient would need more than 15 bits; raise it or use --precision "
                      "fp16 or fp32");
  float step[kQuantSteps];
  quantSteps(T, step);
  const size_t n = brickIds_.size();
  std::vector<Result> res(n);
  std::vector<QuantRecord> recs(n);
  std::vector<uint64_t> scratch(n * kQuantBrickWords, 0);
  parallelFor(int64_t(n), [&](int64_t k) {
    res[size_t(k)] = encodeQuantBrick(size_t(k), step, recs[size_t(k)], &scratch[size_t(k) * kQuantBrickWords]);
  }, 16);
  BaseCode code;
  code.threshold = T;
  code.bricks.assign(geom_.bricks, BrickRecord{});
  code.quant.assign(geom_.bricks, QuantRecord{});
  for (size_t k = 0; k < n; ++k) {
    code.quant[size_t(brickIds_[k])] = recs[k];
    code.brickCount += res[k].mask != 0;
    code.rawBrickCount += res[k].raw;
    code.maxError = std::max(code.maxError, res[k].err);
    code.sumSqError += res[k].sumSq;
  }
  // Running entry indices and bit offsets in brick order (the slot order); each brick's fields
  // appended to the stream.
  uint64_t next = 0, bit = 0, total = 0;
  for (const QuantRecord& r : code.quant) total += r.bits();
  if (total > 0xffffffffull)
    throw unsupported(name_ + ": more than 2^32 bits in one base's quantised stream; raise the threshold");
  code.words.assign(size_t((total + 63) / 64), 0);
  size_t k = 0;
  for (uint64_t b = 0; b < geom_.bricks; ++b) {
    QuantRecord& r = code.quant[b];
    code.bricks[b].set(r.mask(), uint32_t(next), r.raw());
    r.bitOffset = uint32_t(bit);
    const uint64_t bits = r.bits();
    if (bits) {
      while (brickIds_[k] != int64_t(b)) ++k;
      const uint64_t* from = &scratch[k * kQuantBrickWords];
      for (uint64_t i = 0; 64 * i < bits; ++i) putBits(code.words.data(), bit + 64 * i, from[i], uint32_t(std::min<uint64_t>(64, bits - 64 * i)));
    }
    bit += bits;
    next += uint64_t(popcount64(r.mask()));
  }
  code.coefCount = next;
  return code;
}

float LiftedBase::searchQuantStep(float maxError, int* probes) const {
  const size_t n = brickIds_.size();
  int tries = 0;
  auto errorAt = [&](float T) {
    ++tries;
    float step[kQuantSteps];
    quantSteps(T, step);
    std::vector<double> err(n);
    parallelFor(int64_t(n), [&](int64_t k) {
      QuantRecord rec;
      uint64_t words[kQuantBrickWords] = {};
      err[size_t(k)] = encodeQuantBrick(size_t(k), step, rec, words).err;
    }, 16);
    double m = 0;
    for (double e : err) m = std::max(m, e);
    return m;
  };
  if (minQuantStep_ == 0) {  // no light at all: any step is exact
    if (probes) *probes = 0;
    return 1.0f;
  }
  float lo = minQuantStep_, hi = float(4 * valueMax_ + double(minQuantStep_));
  const double e0 = errorAt(lo);
  if (e0 > double(maxError)) {
    if (probes) *probes = tries;
    throw unsupported(name_ + ": --max-error " + formatNumber(maxError) + " cannot be met with quantised "
                      "coefficients: the finest step gives " + formatNumber(e0) + "; use --precision fp16 or fp32");
  }
  if (errorAt(hi) <= double(maxError)) {
    lo = hi;
  } else {
    // Bisection in log space; lo is always a measured feasible step.
    for (int it = 0; it < 40; ++it) {
      const float mid = float(std::sqrt(double(lo) * double(hi)));
      if (mid <= lo || mid >= hi) break;
      if (errorAt(mid) <= double(maxError))
        lo = mid;
      else
        hi = mid;
    }
  }
  if (probes) *probes = tries;
  return lo;
}

BaseCode LiftedBase::encode(float threshold) const {
  if (precision_ == Precision::Quant) return encodeQuant(threshold);
  const size_t n = brickIds_.size();
  std::vector<Result> res(n);
  std::vector<float> scratch(n * 192);
  parallelFor(int64_t(n), [&](int64_t k) {
    res[size_t(k)] = encodeBrick(size_t(k), threshold, &scratch[size_t(k) * 192]);
  }, 16);
  BaseCode code;
  code.threshold = threshold;
  code.bricks.assign(geom_.bricks, BrickRecord{});
  uint64_t next = 0;
  for (size_t k = 0; k < n; ++k) {
    const Result& r = res[k];
    const int cnt = popcount64(r.mask);
    if (next + uint64_t(cnt) > uint64_t(BrickRecord::kMaxFirst))
      throw unsupported(name_ + ": more than 2^31 coefficients in one base");
    code.bricks[size_t(brickIds_[k])].set(r.mask, 0, r.raw);
    code.coefs.insert(code.coefs.end(), &scratch[k * 192], &scratch[k * 192] + 3 * cnt);
    next += uint64_t(cnt);
    code.brickCount += r.mask != 0;
    code.rawBrickCount += (r.mask != 0) && r.raw;
    code.maxError = std::max(code.maxError, r.err);
    code.sumSqError += r.sumSq;
  }
  // `first` is the running sum in brick order; bricks without light keep first = running sum too,
  // so the order survives dropping them into slots.
  next = 0;
  for (auto& rec : code.bricks) {
    rec.set(rec.mask(), uint32_t(next), rec.raw());
    next += uint64_t(popcount64(rec.mask()));
  }
  code.coefCount = next;
  return code;
}

float LiftedBase::searchThreshold(float maxError, int* probes) const {
  if (precision_ == Precision::Quant) return searchQuantStep(maxError, probes);
  const size_t n = brickIds_.size();
  int tries = 0;
  auto feasible = [&](float t) {
    ++tries;
    std::vector<double> err(n);
    parallelFor(int64_t(n), [&](int64_t k) { err[size_t(k)] = encodeBrick(size_t(k), t, nullptr).err; }, 16);
    double m = 0;
    for (double e : err) m = std::max(m, e);
    return m <= double(maxError);
  };
  // Candidates: 0 and every distinct detail magnitude (the error only changes at those).
  std::vector<float> cand;
  cand.reserve(n * 63 + 1);
  cand.push_back(0.0f);
  for (size_t k = 0; k < n; ++k) {
    const float* L = &lifted_[k * 192];
    for (int c = 1; c < kBrickValues; ++c) {
      const float m = std::max(std::fabs(L[c]), std::max(std::fabs(L[64 + c]), std::fabs(L[128 + c])));
      if (m > 0) cand.push_back(m);
    }
  }
  std::sort(cand.begin(), cand.end());
  cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
  if (!feasible(0.0f)) {
    if (probes) *probes = tries;
    const float e0 = float(encode(0.0f).maxError);
    throw unsupported(name_ + ": --max-error " + formatNumber(maxError) +
                      " cannot be met: threshold 0 already gives " + formatNumber(e0) +
                      (precision_ == Precision::Fp16 ? " (fp16 rounding); use --precision fp32" : ""));
  }
  size_t lo = 0, hi = cand.size() - 1;
  if (feasible(cand[hi])) {
    lo = hi;
  } else {
    while (hi - lo > 1) {
      const size_t mid = lo + (hi - lo) / 2;
      if (feasible(cand[mid]))
        lo = mid;
      else
        hi = mid;
    }
  }
  if (probes) *probes = tries;
  return cand[lo];
}

// ---------------------------------------------------------------------------------------------
ChaarData assembleChaar(const ChaarAssembly& a) {
  const LatticeGeom& g = a.geom;
  const uint32_t nb = uint32_t(a.codes.size());
  if (nb < 1 || nb > uint32_t(kMaxBases) || a.directions.size() != nb || a.valueMax.size() != nb)
    throw runtimeError("assembleChaar: bad base count");
  ChaarData d;
  ChaarHeader& h = d.header;
  std::memset(&h, 0, sizeof h);
  h.baseCount = nb;
  h.precision = uint32_t(a.precision);
  for (int i = 0; i < 3; ++i) {
    h.latticeMin[i] = g.min[i];
    h.latticeMax[i] = g.max[i];
    h.brickDims[i] = g.brickDims[i];
  }
  std::memcpy(h.indexToModel, a.indexToModel, sizeof h.indexToModel);
  h.threshold = a.threshold;
  h.maxErrorTarget = a.maxErrorTarget;
  d.meta = a.meta;

  d.slots.assign(g.bricks, kEmptySlot);
  uint32_t slots = 0;
  for (uint64_t b = 0; b < g.bricks; ++b) {
    bool any = false;
    for (uint32_t k = 0; k < nb && !any; ++k) any = a.codes[k].bricks[b].mask() != 0;
    if (any) d.slots[b] = slots++;
  }
  h.slotCount = slots;
  const bool quant = a.precision == Precision::Quant;
  d.records.resize(uint64_t(nb) * slots);
  if (quant) d.quantRecords.resize(d.records.size());
  d.bases.resize(nb);
  uint64_t total = 0;
  for (uint32_t k = 0; k < nb; ++k) {
    const BaseCode& c = a.codes[k];
    for (uint64_t b = 0; b < g.bricks; ++b)
      if (d.slots[b] != kEmptySlot) {
        d.records[uint64_t(k) * slots + d.slots[b]] = c.bricks[b];
        if (quant) d.quantRecords[uint64_t(k) * slots + d.slots[b]] = c.quant[b];
      }
    ChaarBaseEntry& e = d.bases[k];
    std::memset(&e, 0, sizeof e);
    for (int i = 0; i < 3; ++i) e.direction[i] = a.directions[k][size_t(i)];
    e.flags = k < a.flags.size() ? a.flags[k] : 0u;
    e.coefOffset = total;
    e.coefCount = c.coefCount;
    e.threshold = c.threshold;
    e.maxError = float(c.maxError);
    e.rmsError = float(std::sqrt(c.sumSqError / (3.0 * double(g.cells))));
    e.valueMax = float(a.valueMax[k]);
    e.brickCount = c.brickCount;
    e.rawBrickCount = c.rawBrickCount;
    if (quant) {
      e.coefOffset = d.quantWords.size();
      e.quantStep = c.threshold;
      e.quantWords = uint32_t(c.words.size());
      d.quantWords.insert(d.quantWords.end(), c.words.begin(), c.words.end());
      d.quantWords.push_back(0);  // the end word a 64-bit window may read
    }
    total += c.coefCount;
  }
  if (quant) {
    // The streams are in quantWords.
  } else if (a.precision == Precision::Fp16) {
    d.coefs16.reserve(3 * total);
    for (const auto& c : a.codes)
      for (float v : c.coefs) d.coefs16.push_back(floatToHalf(v));
  } else {
    d.coefs32.reserve(3 * total);
    for (const auto& c : a.codes) d.coefs32.insert(d.coefs32.end(), c.coefs.begin(), c.coefs.end());
  }
  h.coefCount = total;
  return d;
}

double psnrOf(double peak, double rms) {
  if (rms == 0) return std::numeric_limits<double>::infinity();
  if (peak == 0) return -std::numeric_limits<double>::infinity();
  return 20.0 * std::log10(peak / rms);
}

std::vector<BaseReport> baseReports(const ChaarData& d, const ChaarAssembly& a,
                                    const std::vector<uint64_t>& activeVoxels, uint64_t fileBytes,
                                    OverallReport& o) {
  std::vector<BaseReport> out;
  o = OverallReport{};
  double sumSq = 0;
  for (uint32_t k = 0; k < d.baseCount(); ++k) {
    const BaseCode& c = a.codes[k];
    BaseReport r;
    r.base = k;
    for (int i = 0; i < 3; ++i) r.direction[i] = a.directions[k][size_t(i)];
    r.threshold = c.threshold;
    r.maxError = c.maxError;
    r.rmsError = std::sqrt(c.sumSqError / (3.0 * double(a.geom.cells)));
    r.valueMax = a.valueMax[k];
    r.psnr = psnrOf(r.valueMax, r.rmsError);
    r.denseBytes = a.geom.cells * 12;
    r.sparseBytes = (k < activeVoxels.size() ? activeVoxels[k] : 0) * 12;
    r.compressedBytes = d.baseBytes(k);
    r.bricks = c.brickCount;
    r.rawBricks = c.rawBrickCount;
    r.coefficients = c.coefCount;
    out.push_back(r);
    o.denseBytes += r.denseBytes;
    o.sparseBytes += r.sparseBytes;
    o.maxError = std::max(o.maxError, r.maxError);
    o.valueMax = std::max(o.valueMax, r.valueMax);
    sumSq += c.sumSqError;
  }
  o.fileBytes = fileBytes;
  o.rmsError = std::sqrt(sumSq / (3.0 * double(a.geom.cells) * d.baseCount()));
  o.psnr = psnrOf(o.valueMax, o.rmsError);
  o.slots = d.header.slotCount;
  return out;
}

uint64_t chaarFileSize(uint32_t baseCount, uint64_t bricks, uint32_t slots, uint64_t coefBytes,
                       Precision precision, size_t metaBytes) {
  auto up = [](uint64_t v) { return (v + 15) / 16 * 16; };
  uint64_t s = sizeof(ChaarHeader);
  s = up(s) + metaBytes;
  s = up(s) + uint64_t(baseCount) * sizeof(ChaarBaseEntry);
  s = up(s) + bricks * 4;
  s = up(s) + uint64_t(baseCount) * slots * recordBytes(precision);
  s = up(s) + coefBytes;
  return s;
}

}  // namespace canopy::haar
