// test_reference.cpp: canopy-play's lighting against an independent Monte Carlo reference
// (tests/reference/pathtrace.h; docs/validation.md has the model, the mapping and the figures).
//
// Part 1 checks the path tracer itself against closed forms (Beer-Lambert through a uniform cube,
// single scattering against a deterministic quadrature of the single-scatter integral, albedo 0
// = single scattering, the white furnace). Part 2 runs the pipeline in-process on a real plant
// (voxelize 40^3 -> lbsolve -> octreepack; a plant and a 3-tree scene with scene light), renders
// it with the player's CPU renderer and with the path tracer (same camera, sun, sky), under a low
// (15 deg) and a high (70 deg) sun, prints the figures and holds the image RMS, the alpha RMS and
// the mean-radiance ratio within per-case bounds (kBounds below: measured value x ~1.5, rounded).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <tuple>

#include "tests/reference/compare.h"
#include "tests/reference/pathtrace.h"

namespace ref = canopy::reference;
using canopy::play::V3;

namespace {

// A cube lattice of n^3 cells, all of density rho (and the given albedo and wood), identity
// transform scaled by `cell` metres per cell and shifted by `offset`.
ref::Medium uniformCube(int n, float rho, float cell = 1.0f, V3 offset = V3{0, 0, 0}, float albedo = 1.0f) {
  ref::Medium m;
  ref::Volume v;
  for (int a = 0; a < 3; ++a) v.dim[a] = n;
  const size_t cells = size_t(n) * n * n;
  v.density.assign(cells, rho);
  v.wood.assign(cells, 0.0f);
  v.albedo.assign(3 * cells, albedo);
  v.finish();
  m.volumes.push_back(v);
  ref::Instance in;
  const double s = 1.0 / cell;
  const double w2i[12] = {s, 0, 0, -offset.x * s, 0, s, 0, -offset.y * s, 0, 0, s, -offset.z * s};
  for (int e = 0; e < 12; ++e) in.worldToIndex[e] = w2i[e];
  in.cellWorld = cell;
  m.instances.push_back(in);
  m.sigma = 4.0f;
  m.lb = ref::LbMaterial{};
  return m;
}

// The optical depth through a uniform cube of n cells of density rho along an axis, on a line
// through cell centres: rho (n - 1) between the outer centres plus 2 x the half-cell ramp from
// rho / 2 at the face to rho (trilinear towards the empty cells outside): sigma rho (n - 1/4).
double cubeDepth(int n, float rho, float sigma) { return double(sigma) * rho * (n - 0.25); }

}  // namespace

// Ratio tracking (20000 estimates) through a 12^3 cube of density 0.05 (optical depth 2.35) along +x through cell
// centres, against Beer-Lambert's exp(-tau) with the closed-form tau; in world units on a cube of
// 0.25 m cells shifted away from the origin (the length correction: depth per cell, not per metre).
// Bound: 4 standard errors of the estimate plus 1e-4. The deterministic quadrature (1/64-cell
// midpoint steps) agrees to 1e-4.
TEST(Reference, TransmittanceOfAUniformCubeIsBeerLambert) {
  const int n = 12;
  const float rho = 0.05f, cell = 0.25f;
  const V3 off{3.0f, -1.0f, 2.0f};
  const ref::Medium m = uniformCube(n, rho, cell, off);
  const double want = std::exp(-cubeDepth(n, rho, m.sigma));
  const V3 o = V3{-5.0f, 5.0f * cell, 7.0f * cell} + off;  // the row of cell centres y = 5, z = 7
  const V3 d{1, 0, 0};
  EXPECT_NEAR(ref::quadratureTransmittance(m, o, d, 1e30, 1.0 / 64), want, 1e-4);
  const int N = 20000;
  double sum = 0, sumSq = 0;
  for (int i = 0; i < N; ++i) {
    ref::Rng rng(7, uint64_t(i));
    const float T = ref::ratioTrackTransmittance(m, o, d, 1e30f, rng);
    sum += T, sumSq += double(T) * T;
  }
  const double mean = sum / N, sd = std::sqrt(std::max(0.0, sumSq / N - mean * mean) / N);
  std::printf("Beer-Lambert: T = %.5f, ratio tracking %.5f +- %.5f\n", want, mean, sd);
  EXPECT_NEAR(mean, want, 4 * sd + 1e-4);
}

// Delta tracking's free-flight distribution: the fraction of rays whose first collision lies beyond
// the cube (a single-scatter pixel with a unit sun along +y seen through a 1-cell-thin medium is
// 0 exactly when the ray escapes) matches exp(-tau) within 4 binomial standard deviations. Here:
// albedo 1, sun radiance 1, medium thin along the sun (the cube is one cell high above the ray,
// so T_sun > 0 always), and the pixel's RGB is non-zero iff the camera ray collided.
TEST(Reference, DeltaTrackingEscapeFractionIsBeerLambert) {
  ref::Medium m;
  ref::Volume v;
  v.dim[0] = 24, v.dim[1] = 1, v.dim[2] = 1;
  v.density.assign(24, 0.03f);
  v.wood.assign(24, 0.0f);
  v.albedo.assign(72, 1.0f);
  v.finish();
  m.volumes.push_back(v);
  ref::Instance in;
  const double w2i[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  for (int e = 0; e < 12; ++e) in.worldToIndex[e] = w2i[e];
  m.instances.push_back(in);
  m.sigma = 4.0f;
  // along x through y = z = 0 (the one row of centres): the x ramps as in cubeDepth; y and z are
  // at the centre, so their weights are exact
  const double want = std::exp(-cubeDepth(24, 0.03f, m.sigma));
  ref::Lighting L;
  L.toSun = V3{0, 1, 0};
  L.ambient = 0.0f;
  ref::TraceOptions opt;
  opt.spp = 1;
  opt.firstVertexOnly = true;
  const int N = 20000;
  int escaped = 0;
  for (int i = 0; i < N; ++i) {
    opt.seed = uint64_t(i + 1);
    escaped += ref::tracePixel(m, L, V3{-3, 0, 0}, V3{1, 0, 0}, opt, 0).rgba[0] == 0.0f;
  }
  const double p = double(escaped) / N, sd = std::sqrt(want * (1 - want) / N);
  std::printf("delta tracking: escape fraction %.5f, exp(-tau) %.5f +- %.5f\n", p, want, sd);
  EXPECT_NEAR(p, want, 4 * sd);
}

// Tracking through a lattice of random densities (20^3, 45 % of the cells empty, 51 % up to 0.1,
// 4 % at 1, so that neighbouring majorant blocks differ and a block that missed a neighbour's
// dense cell would be caught),
// rotated about a skew axis, scaled (0.3 m cells) and shifted, along 6 random rays (some starting
// inside the lattice): the majorant blocks and their DDA must bound every trilinear sample, or
// ratio tracking (T *= 1 - rho / max) and delta tracking (accept with rho / max) are biased.
// Ratio tracking (4000 estimates) and delta tracking's collision fraction (4000 paths: a single-
// scatter pixel with albedo 1 and an unshadowed unit sun is 1 exactly when the ray collides) against
// the midpoint quadrature of the optical depth (1/64-cell steps), within 4 standard errors + 2e-3.
TEST(Reference, TrackingThroughARandomRotatedLatticeMatchesQuadrature) {
  const int n = 20;
  ref::Medium m;
  ref::Volume v;
  for (int a = 0; a < 3; ++a) v.min[a] = -3, v.dim[a] = n;
  const size_t cells = size_t(n) * n * n;
  v.density.assign(cells, 0.0f);
  v.wood.assign(cells, 0.0f);
  v.albedo.assign(3 * cells, 1.0f);
  uint64_t h = 12345;
  const auto unit = [&h] {
    h = h * 6364136223846793005ull + 1442695040888963407ull;
    return float(h >> 40) / float(1ull << 24);
  };
  for (size_t i = 0; i < cells; ++i) {  // mostly thin (<= 0.1), 4 % dense cells (1): blocks of very different majorants
    const float r = unit();
    v.density[i] = r < 0.45f ? 0.0f : (r < 0.96f ? 0.1f * unit() : 1.0f);
  }
  v.finish();
  m.volumes.push_back(v);
  // index -> world = s R p + t, R about the unit axis (1, 2, 2)/3 by 0.7 rad; world -> index = R^T (x - t) / s
  const double s = 0.3, ang = 0.7, ax[3] = {1.0 / 3, 2.0 / 3, 2.0 / 3}, t[3] = {1.5, -0.4, 2.0};
  const double c = std::cos(ang), sn = std::sin(ang);
  double R[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const double cr = (i == j ? 0.0 : ((3 + j - i) % 3 == 1 ? -ax[3 - i - j] : ax[3 - i - j]));
      R[i][j] = c * (i == j) + (1 - c) * ax[i] * ax[j] + sn * cr;
    }
  ref::Instance in;
  for (int i = 0; i < 3; ++i) {
    double off = 0.0;
    for (int j = 0; j < 3; ++j) {
      in.worldToIndex[4 * i + j] = R[j][i] / s;
      off += R[j][i] * t[j];
    }
    in.worldToIndex[4 * i + 3] = -off / s;
  }
  in.cellWorld = float(s);
  m.instances.push_back(in);
  m.sigma = 1.0f;
  ref::Lighting L;
  L.toSun = V3{0, 1, 0};
  L.ambient = 0.0f;
  ref::TraceOptions opt;
  opt.spp = 4000;
  opt.firstVertexOnly = true;
  opt.unshadowedSun = true;
  const V3 centre = V3{float(t[0]), float(t[1]), float(t[2])} + V3{0.3f * 6.5f, 0.3f * 6.5f, 0.3f * 6.5f};
  for (int r = 0; r < 6; ++r) {
    const V3 d = canopy::play::normalize(V3{unit() - 0.5f, unit() - 0.5f, unit() - 0.5f});
    const V3 o = r < 3 ? centre - d * 10.0f : centre + V3{unit() - 0.5f, unit() - 0.5f, unit() - 0.5f} * 2.0f;  // outside / inside
    const double want = ref::quadratureTransmittance(m, o, d, 1e30, 1.0 / 64);
    double sum = 0, sumSq = 0;
    for (int i = 0; i < 4000; ++i) {
      ref::Rng rng(3, uint64_t(r) * 100000 + uint64_t(i));
      const double T = ref::ratioTrackTransmittance(m, o, d, 1e30f, rng);
      sum += T, sumSq += T * T;
    }
    const double mean = sum / 4000, sd = std::sqrt(std::max(0.0, sumSq / 4000 - mean * mean) / 4000);
    const ref::PixelEstimate e = ref::tracePixel(m, L, o, d, opt, uint64_t(r));
    const double collided = e.rgba[0], sdc = std::sqrt(want * (1 - want) / 4000);
    std::printf("ray %d: T quadrature %.4f, ratio tracking %.4f +- %.4f, delta tracking escape %.4f +- %.4f\n", r, want, mean, sd,
                1 - collided, sdc);
    EXPECT_NEAR(mean, want, 4 * sd + 2e-3) << "ray " << r;
    EXPECT_NEAR(1.0 - collided, want, 4 * sdc + 2e-3) << "ray " << r;
  }
}

// Single scattering (the camera vertex's next-event estimate alone) in an optically thin cube
// (16^3, density 0.02: tau ~ 1.3 across) lit by a sun at 35 degrees, against the single-scatter
// integral  L = int T_cam(t) k(t) a sun T_sun(x(t)) dt  by nested midpoint quadrature (1/32-cell
// steps, deterministic, none of the tracer's estimators), for 5 camera rays; voxel albedo
// (0.8, 0.5, 0.3). Bound: 4 standard errors of the MC estimate (2000 paths) + 2e-4.
TEST(Reference, SingleScatteringMatchesTheQuadratureOfTheSingleScatterIntegral) {
  ref::Medium m = uniformCube(16, 0.02f, 0.5f, V3{0, 0, 0}, 1.0f);
  for (size_t i = 0; i < m.volumes[0].albedo.size(); i += 3)
    m.volumes[0].albedo[i] = 0.8f, m.volumes[0].albedo[i + 1] = 0.5f, m.volumes[0].albedo[i + 2] = 0.3f;
  ref::Lighting L;
  L.toSun = canopy::play::normalize(V3{0.5f, 0.7f, -0.3f});
  L.sun[0] = 1.0f, L.sun[1] = 2.0f, L.sun[2] = 0.5f;
  L.ambient = 0.35f;  // unused by single scattering
  ref::TraceOptions opt;
  opt.spp = 2000;
  opt.firstVertexOnly = true;
  const V3 origins[5] = {{-4, 3, 4}, {-4, 1, 6}, {4, 3, -5}, {-3, -2, 2}, {10, 4, 3}};
  const V3 targets[5] = {{4, 4, 4}, {4, 2, 3}, {3.5f, 4, 4}, {4, 5, 4}, {2, 3, 4}};
  for (int r = 0; r < 5; ++r) {
    const V3 d = canopy::play::normalize(targets[r] - origins[r]);
    double want = 0.0, tau = 0.0;
    const double h = 0.5 / 32;
    for (int k = 0; k < 32 * 64; ++k) {
      const double t = (k + 0.5) * h;
      const V3 x = origins[r] + d * float(t);
      const double kx = ref::extinctionAt(m, x);
      if (kx > 0) want += std::exp(-(tau + 0.5 * kx * h)) * kx * h * ref::quadratureTransmittance(m, x, L.toSun, 1e30, 1.0 / 32);
      tau += kx * h;
    }
    const ref::PixelEstimate e = ref::tracePixel(m, L, origins[r], d, opt, uint64_t(r));
    const float alb[3] = {0.8f, 0.5f, 0.3f};
    for (int c = 0; c < 3; ++c) {
      const double w = want * alb[c] * L.sun[c];
      std::printf("ray %d channel %d: MC %.5f +- %.5f, quadrature %.5f\n", r, c, e.rgba[c], std::sqrt(e.variance[c]), w);
      EXPECT_NEAR(e.rgba[c], w, 4 * std::sqrt(e.variance[c]) + 2e-4) << "ray " << r << " channel " << c;
    }
    EXPECT_NEAR(e.rgba[3], 1.0 - std::exp(-tau), 0.02) << "ray " << r;  // alpha (ratio tracking, 2000 samples)
  }
}

// With LB albedo 0 (sigma_s = 0) and no sky, light scattered more than once is absorbed: the full
// tracer gives the single-scatter image (same mean within 4 standard errors over 64 pixels of
// 200 paths), and neither is 0.
TEST(Reference, AlbedoZeroMediumShowsSingleScatteringOnly) {
  ref::Medium m = uniformCube(16, 0.15f, 1.0f);
  m.lb.sigmaA[0] = m.lb.sigmaA[1] = m.lb.sigmaA[2] = 1.0f;
  m.lb.sigmaS[0] = m.lb.sigmaS[1] = m.lb.sigmaS[2] = 0.0f;
  ref::Lighting L;
  L.toSun = canopy::play::normalize(V3{0.3f, 0.9f, 0.2f});
  L.ambient = 0.0f;
  ref::TraceOptions full, single;
  full.spp = single.spp = 200;
  single.firstVertexOnly = true;
  single.seed = 99;
  double a = 0, b = 0, va = 0, vb = 0;
  for (int p = 0; p < 64; ++p) {
    const V3 o{-10.0f, 2.0f + float(p % 8) * 1.6f, 2.0f + float(p / 8) * 1.6f};
    const V3 d = canopy::play::normalize(V3{10.0f, 1.0f, 0.5f});
    const ref::PixelEstimate ef = ref::tracePixel(m, L, o, d, full, uint64_t(p));
    const ref::PixelEstimate es = ref::tracePixel(m, L, o, d, single, uint64_t(p));
    a += ef.rgba[1], b += es.rgba[1], va += ef.variance[1], vb += es.variance[1];
  }
  std::printf("albedo 0: full %.5f, single %.5f (+- %.5f)\n", a / 64, b / 64, std::sqrt(va + vb) / 64);
  EXPECT_GT(b, 0.5);
  EXPECT_NEAR(a, b, 4 * std::sqrt(va + vb) + 1e-4);
}

// The white furnace: every event conserves energy (voxel albedo 1, LB sigma_a = 0 so the leaf
// albedo is 1, HG lobes of the default g, a third of the cells wood: back-reflection), no sun, sky
// radiance A. The radiance field is then A everywhere, and a camera ray sees A x (1 - T): the
// image's RGB over A x alpha (alpha by quadrature) is 1, per channel, within 4 standard errors
// (64 rays x 256 paths; measured 1.003, 1.002, 0.998 +- 0.006..0.008). This exercises the HG
// sampling and its path-level spectral MIS, wood, roulette and the sky. (In a much denser cube,
// tau ~ 25, the estimate is right on average but heavy-tailed: paths of hundreds of events.)
TEST(Reference, WhiteFurnaceReturnsTheSky) {
  ref::Medium m = uniformCube(16, 0.1f, 1.0f);  // optical depth 6.3 across
  for (size_t i = 0; i < m.volumes[0].wood.size(); i += 3) m.volumes[0].wood[i] = 1.0f;
  for (int c = 0; c < 3; ++c) m.lb.sigmaA[c] = 0.0f;
  m.lb.sigmaS[0] = 0.891f, m.lb.sigmaS[1] = 0.909f, m.lb.sigmaS[2] = 0.882f;
  m.lb.g[0] = -0.120f, m.lb.g[1] = 0.091f, m.lb.g[2] = -0.333f;
  ref::Lighting L;
  L.sun[0] = L.sun[1] = L.sun[2] = 0.0f;
  L.ambient = 0.7f;
  ref::TraceOptions opt;
  opt.spp = 256;
  double rgb[3] = {0, 0, 0}, var[3] = {0, 0, 0}, alpha = 0;
  for (int p = 0; p < 64; ++p) {
    const V3 o{-10.0f, 1.0f + float(p % 8) * 1.8f, 1.0f + float(p / 8) * 1.8f};
    const V3 d = canopy::play::normalize(V3{10.0f, 0.7f, -0.4f});
    const ref::PixelEstimate e = ref::tracePixel(m, L, o, d, opt, uint64_t(p));
    for (int c = 0; c < 3; ++c) rgb[c] += e.rgba[c], var[c] += e.variance[c];
    alpha += 1.0 - ref::quadratureTransmittance(m, o, d, 1e30, 1.0 / 32);
  }
  for (int c = 0; c < 3; ++c) {
    const double ratio = rgb[c] / (L.ambient * alpha), sd = std::sqrt(var[c]) / (L.ambient * alpha);
    std::printf("furnace channel %d: %.4f +- %.4f\n", c, ratio, sd);
    EXPECT_NEAR(ratio, 1.0, 4 * sd + 1e-3) << "channel " << c;
  }
}

// ---- canopy-play against the reference -------------------------------------------------------------

namespace {

// One bound per case and figure: measured value x ~1.5, rounded up (the ratio's deviation from 1
// likewise, at least 0.05), measured on this 2-core CPU (docs/validation.md; the test prints every
// figure). After a change of the lighting model re-measure and update these constants.
struct Bounds {
  double rms;       // image RMS / mean (MC noise included: ~0.04 at kSpp)
  double alphaRms;  // alpha RMS
  double ratioDev;  // |mean play / mean MC - 1|
};
constexpr int kSize = 128;  // pixels per side
constexpr int kSpp = 128;   // MC paths per pixel
constexpr int kResolution = 40;

const ref::Prepared& prepared() {
  static const ref::Prepared p = [] {
    ref::PrepareOptions o;
    o.mesh = std::string(CANOPY_SHARED_DIR) + "/assets/plants/oak_medium.glb";
    o.workDir = std::string(CANOPY_BINARY_DIR) + "/tests/reference/work";
    o.resolution = kResolution;
    ref::Prepared r = ref::prepareScenes(o);
    std::printf("pipeline (voxelize %d^3, lbsolve, octreepack x2): %.1f s\n", kResolution, r.seconds);
    return r;
  }();
  return p;
}

ref::CaseResult measure(const ref::PreparedScene& scene, double elevation, int spp, float playerSunScale = 1.0f,
                        bool directOnly = false, const char* shadows = "map", bool indirectOnly = false) {
  ref::CaseOptions o;
  o.indirectOnly = indirectOnly;
  o.width = o.height = kSize;
  o.sunElevation = elevation;
  o.trace.spp = spp;
  o.trace.seed = 1;
  o.playerSunScale = playerSunScale;
  o.directOnly = directOnly;
  o.shadows = std::string(shadows) == "off" ? "map" : shadows;
  if (std::string(shadows) == "off") {  // canopy-play --no-shadows; the reference's sun unshadowed too
    o.tweakPlayer = [](canopy::play::PlayOptions& p) { p.shadows = false; };
    o.trace.unshadowedSun = true;
  }
  return ref::compareCase(scene, o);
}

void runCase(const ref::PreparedScene& scene, double elevation, const Bounds& b) {
  const ref::CaseResult r = measure(scene, elevation, kSpp);
  std::printf("%s, sun %g deg, %dx%d px, %d spp: RMS %.4f (MC noise %.4f), alpha RMS %.4f, mean ratio play/MC %.4f; "
              "player %.2f s, MC %.1f s\n",
              scene.name.c_str(), elevation, kSize, kSize, kSpp, r.rms, r.noise, r.alphaRms, r.meanRatio, r.playSeconds, r.mcSeconds);
  EXPECT_GT(r.coveredPixels, 300);  // the view shows the plant
  EXPECT_GT(r.meanMc, 0.0);
  EXPECT_LT(r.rms, b.rms);
  EXPECT_LT(r.alphaRms, b.alphaRms);
  EXPECT_LT(std::fabs(r.meanRatio - 1.0), b.ratioDev);
}

}  // namespace

// The oak (oak_medium.glb at 40^3) alone, and three of it (scene light on), sun at azimuth 40 deg,
// elevation 15 and 70 deg; canopy-play's defaults otherwise (shadow map, --sigma 4, --ambient 0.35).
// Measured 2026-12-04 (kSize 128, kSpp 128, seed 1; the MC noise part of the RMS in brackets), with
// the LB's Beer-Lambert collision (one medium with the player), the map read without a bias and
// the shadow cones recomputed after optical depth 0.05:
//   plant  15 deg: RMS 0.0684 (0.0451), alpha RMS 0.0027, ratio 0.9777
//   plant  70 deg: RMS 0.1119 (0.0473), alpha RMS 0.0027, ratio 1.0361
//   trees  15 deg: RMS 0.0780 (0.0463), alpha RMS 0.0028, ratio 0.9868
//   trees  70 deg: RMS 0.0974 (0.0499), alpha RMS 0.0028, ratio 1.0002
// (Before those three changes: ratios 1.074, 1.257, 1.015, 1.119, the map's direct sun 1.6-2.1x
// too bright over an indirect light 29 % too dark.) Bounds: RMS about 1.4x, |ratio - 1| 1.5x or 0.03.
constexpr Bounds kPlantLow{0.10, 0.0045, 0.05};
constexpr Bounds kPlantHigh{0.16, 0.0045, 0.06};
constexpr Bounds kTreesLow{0.11, 0.0045, 0.04};
constexpr Bounds kTreesHigh{0.14, 0.0045, 0.03};

// One test case for the four cases and the control, so that the pipeline (~8-10 s of it: the 57 LB
// solves) runs once per process: CTest runs each test case in its own process. ~20 s in all here.
TEST(Reference, PlayMatchesTheReferenceForAPlantAndThreeTreesUnderALowAndAHighSun) {
  {
    SCOPED_TRACE("plant, sun 15 deg");
    runCase(prepared().plant, 15.0, kPlantLow);
  }
  {
    SCOPED_TRACE("plant, sun 70 deg");
    runCase(prepared().plant, 70.0, kPlantHigh);
  }
  {
    SCOPED_TRACE("3 trees, sun 15 deg");
    runCase(prepared().trees, 15.0, kTreesLow);
  }
  {
    SCOPED_TRACE("3 trees, sun 70 deg");
    runCase(prepared().trees, 70.0, kTreesHigh);
  }
  // The bounds catch a lighting error: the player's sun 1.5x too strong (what counting part of the
  // direct beam twice looks like) on the low-sun plant leaves its RMS and mean-ratio bounds (the MC
  // at 32 spp here: its noise only adds to the RMS; the ratio is what must move).
  const ref::CaseResult r = measure(prepared().plant, 15.0, 32, 1.5f);
  std::printf("control (player sun x1.5): RMS %.4f, mean ratio %.4f\n", r.rms, r.meanRatio);
  EXPECT_GT(r.rms, kPlantLow.rms);
  EXPECT_GT(std::fabs(r.meanRatio - 1.0), kPlantLow.ratioDev);

  // The direct sun alone (the unlit file, --ambient 0; the reference's single scattering), 64 spp.
  // Unshadowed (--no-shadows; the reference's sun transmittance 1): everything but the shadows and
  // the LB light, i.e. the camera, the transforms, the extinction, the front-to-back integral and
  // the albedo, must agree up to MC noise: measured RMS 0.0166 with MC noise 0.0168, ratio 0.9990;
  // bounds RMS < 0.025 and |ratio - 1| < 0.01.
  {
    SCOPED_TRACE("plant, direct sun, no shadows");
    const ref::CaseResult d = measure(prepared().plant, 15.0, 64, 1.0f, true, "off");
    std::printf("plant, direct sun unshadowed: RMS %.4f (MC noise %.4f), alpha RMS %.4f, ratio %.4f\n", d.rms, d.noise, d.alphaRms,
                d.meanRatio);
    EXPECT_LT(d.rms, 0.025);
    EXPECT_LT(std::fabs(d.meanRatio - 1.0), 0.01);
  }
  // With the shadow cones (--shadows cone): the player's sun transmittance against ratio tracking.
  // Measured ratio 1.0158 at 15 deg and 1.0377 at 70 deg, RMS 0.0329 / 0.0459 against MC noise
  // 0.0335 / 0.0412 (before the cones were recomputed after optical depth 0.05 along the primary
  // ray, one cone served a whole 1.5-cell interval: 1.2453 and 1.3134). Bounds: RMS < 0.05 / 0.065,
  // |ratio - 1| < 0.04 / 0.06.
  for (const auto& [elevation, rmsBound, ratioDev] : {std::tuple<double, double, double>{15.0, 0.05, 0.04}, {70.0, 0.065, 0.06}}) {
    SCOPED_TRACE("plant, direct sun, shadow cones, sun " + std::to_string(elevation));
    const ref::CaseResult d = measure(prepared().plant, elevation, 64, 1.0f, true, "cone");
    std::printf("plant, direct sun, shadow cones, sun %g deg: RMS %.4f (MC noise %.4f), ratio %.4f\n", elevation, d.rms, d.noise, d.meanRatio);
    EXPECT_LT(d.rms, rmsBound);
    EXPECT_LT(std::fabs(d.meanRatio - 1.0), ratioDev);
  }
  // The indirect light alone (--no-direct-sun; the reference without the camera vertex's sun),
  // 64 spp, sun 15 deg: the LB light against the light field of the player's medium. Measured
  // RMS 0.1056 (MC noise 0.0931: all of it is multiply scattered), ratio 1.0084 with the LB's
  // Beer-Lambert collision (0.7077 with the dissertation's linear one, which solves a medium about
  // 4x thinner than the player's); bounds RMS < 0.16, |ratio - 1| < 0.06.
  {
    SCOPED_TRACE("plant, indirect light, sun 15");
    const ref::CaseResult d = measure(prepared().plant, 15.0, 64, 1.0f, false, "map", true);
    std::printf("plant, indirect light only, sun 15 deg: RMS %.4f (MC noise %.4f), ratio %.4f\n", d.rms, d.noise, d.meanRatio);
    EXPECT_LT(d.rms, 0.16);
    EXPECT_LT(std::fabs(d.meanRatio - 1.0), 0.06);
  }
}
