// Haar brick math, encoder guarantees and the random-access sampler (no OpenVDB, no files).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "canopy/errors.h"
#include "canopy/half.h"
#include "formats/haar_encode.h"
#include "formats/haar_view.h"
#include "synthetic_light.h"

using namespace canopy::haar;
using namespace canopy::haar::testing;

namespace {

// Trilinear sample of a dense decoded lattice (3 floats per cell), same clamp/convention as the
// compressed sampler, values outside the lattice = 0.
Rgb denseSample(const LatticeGeom& g, const std::vector<float>& dense, float x, float y, float z) {
  const float p[3] = {x, y, z};
  int i[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    const float q = clampf(p[a], float(g.min[a]), float(g.max[a]));
    const float fl = std::floor(q);
    i[a] = int(fl) - g.min[a];
    f[a] = q - fl;
  }
  auto at = [&](int64_t xx, int64_t yy, int64_t zz, int ch) -> float {
    if (xx >= g.dims[0] || yy >= g.dims[1] || zz >= g.dims[2]) return 0.0f;
    return dense[size_t(3 * ((zz * g.dims[1] + yy) * g.dims[0] + xx) + ch)];
  };
  float out[3];
  for (int ch = 0; ch < 3; ++ch) {
    float v[2][2][2];
    for (int dz = 0; dz < 2; ++dz)
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) v[dz][dy][dx] = at(i[0] + dx, i[1] + dy, i[2] + dz, ch);
    out[ch] = trilinear(v, f[0], f[1], f[2]);
  }
  return Rgb{out[0], out[1], out[2]};
}

// The rounding bound of a sample against the dense sample of the same values: 32 ulps of the
// largest sum of term magnitudes a footprint can have (27 coefficients, each at most the light's
// peak in magnitude, weights at most 1).
double sampleRounding(const DenseLight& light) {
  double peak = 0;
  for (float v : light.rgb) peak = std::max(peak, double(std::fabs(v)));
  return 32.0 / (1 << 24) * 27.0 * peak;
}

double maxAbsDiff(const std::vector<float>& a, const std::vector<float>& b) {
  double m = 0;
  for (size_t i = 0; i < a.size(); ++i) m = std::max(m, std::fabs(double(a[i]) - double(b[i])));
  return m;
}

}  // namespace

TEST(Half, KnownValuesAndRoundTrip) {
  EXPECT_EQ(canopy::floatToHalf(1.0f), 0x3c00);
  EXPECT_EQ(canopy::floatToHalf(-2.0f), 0xc000);
  EXPECT_EQ(canopy::floatToHalf(65504.0f), 0x7bff);
  EXPECT_EQ(canopy::floatToHalf(65520.0f), 0x7c00);       // rounds to infinity
  EXPECT_EQ(canopy::floatToHalf(5.9604645e-8f), 0x0001);  // smallest subnormal
  EXPECT_EQ(canopy::floatToHalf(2.9802322e-8f), 0x0000);  // half of it: tie to even -> 0
  EXPECT_EQ(canopy::floatToHalf(1.0f + 1.0f / 2048), 0x3c00);  // tie to even (down)
  EXPECT_EQ(canopy::floatToHalf(1.0f + 3.0f / 2048), 0x3c02);  // tie to even (up)
  for (uint32_t h = 0; h < 0x10000u; ++h) {
    if ((h & 0x7c00u) == 0x7c00u) continue;  // inf/NaN
    const float f = canopy::halfToFloat(uint16_t(h));
    EXPECT_EQ(canopy::floatToHalf(f), uint16_t(h)) << h;
  }
}

TEST(HaarMath, DissertationExample1D) {
  // §2.3: [4 19 44 0] -> [16.75 -5.25 -7.5 22]
  double v[4] = {4, 19, 44, 0};
  lift4(v, 1);
  EXPECT_DOUBLE_EQ(v[0], 16.75);
  EXPECT_DOUBLE_EQ(v[1], -5.25);
  EXPECT_DOUBLE_EQ(v[2], -7.5);
  EXPECT_DOUBLE_EQ(v[3], 22);
  float f[4] = {16.75f, -5.25f, -7.5f, 22.0f};
  unlift4(f, 1);
  EXPECT_EQ(f[0], 4.0f);
  EXPECT_EQ(f[1], 19.0f);
  EXPECT_EQ(f[2], 44.0f);
  EXPECT_EQ(f[3], 0.0f);
}

TEST(HaarMath, LiftUnliftBrickRoundTripsDyadicValuesExactly) {
  // Small integers: every intermediate is exact in float, so the round trip is exact.
  std::mt19937 rng(7);
  float v[64];
  double d[64];
  for (int c = 0; c < 64; ++c) d[c] = v[c] = float(int(rng() % 200) - 50);
  liftBrick(d);
  float f[64];
  for (int c = 0; c < 64; ++c) f[c] = float(d[c]);
  unliftBrick(f);
  for (int c = 0; c < 64; ++c) EXPECT_EQ(f[c], v[c]) << c;
}

// Basis function k (0..3) of one axis at positions 0..3: unlift4 of the unit coefficient vector
// (exact in float: the values are 0 and +-1). The sampler's weights are derived from this here,
// independently of haarAxisWeights.
void axisBasis(int k, float b[4]) {
  for (int i = 0; i < 4; ++i) b[i] = i == k ? 1.0f : 0.0f;
  unlift4(b, 1);
}
// Trilinear weight of axis coefficient k for a footprint at l with fraction f (raw: of value k);
// absolute: max |basis| over the two positions instead (the scale of the rounding error of
// decode-then-interpolate, whose lerp a + f (b - a) carries a's rounding even at f = 1).
double refAxisWeight(bool raw, int k, int l, double f, bool absolute = false) {
  float b[4];
  if (raw) {
    for (int i = 0; i < 4; ++i) b[i] = i == k ? 1.0f : 0.0f;
  } else {
    axisBasis(k, b);
  }
  if (absolute) return std::max(std::fabs(b[l]), std::fabs(b[l + 1]));
  return (1.0 - f) * b[l] + f * b[l + 1];
}

// The sampler's per-axis weights and needed-coefficient sets against that definition.
TEST(HaarMath, AxisWeightsInterpolateTheBasisFunctions) {
  for (int raw = 0; raw < 2; ++raw)
    for (int l = 0; l < 3; ++l)
      for (float f : {0.0f, 0.125f, 0.3f, 0.5f, 0.7f, 0.999f}) {
        float w[4];
        if (raw)
          rawAxisWeights(l, f, w);
        else
          haarAxisWeights(l, f, w);
        for (int k = 0; k < 4; ++k) {
          EXPECT_NEAR(w[k], refAxisWeight(raw, k, l, f), 1e-7) << raw << " " << l << " " << f << " " << k;
          EXPECT_EQ(pickWeight(w, uint32_t(k)), w[k]);
        }
      }
  for (int l = 0; l < 3; ++l)
    for (int k = 0; k < 4; ++k) {
      float b[4];
      axisBasis(k, b);
      EXPECT_EQ((axisNeedBits(l) >> k & 1u) != 0, b[l] != 0.0f || b[l + 1] != 0.0f) << l << " " << k;
    }
  for (int lz = 0; lz < 3; ++lz)
    for (int ly = 0; ly < 3; ++ly)
      for (int lx = 0; lx < 3; ++lx) {
        uint64_t want = 0, wantRaw = 0;
        for (int z = 0; z < 4; ++z)
          for (int y = 0; y < 4; ++y)
            for (int x = 0; x < 4; ++x) {
              if ((axisNeedBits(lx) >> x & 1u) && (axisNeedBits(ly) >> y & 1u) && (axisNeedBits(lz) >> z & 1u))
                want |= uint64_t(1) << brickIndex(x, y, z);
              if (x - lx >= 0 && x - lx <= 1 && y - ly >= 0 && y - ly <= 1 && z - lz >= 0 && z - lz <= 1)
                wantRaw |= uint64_t(1) << brickIndex(x, y, z);
            }
        EXPECT_EQ(footprintNeedMask(lx, ly, lz), want) << lx << ly << lz;
        EXPECT_EQ(coefficientBox(3u << lx, 3u << ly, 3u << lz), wantRaw) << lx << ly << lz;
      }
}

// The point sampler sums the footprint's kept coefficients times their weights; it must equal the
// exact (double) value of that sum, and trilinear interpolation of the fully decoded brick, within
// float rounding: 32 ulps (2^-24) of the sum of the terms' magnitudes (raw and Haar bricks, any
// mask, both precisions).
TEST(HaarMath, SampleBrickEqualsDecodeThenTrilinearWithinRounding) {
  constexpr double kUlps = 32.0 / (1 << 24);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-2.0f, 2.0f);
  double worst = 0;  // largest |sample - exact| / bound seen
  for (int trial = 0; trial < 1200; ++trial) {
    const bool raw = trial % 4 == 3;
    uint64_t mask = (uint64_t(rng()) << 32) | rng();
    if (trial % 5 == 0) mask &= (uint64_t(rng()) << 32) | rng();  // sparser
    if (trial % 3 == 1)  // a few coefficients: whole rows and z-slabs empty
      for (int k = 0; k < 3; ++k) mask &= (uint64_t(rng()) << 32) | rng();
    if (trial % 7 == 0) mask = 1;                                    // fast path
    BrickRecord rec;
    rec.set(mask, 5, raw);  // first = 5: not at the stream start
    std::vector<float> coefs(3 * (5 + 64));
    for (float& c : coefs) c = u(rng);
    std::vector<uint16_t> coefs16(coefs.size());
    for (size_t i = 0; i < coefs.size(); ++i) coefs16[i] = canopy::floatToHalf(coefs[i]);
    for (int prec = 0; prec < 2; ++prec) {
      float dec[3][kBrickValues];
      if (prec == 0)
        decodeBrick(rec, CoefReader32{coefs.data()}, dec);
      else
        decodeBrick(rec, CoefReader16{coefs16.data()}, dec);
      for (int s = 0; s < 30; ++s) {
        const int l[3] = {int(rng() % 3), int(rng() % 3), int(rng() % 3)};
        float f[3];
        for (float& x : f) x = (s % 3 == 0) ? float(rng() % 2) : std::uniform_real_distribution<float>(0, 1)(rng);
        const Rgb got = prec == 0 ? sampleBrick(rec, CoefReader32{coefs.data()}, l[0], l[1], l[2], f[0], f[1], f[2])
                                  : sampleBrick(rec, CoefReader16{coefs16.data()}, l[0], l[1], l[2], f[0], f[1], f[2]);
        for (int ch = 0; ch < 3; ++ch) {
          double exact = 0, scale = 0, scaleAbs = 0;
          uint32_t j = 0;
          for (int c = 0; c < 64; ++c) {
            if (!(mask >> c & 1u)) continue;
            const double v = prec == 0 ? coefs[3 * (5 + j) + ch] : canopy::halfToFloat(coefs16[3 * (5 + j) + ch]);
            ++j;
            const int k[3] = {c & 3, (c >> 2) & 3, c >> 4};
            double w = 1, wa = 1;
            for (int a = 0; a < 3; ++a) {
              w *= refAxisWeight(raw, k[a], l[a], f[a]);
              wa *= refAxisWeight(raw, k[a], l[a], f[a], true);
            }
            exact += v * w;
            scale += std::fabs(v * w);
            scaleAbs += std::fabs(v) * wa;
          }
          float t[2][2][2];
          for (int dz = 0; dz < 2; ++dz)
            for (int dy = 0; dy < 2; ++dy)
              for (int dx = 0; dx < 2; ++dx) t[dz][dy][dx] = dec[ch][brickIndex(l[0] + dx, l[1] + dy, l[2] + dz)];
          const double want = trilinear(t, f[0], f[1], f[2]);
          const double g = ch == 0 ? got.r : ch == 1 ? got.g : got.b;
          ASSERT_LE(std::fabs(g - exact), kUlps * scale) << "trial " << trial << " prec " << prec << " ch " << ch;
          ASSERT_LE(std::fabs(want - exact), kUlps * scaleAbs) << "trial " << trial << " prec " << prec << " ch " << ch;
          if (scale > 0) worst = std::max(worst, std::fabs(g - exact) / (kUlps * scale));
        }
      }
    }
  }
  EXPECT_LT(worst, 1.0);
  std::printf("sampleBrick vs the exact sum: largest error %.3f of the 32-ulp bound\n", worst);
}

// Threshold 0 reproduces fp32 input exactly (Haar bricks whose float round trip is exact, raw
// bricks otherwise), and fp16 within fp16 rounding.
TEST(HaarEncode, ThresholdZeroIsExactInFp32AndWithinRoundingInFp16) {
  const LatticeGeom g = makeGeom(13, 11, 10, -4, 2, 7);
  for (int kind = 0; kind < 2; ++kind) {
    std::vector<DenseLight> lights = {kind ? randomLight(g, 3) : smoothLight(g, 4)};
    const ChaarData d32 = encodeLights(g, lights, 0.0f);
    std::vector<float> dense;
    decodeBaseDense(d32, 0, dense);
    EXPECT_EQ(dense, lights[0].rgb) << "fp32 threshold 0 must be lossless";
    EXPECT_EQ(d32.bases[0].maxError, 0.0f);
    // Float Haar round trips are not always exact: bricks fall back to raw.
    EXPECT_GT(d32.bases[0].rawBrickCount, 0u);
    std::printf("threshold 0 fp32 (%s): %u of %u bricks raw\n", kind ? "random" : "smooth",
                d32.bases[0].rawBrickCount, d32.bases[0].brickCount);

    const ChaarData d16 = encodeLights(g, lights, 0.0f, -1.0f, Precision::Fp16);
    decodeBaseDense(d16, 0, dense);
    for (size_t i = 0; i < dense.size(); ++i) {
      // Raw bricks round each value once (<= 2^-11 relative); Haar bricks sum at most 7 rounded
      // coefficients each bounded by the brick's max |value| (<= 1 here): 7 * 2^-11 absolute.
      const double tol = 7.0 / 2048.0;
      ASSERT_LE(std::fabs(double(dense[i]) - lights[0].rgb[i]), tol) << i;
    }
  }
}

TEST(HaarEncode, MaxErrorIsNeverExceeded) {
  const LatticeGeom g = makeGeom(17, 14, 12);
  for (int kind = 0; kind < 2; ++kind)
    for (Precision p : {Precision::Fp32, Precision::Fp16, Precision::Quant})
      for (float E : {0.002f, 0.01f, 0.05f, 0.2f}) {
        const DenseLight light = kind ? randomLight(g, 99, 2.0f) : smoothLight(g, 9, 3.0f);
        LiftedBase lb(g, light, p, "t");
        float T;
        try {
          T = lb.searchThreshold(E);
        } catch (const canopy::Error& e) {
          // Only allowed where fp16 rounding, or the finest quantisation step, alone exceeds E
          // (checked below to be so).
          ASSERT_NE(p, Precision::Fp32) << e.what();
          EXPECT_GT(lb.encode(p == Precision::Quant ? lb.minQuantStep() : 0.0f).maxError, E);
          EXPECT_EQ(e.code(), canopy::ExitCode::Unsupported);
          continue;
        }
        const BaseCode c = lb.encode(T);
        EXPECT_LE(c.maxError, E) << "kind " << kind << " E " << E;
        // Independent check: decode the file and compare every cell with the input.
        const ChaarData d = encodeLights(g, {light}, 0.0f, E, p);
        std::vector<float> dense;
        decodeBaseDense(d, 0, dense);
        EXPECT_LE(maxAbsDiff(dense, light.rgb), double(E)) << "kind " << kind << " E " << E;
        if (E >= 0.05f && kind == 0) {
          EXPECT_GT(T, 0.0f) << "a loose bound must allow dropping details";
        }
      }
}

TEST(HaarEncode, ThresholdTradesSizeForError) {
  const LatticeGeom g = makeGeom(24, 24, 24);
  const DenseLight light = smoothLight(g, 3);
  LiftedBase lb(g, light, Precision::Fp32, "t");
  uint64_t lastCoefs = ~uint64_t(0);
  for (float T : {0.0f, 0.001f, 0.01f, 0.1f}) {
    const BaseCode c = lb.encode(T);
    EXPECT_LE(c.coefCount, lastCoefs);
    lastCoefs = c.coefCount;
  }
  // Empty bricks are not stored and a loose threshold leaves single-coefficient bricks.
  const BaseCode loose = lb.encode(10.0f);
  EXPECT_LT(loose.brickCount, g.bricks);
  EXPECT_EQ(loose.coefCount, loose.brickCount);
}

// Seams: samples on brick faces, edges and corners (and just inside either side), float and
// quantised coefficients.
TEST(HaarSample, BrickSeamsFacesEdgesCorners) {
  const LatticeGeom g = makeGeom(16, 13, 11, 3, -5, 0);
  const DenseLight light = smoothLight(g, 11);
  std::vector<float> dense;
  std::vector<float> seams;
  for (int k = 0; k <= 5; ++k) seams.push_back(float(3 * k));  // brick boundaries (lattice-relative)
  const float offs[] = {0.0f, 1e-3f, -1e-3f, 0.5f};
  for (const auto& [T, p] : {std::pair{0.0f, Precision::Fp32}, std::pair{0.004f, Precision::Fp32},
                             std::pair{0.03f, Precision::Fp32}, std::pair{0.002f, Precision::Quant},
                             std::pair{0.02f, Precision::Quant}}) {
    const ChaarData d = encodeLights(g, {light}, T, -1.0f, p);
    const ChaarView v = d.view();
    decodeBaseDense(d, 0, dense);
    const double E = d.bases[0].maxError;
    int n = 0;
    for (float sx : seams)
      for (float sy : seams)
        for (float sz : seams)
          for (int o = 0; o < 16; ++o) {
            // o picks which axes sit exactly on the seam: all three = corner, two = edge, one = face.
            const float x = g.min[0] + sx + (o & 1 ? offs[(o >> 1) % 4] : 0.0f);
            const float y = g.min[1] + sy + (o & 2 ? offs[(o >> 2) % 4] : 0.0f);
            const float z = g.min[2] + sz + (o & 4 ? offs[(o >> 3) % 4] : 0.0f);
            const Rgb c = chaarSample(v, 0, x, y, z);
            const Rgb r = denseSample(g, dense, x, y, z);
            const Rgb in = denseSample(g, light.rgb, x, y, z);
            ++n;
            if (T == 0.0f) {
              // Lossless: the compressed sample is the dense sample up to float rounding.
              ASSERT_NEAR(c.r, r.r, sampleRounding(light)) << x << " " << y << " " << z;
              ASSERT_NEAR(c.g, r.g, sampleRounding(light));
              ASSERT_NEAR(c.b, r.b, sampleRounding(light));
            } else {
              // Lossy: both copies of a shared texel are within E of the input, so the compressed
              // sample is within E of the input's sample and within 2E of the dense-decoded one.
              ASSERT_LE(std::fabs(double(c.g) - in.g), E + 1e-6);
              ASSERT_LE(std::fabs(double(c.g) - r.g), 2 * E + 1e-6);
            }
          }
    EXPECT_GT(n, 1000);
  }
}

TEST(HaarSample, RandomPointsMatchDenseAtThresholdZero) {
  const LatticeGeom g = makeGeom(10, 9, 8, -2, 0, 5);
  std::vector<DenseLight> lights = {smoothLight(g, 0), randomLight(g, 5), smoothLight(g, 14)};
  const ChaarData d = encodeLights(g, lights, 0.0f);
  const ChaarView v = d.view();
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> ux(g.min[0] - 2.0f, g.max[0] + 2.0f), uy(g.min[1] - 2.0f, g.max[1] + 2.0f),
      uz(g.min[2] - 2.0f, g.max[2] + 2.0f);
  for (uint32_t b = 0; b < 3; ++b)
    for (int i = 0; i < 3000; ++i) {
      const float x = ux(rng), y = uy(rng), z = uz(rng);
      const Rgb c = chaarSample(v, int(b), x, y, z);
      const Rgb r = denseSample(g, lights[b].rgb, x, y, z);
      ASSERT_NEAR(c.r, r.r, sampleRounding(lights[b]));
      ASSERT_NEAR(c.b, r.b, sampleRounding(lights[b]));
    }
  // NaN coordinates clamp (no out-of-bounds read).
  const Rgb n = chaarSample(v, 0, NAN, NAN, NAN);
  EXPECT_TRUE(std::isfinite(n.r));
}

TEST(HaarEncode, RejectsNonFiniteAndFp16Overflow) {
  const LatticeGeom g = makeGeom(5, 5, 5);
  DenseLight light = smoothLight(g, 1);
  light.rgb[3 * 62 + 1] = NAN;
  try {
    LiftedBase lb(g, light, Precision::Fp32, "file.vdb grid B01");
    FAIL();
  } catch (const canopy::Error& e) {
    EXPECT_EQ(e.code(), canopy::ExitCode::InvalidInput);
    EXPECT_NE(std::string(e.what()).find("file.vdb grid B01: non-finite value at (2,2,2)"), std::string::npos) << e.what();
  }
  light = smoothLight(g, 1, 1e5f);
  EXPECT_THROW(LiftedBase(g, light, Precision::Fp16, "x"), canopy::Error);
  EXPECT_NO_THROW(LiftedBase(g, light, Precision::Fp32, "x"));
}

// The decimation rule: a detail is dropped only when all three channels are <= T (joint RGB).
TEST(HaarEncode, DetailDroppedOnlyWhenAllChannelsUnderThreshold) {
  float coef[3][kBrickValues] = {};
  for (int ch = 0; ch < 3; ++ch) coef[ch][0] = 1.0f;
  const float c5[3] = {0.25f, 0.25f, 0.25f}, c9[3] = {0.25f, 0.125f, 0.5f}, c40[3] = {-0.5f, 0.0f, 0.0f};
  for (int ch = 0; ch < 3; ++ch) {
    coef[ch][5] = c5[ch];
    coef[ch][9] = c9[ch];
    coef[ch][40] = c40[ch];
    unliftBrick(coef[ch]);  // dyadic values: exact
  }
  const LatticeGeom g = makeGeom(4, 4, 4);  // brick 0 is the whole lattice (its border included)
  DenseLight light;
  light.rgb.resize(3 * 64);
  for (int c = 0; c < 64; ++c)
    for (int ch = 0; ch < 3; ++ch) light.rgb[size_t(3 * c + ch)] = coef[ch][c];
  LiftedBase lb(g, light, Precision::Fp32, "t");
  const BaseCode code = lb.encode(0.3f);
  EXPECT_EQ(code.bricks[0].mask(), (uint64_t(1) << 0) | (uint64_t(1) << 9) | (uint64_t(1) << 40));
  EXPECT_EQ(lb.encode(0.25f).bricks[0].mask(), (uint64_t(1) << 0) | (uint64_t(1) << 9) | (uint64_t(1) << 40));
  EXPECT_EQ(lb.encode(0.5f).bricks[0].mask(), uint64_t(1));  // <= T: dropped, fast path left
  EXPECT_EQ(lb.encode(0.2f).bricks[0].mask(), (uint64_t(1) << 0) | (uint64_t(1) << 5) | (uint64_t(1) << 9) | (uint64_t(1) << 40));
}

// A base (or a whole file) without light: nothing stored, samples are zero, the file round-trips.
TEST(HaarEncode, EmptyLightStoresNoBricks) {
  const LatticeGeom g = makeGeom(7, 7, 7);
  DenseLight dark;
  dark.rgb.assign(3 * g.cells, 0.0f);
  LiftedBase lb(g, dark, Precision::Fp32, "dark");
  EXPECT_EQ(lb.searchThreshold(0.01f), 0.0f);
  ChaarData d = encodeLights(g, {dark, dark}, 0.01f);
  EXPECT_EQ(d.header.slotCount, 0u);
  EXPECT_EQ(d.header.coefCount, 0u);
  const std::vector<uint8_t> bytes = serializeChaar(d);
  const ChaarData back = parseChaar(bytes.data(), bytes.size(), "dark.chaar");
  const Rgb s = chaarSample(back.view(), 1, 3.5f, 2.5f, 1.0f);
  EXPECT_EQ(s.r, 0.0f);
  EXPECT_EQ(s.g, 0.0f);
  std::vector<float> dense;
  decodeBaseDense(back, 0, dense);
  EXPECT_EQ(dense, dark.rgb);
}

// The quantised stream's fields: three consecutive fields of random widths (0..15, as one
// coefficient's Y, R-Y, B-Y) at every bit position read back exactly (QuantFieldLayout against a
// bit-by-bit writer). The CPU runs the device's window code (three 32-bit words, funnel shifts,
// fields to float by the mask-flip-OR trick).
TEST(HaarQuant, FieldsReadBackAtEveryBitPosition) {
  std::mt19937 rng(5);
  std::vector<uint64_t> words(64, 0);
  struct Field {
    uint64_t pos;
    uint32_t w;
    int32_t v;
  };
  std::vector<Field> fields;
  uint64_t pos = 0;
  while (pos + 15 < 62 * 64) {
    const uint32_t w = rng() % 16;
    const int32_t lo = w ? -(1 << (w - 1)) : 0, hi = w ? (1 << (w - 1)) - 1 : 0;
    const int32_t v = lo + int32_t(rng() % uint32_t(hi - lo + 1));
    for (uint32_t b = 0; b < w; ++b)
      if ((uint32_t(v) >> b) & 1u) words[(pos + b) / 64] |= uint64_t(1) << ((pos + b) % 64);
    fields.push_back({pos, w, v});
    pos += w;
  }
  EXPECT_GT(fields.size(), 400u);
  int wide = 0;  // triples over 33 bits: the window's third word matters
  for (size_t i = 0; i + 2 < fields.size(); ++i) {
    const QuantFieldLayout layout(fields[i].w | fields[i + 1].w << 4 | fields[i + 2].w << 8);
    wide += fields[i].w + fields[i + 1].w + fields[i + 2].w > 33u;
    const Rgb q = layout.levels(words.data(), uint32_t(fields[i].pos));
    ASSERT_EQ(q.r, float(fields[i].v)) << fields[i].pos;
    ASSERT_EQ(q.g, float(fields[i + 1].v)) << fields[i].pos;
    ASSERT_EQ(q.b, float(fields[i + 2].v)) << fields[i].pos;
  }
  EXPECT_GT(wide, 10);
  EXPECT_EQ(fineDetailAxes(brickIndex(0, 1, 0)), 0u);
  EXPECT_EQ(fineDetailAxes(brickIndex(2, 1, 3)), 2u);
  EXPECT_EQ(fineDetailAxes(brickIndex(3, 3, 2)), 3u);
}

// The quantised sampler equals decoding the point's brick (decodeSlot) and interpolating its 8
// texels, up to float rounding, at random points of random and smooth light (each base's own
// steps; the colour transform inside both).
TEST(HaarQuant, SampleEqualsDecodeThenTrilinearWithinRounding) {
  const LatticeGeom g = makeGeom(14, 12, 10, -3, 1, 2);
  const std::vector<DenseLight> lights = {smoothLight(g, 2), randomLight(g, 7), smoothLight(g, 12, 4.0f)};
  int compared = 0, rawSamples = 0, haarSamples = 0;
  for (float T : {0.001f, 0.01f, 0.1f}) {
    const ChaarData d = encodeLights(g, lights, T, -1.0f, Precision::Quant);
    const ChaarView v = d.view();
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> ux(g.min[0] - 1.0f, g.max[0] + 1.0f), uy(g.min[1] - 1.0f, g.max[1] + 1.0f),
        uz(g.min[2] - 1.0f, g.max[2] + 1.0f);
    for (uint32_t b = 0; b < lights.size(); ++b) {
      // Y and the differences are at most twice the peak: twice the float bound.
      const double tol = 2 * sampleRounding(lights[b]);
      for (int i = 0; i < 4000; ++i) {
        const float x = ux(rng), y = uy(rng), z = uz(rng);
        const Rgb c = chaarSample(v, int(b), x, y, z);
        const BrickLookup at = locate(v, x, y, z);
        float vals[3][kBrickValues] = {};
        if (at.slot != kEmptySlot) decodeSlot(v, int(b), at.slot, vals);
        float want[3];
        for (int ch = 0; ch < 3; ++ch) {
          float t[2][2][2];
          for (int dz = 0; dz < 2; ++dz)
            for (int dy = 0; dy < 2; ++dy)
              for (int dx = 0; dx < 2; ++dx) t[dz][dy][dx] = vals[ch][brickIndex(at.lx + dx, at.ly + dy, at.lz + dz)];
          want[ch] = trilinear(t, at.fx, at.fy, at.fz);
        }
        ASSERT_NEAR(c.r, want[0], tol) << "T " << T << " base " << b;
        ASSERT_NEAR(c.g, want[1], tol) << "T " << T << " base " << b;
        ASSERT_NEAR(c.b, want[2], tol) << "T " << T << " base " << b;
        compared += want[1] != 0.0f;
        if (at.slot != kEmptySlot) {
          const QuantRecord& q = v.quantRecords[uint64_t(b) * v.slotCount + at.slot];
          (q.raw() ? rawSamples : haarSamples) += q.mask() != 0;
        }
      }
    }
  }
  EXPECT_GT(compared, 15000);  // of 36000: most points have light
  EXPECT_GT(rawSamples, 3000);  // both kinds of quantised brick (dense ones are stored raw)
  EXPECT_GT(haarSamples, 3000);
}

// The step is the error dial: a larger step stores fewer bits and errs more; the encoder's
// reported error is the decoded file's; steps of 0 or below the 15-bit floor are refused.
TEST(HaarQuant, StepTradesSizeForErrorAndIsRefusedWhereLevelsOverflow) {
  const LatticeGeom g = makeGeom(20, 18, 16);
  const DenseLight light = smoothLight(g, 3, 2.0f);
  LiftedBase lb(g, light, Precision::Quant, "file.vdb grid B03");
  uint64_t lastBytes = ~uint64_t(0);
  double lastSumSq = 0;
  for (float T : {0.0005f, 0.005f, 0.05f, 0.5f}) {
    const BaseCode c = lb.encode(T);
    EXPECT_LT(c.coefBytes(Precision::Quant), lastBytes) << T;
    EXPECT_GE(c.sumSqError, lastSumSq) << T;
    lastBytes = c.coefBytes(Precision::Quant);
    lastSumSq = c.sumSqError;
    ChaarAssembly a;
    a.geom = g;
    a.precision = Precision::Quant;
    a.codes.push_back(c);
    a.directions.push_back({0, 0, 0});
    a.valueMax.push_back(lb.valueMax());
    const ChaarData d = assembleChaar(a);
    std::vector<float> dense;
    decodeBaseDense(d, 0, dense);
    EXPECT_LE(maxAbsDiff(dense, light.rgb), c.maxError) << T;
  }
  for (float bad : {0.0f, -1.0f, lb.minQuantStep() * 0.5f}) {
    try {
      lb.encode(bad);
      ADD_FAILURE() << "step " << bad << " accepted";
    } catch (const canopy::Error& e) {
      EXPECT_EQ(e.code(), canopy::ExitCode::Unsupported);
      EXPECT_EQ(std::string(e.what()).rfind("file.vdb grid B03: ", 0), 0u) << e.what();
    }
  }
  EXPECT_NO_THROW(lb.encode(lb.minQuantStep()));
  // Values so large that even the finest step is beyond the reader's bound (1e30): refused.
  DenseLight huge = light;
  for (float& v : huge.rgb) v *= 1e36f;
  LiftedBase hb(g, huge, Precision::Quant, "huge");
  EXPECT_GE(hb.minQuantStep(), 1e30f);
  EXPECT_THROW(hb.encode(hb.minQuantStep()), canopy::Error);
}
