// test_play_light.cpp: the player's LB lighting on the CPU reference (the same cone.h code the
// CUDA kernel runs): light pages streamed through the page cache, sampled with canopySampleLight
// for the sun's (up to) three bases and B_0, weighted by the shared sun lookup in each instance's
// model space.
//
// Scenes are packed in-process with the octreepack builder and lighting functions built here
// (tests/play/scenes.h: rampLight). Tolerances are stated at each test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "canopy/atomic_file.h"
#include "canopy/sun_lookup.h"
#include "formats/canopy_file.h"
#include "runtime/cone.h"
#include "runtime/player.h"
#include "tests/octreepack/synthetic.h"
#include "tests/play/resident.h"
#include "tests/play/scenes.h"
#include "tests/play/views.h"

namespace pl = canopy::play;
namespace pt = canopy::play::testing;
using canopy::Device;

namespace {

using pt::render;

constexpr float kRgb[3] = {1.0f, 0.5f, 0.25f};  // base j = (j + 1) * kRgb: exact in fp16

// A ball (24^3 lattice, radius 10 cells, density 0.3) with constant light bases, and the same
// ball density-only.
const std::string& litSphere() {
  static const std::string p = [] {
    const std::string f = pt::tmpDir("light") + "/sphere-lit.canopy";
    pt::writeLitScene(f, {pt::sphereModel(24, 10, 0.3f)}, {pt::rampLight(kRgb)}, {pt::instanceAt(0, 0, 0, 0)});
    return f;
  }();
  return p;
}
const std::string& plainSphere() {
  static const std::string p = [] {
    const std::string f = pt::tmpDir("light") + "/sphere-plain.canopy";
    pt::writeScene(f, {pt::sphereModel(24, 10, 0.3f)}, {pt::instanceAt(0, 0, 0, 0)});
    return f;
  }();
  return p;
}

// The expected indirect light / (ambient * albedo-weighted density-only image) per channel for the
// constant bases: (sun * sum_v w_v (b_v + 1) + ambient * B_0 / 18) * kRgb[c] / ambient, B_0 = 1.
void expectedRatio(canopy::play::V3 toSun, float sun, float ambient, float ratio[3]) {
  canopy::sun::Weights w;
  ASSERT_TRUE(canopy::sun::lookup(-toSun.x, -toSun.y, -toSun.z, w));
  float sum = 0.0f;
  for (int v = 0; v < 3; ++v) sum += w.weight[v] * float(w.base[v] + 1);
  for (int c = 0; c < 3; ++c) ratio[c] = (sun * sum + ambient * pl::kAmbientB0Scale) * kRgb[c] / ambient;
}

// Flips a byte of page `page` of `good` (a copy), renders both files (2 frames, the sun's direct
// term off) and checks that the bad page is reported once, never cached (one page fewer streamed,
// so it was wanted), and that the frame equals the intact one within float rounding (2e-5
// relative): the scenes have constant bases, so whatever serves instead holds the same light.
void expectCorruptPageIsLitFromElsewhere(const std::string& good, uint32_t page, size_t byteInPage, bool exactLight) {
  const std::string bad = pt::tmpDir("light") + "/corrupt-" + std::to_string(page) + ".canopy";
  std::vector<unsigned char> bytes = canopy::readFile(good);
  const canopy::CanopyFile f = canopy::CanopyFile::open(good);
  bytes[size_t(f.header().pagesOffset) + size_t(page) * f.header().pageBytes + byteInPage] ^= 0x40;
  canopy::writeFileAtomic(bad, bytes.data(), bytes.size());
  pl::PlayOptions o = pt::convergedView(good, 33, 33);
  o.frames = 2;
  o.camera = "orbit:azimuth=30,elevation=15,distance=3.5,turns=0.05";
  o.directSun = false;
  o.exactLight = exactLight;
  nlohmann::json rg, rb;
  const std::vector<float> intact = render(o, &rg);
  o.input = bad;
  const std::vector<float> damaged = render(o, &rb);
  EXPECT_EQ(rg["corrupt_pages"], 0);
  EXPECT_EQ(rb["corrupt_pages"], 1);
  EXPECT_EQ(int(rb["pages_streamed"]) + 1, int(rg["pages_streamed"]));  // the page was wanted
  double peak = 0;
  for (size_t i = 0; i < intact.size(); ++i) {
    if (i % 4 == 3) {
      ASSERT_EQ(intact[i], damaged[i]);  // light never changes opacity
      continue;
    }
    ASSERT_NEAR(damaged[i], intact[i], 2e-5f * intact[i] + 1e-7f) << "value " << i;
    peak = std::max(peak, double(intact[i]));
  }
  EXPECT_GT(peak, 0.1);
}

}  // namespace

// sampleLbLight on a hand-made light item whose base k, channel c holds (k + x_index) * (c + 1):
// linear along x, so the trilinear sample at node-local lx is exactly (k + 4 lx + 0.5) * (c + 1)
// (light voxel centres (i + 0.5) / 4 are indices i + 1), and the result is lbIndirect of those
// values with the lookup's bases. Every value is exact in the shared-exponent words (multiples of 1/8
// below 9: 1e-5 tolerance for the arithmetic).
TEST(Light, SampleLbLightIsLbIndirectOfTheTrilinearBases) {
  std::vector<uint32_t> item(canopy::kCanopyLightItemBytes / 4);
  for (uint32_t k = 0; k < canopy::kCanopyLightBases; ++k)
    for (uint32_t v = 0; v < canopy::kCanopyLightVoxelCount; ++v) {
      const float x = float(k + v % canopy::kCanopyLightVoxels);
      item[k * canopy::kCanopyLightVoxelCount + v] = canopy::rgb9e5Encode(x / 8.0f, x * 2.0f / 8.0f, x * 3.0f / 8.0f);
    }
  canopy::sun::Weights w;
  ASSERT_TRUE(canopy::sun::lookup(0.2f, -1.0f, 0.45f, w));
  const float sun[3] = {1.5f, 1.0f, 0.75f};
  for (float lx : {0.0f, 0.1f, 0.37f, 0.5f, 0.93f, 1.0f}) {
    float out[3];
    pl::sampleLbLight(item.data(), w, lx, 0.3f, 0.6f, sun, 0.35f, pl::SceneLightPair{0.5f, 0.75f}, out);
    const float t = lx * 4.0f + 0.5f;
    for (int c = 0; c < 3; ++c) {
      float want = 0.0f;
      for (int v = 0; v < 3; ++v) want += w.weight[v] * (float(w.base[v]) + t);
      want = want * sun[c] * 0.75f + 0.35f * pl::kAmbientB0Scale * t * 0.5f;
      want *= float(c + 1) / 8.0f;
      EXPECT_NEAR(out[c], want, 1e-5f) << "lx " << lx << " channel " << c;
    }
  }
}

// With the sun's direct term off, a pixel of the lit ball is the density-only ball's pixel (whose
// indirect term is ambient * 1) times (sum_v w_v B_v + ambient B_0) / ambient per channel, since
// the bases are constant (every light level, border and fallback holds the same values). The
// values (j + 1) * {1, 0.5, 0.25} are exact in fp16 and the trilinear weights sum to 1 within a
// few ulps, so the tolerance is 2e-5 relative (+1e-7 absolute): float rounding only. Two suns:
// straight overhead (light travelling -y: all the weight on B04) and a general direction (three
// bases, weights from the shared lookup).
// The sun bases scale with the sun radiance (solved for a unit sun), B_0 does not: two intensities.
TEST(Light, IndirectIsTheLookupWeightedSunBasesPlusAmbientB0) {
  const std::pair<const char*, float> cases[] = {{"0,1,0", 1.0f}, {"0,1,0", 2.5f}, {"0.3,0.8,-0.52", 1.0f}, {"0.3,0.8,-0.52", 2.5f}};
  for (const auto& [sun, intensity] : cases) {
    pl::PlayOptions o = pt::convergedView(litSphere(), 21, 21);
    o.ground = "none";  // the volume's shading alone
    o.sun = sun;
    o.sunIntensity = intensity;
    o.directSun = false;
    nlohmann::json r;
    const std::vector<float> lit = render(o, &r);
    EXPECT_EQ(int(r["lit_models"]), 1);
    EXPECT_EQ(r["sun_bases"], "scattered");
    EXPECT_GT(double(r["light_page_mb"]), 0.0);
    o.input = plainSphere();
    const std::vector<float> ref = render(o, &r);
    EXPECT_EQ(int(r["lit_models"]), 0);
    float x, y, z;
    ASSERT_EQ(std::sscanf(sun, "%f,%f,%f", &x, &y, &z), 3);
    float ratio[3];
    expectedRatio(canopy::play::normalize(canopy::play::v3(x, y, z)), intensity, o.ambient, ratio);
    if (std::string(sun) == "0,1,0") {
      EXPECT_FLOAT_EQ(ratio[0], (intensity * 5.0f + o.ambient * pl::kAmbientB0Scale) / o.ambient);  // B04 alone
    }
    double peak = 0;
    for (size_t i = 0; i < lit.size(); ++i) {
      if (i % 4 == 3) {
        ASSERT_EQ(lit[i], ref[i]);  // light never changes opacity
        continue;
      }
      const float want = ref[i] * ratio[i % 4];
      ASSERT_NEAR(lit[i], want, 2e-5f * want + 1e-7f) << sun << " value " << i;
      peak = std::max(peak, double(ref[i]));
    }
    EXPECT_GT(peak, 0.05) << sun;
  }
}

// A lit model packed without kCanopyModelScatteredSun (bases that include the direct beam: lbsolve
// --sun-bases total, or older light files) is reported, since its direct sun is counted twice.
TEST(Light, SunBasesWithTheirBeamAreReported) {
  const std::string f = pt::tmpDir("light") + "/sphere-lit-total.canopy";
  pt::writeLitScene(f, {pt::sphereModel(24, 10, 0.3f)}, {pt::rampLight(kRgb)}, {pt::instanceAt(0, 0, 0, 0)}, /*scatteredSun=*/false);
  EXPECT_FALSE(canopy::CanopyFile::open(f).model(0).flags & canopy::kCanopyModelScatteredSun);
  EXPECT_TRUE(canopy::CanopyFile::open(litSphere()).model(0).flags & canopy::kCanopyModelScatteredSun);
  nlohmann::json r;
  render(pt::convergedView(f, 9, 9), &r);
  EXPECT_EQ(r["sun_bases"], "total");
  render(pt::convergedView(plainSphere(), 9, 9), &r);
  EXPECT_EQ(r["sun_bases"], "none");
}

// The sun sweep of Render.MovingTheSunChangesTheImageSmoothly with LB light on (spatially varying
// bases of the size of the direct term): consecutive 1-degree steps change the image by a similar
// amount (each step's mean change within 2x the median) and no pixel by more than 0.05, i.e. the
// lookup weights and the light sampling add no popping.
TEST(Light, MovingTheSunChangesTheLitImageSmoothly) {
  const std::string p = pt::tmpDir("light") + "/plant-lit.canopy";
  pt::writeLitScene(p, {canopy::octreepack::testing::syntheticPlant(40, 0, "plant", 4)}, {pt::rampLight(kRgb, 1.0f, 40, 0.03f)},
                    {pt::instanceAt(0, 0, 0, 0)});
  pl::PlayOptions o = pt::convergedView(p, 48, 48);
  o.camera = "orbit:azimuth=30,elevation=15,fov=40,turns=0";
  std::vector<std::vector<float>> frames;
  // azimuth 40..48 at elevation 35 crosses from one lookup face to its neighbours
  for (int s = 0; s <= 8; ++s) {
    o.sun = "orbit:azimuth=" + std::to_string(40 + s) + ",elevation=35";
    frames.push_back(render(o));
  }
  std::vector<double> means;
  double maxPixel = 0;
  for (size_t s = 1; s < frames.size(); ++s) {
    double sum = 0;
    for (size_t i = 0; i < frames[s].size(); ++i) {
      if (i % 4 == 3) {
        ASSERT_EQ(frames[s][i], frames[s - 1][i]);
        continue;
      }
      const double d = std::fabs(frames[s][i] - frames[s - 1][i]);
      sum += d;
      maxPixel = std::max(maxPixel, d);
    }
    means.push_back(sum / double(frames[s].size() * 3 / 4));
  }
  std::vector<double> sorted = means;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  std::printf("lit sun steps: median mean change %.3g, largest step mean %.3g, largest pixel change %.3g\n", median, sorted.back(),
              maxPixel);
  EXPECT_GT(median, 0.0);
  EXPECT_LT(maxPixel, 0.05);
  for (double m : means) EXPECT_LE(m, 2.0 * median + 1e-6);
}

// A flipped byte in the finest light page: reported once, never cached, and the samples that wanted
// it use the light of a coarser resident brick. With constant bases every light level holds the
// same values, so the damaged frame equals the intact one within float rounding (2e-5 relative),
// which the density-only fallback (ambient alone, 6x darker here) would not.
TEST(Light, CorruptLightPageIsReportedAndLitFromACoarserLevel) {
  const canopy::CanopyFile f = canopy::CanopyFile::open(litSphere());
  const canopy::CanopyModel& M = f.model(0);
  ASSERT_GE(M.lightPageCount, 2u);
  const uint32_t page = M.firstLightPage + M.lightPageCount - 1;
  ASSERT_EQ(f.pageEntry(page).kind, uint32_t(canopy::CanopyPageKind::Light));
  expectCorruptPageIsLitFromElsewhere(litSphere(), page, 1000, false);
}

// Rotating the instance 90 degrees about +y together with the sun and the camera leaves the image
// unchanged: the sun reaches the lookup in the instance's model axes. The bases vary along lattice
// x, so both the sampled position and the chosen bases must follow the instance. Tolerance: the
// rotated matrix is exact only to float rounding (cos 90 deg = -4e-8), so a rare sample may fall
// on the other side of a step or level boundary: RMS < 1e-4 and 99% of values within 1e-3
// (measured RMS 6e-7). The control (instance rotated, sun not) must differ far beyond that, and so
// does a player that feeds the lookup the world direction instead of the model-space one.
TEST(Light, InstanceRotationTakesTheSunIntoModelSpace) {
  const std::string a = pt::tmpDir("light") + "/rot0.canopy", b = pt::tmpDir("light") + "/rot90.canopy";
  const auto light = pt::rampLight(kRgb, 1.0f, 24, 0.2f);
  const float half = float(M_PI / 2);
  pt::writeLitScene(a, {pt::sphereModel(24, 10, 0.3f)}, {light}, {pt::instanceAt(0, 0, 0, 0)});
  pt::writeLitScene(b, {pt::sphereModel(24, 10, 0.3f)}, {light}, {pt::instanceAt(0, 0, 0, 0, 1.0f, half)});
  pl::PlayOptions o = pt::convergedView(a, 33, 33);
  o.directSun = false;  // the indirect term alone (shadows rotate with the sun in any case)
  o.camera = "orbit:azimuth=30,elevation=20,turns=0";
  o.sun = "orbit:azimuth=40,elevation=35";
  const std::vector<float> ref = render(o);
  o.input = b;
  o.camera = "orbit:azimuth=120,elevation=20,turns=0";  // yaw adds to the orbit azimuth
  o.sun = "orbit:azimuth=130,elevation=35";
  const std::vector<float> rot = render(o);
  o.sun = "orbit:azimuth=40,elevation=35";
  const std::vector<float> control = render(o);
  size_t within = 0;
  for (size_t i = 0; i < ref.size(); ++i) within += std::fabs(ref[i] - rot[i]) <= 1e-3f;
  const double e = pt::imageRms(ref, rot), ec = pt::imageRms(ref, control);
  std::printf("rotated instance + sun: RMS %.3g (control, sun not rotated: %.3g)\n", e, ec);
  EXPECT_LT(e, 1e-4);
  EXPECT_GT(double(within) / double(ref.size()), 0.99);
  EXPECT_GT(ec, 1e-3);  // measured 7e-3
}

// Light pages compete with brick pages in the same LRU: a lit forest along a camera path (far ->
// among the trees -> far, held from frame 8) with a quarter-size cache, real-time frames after the
// converged first one. The path completes with evictions, and once the last view has been held
// the frame equals the converged full-cache frame (the same pages resident: RMS < 1e-6), i.e. the
// evicted and reloaded light pages are sampled again and nothing of the fallback remains.
TEST(Light, SmallCacheStreamsLightPagesWithBrickPagesAndConverges) {
  const std::string p = pt::tmpDir("light") + "/forest-lit.canopy";
  std::vector<canopy::CanopyInstance> inst;
  for (int i = 0; i < 12; ++i)
    inst.push_back(pt::instanceAt(0, float(i % 4) * 2.5f - 3.75f, 0, float(i / 4) * 2.5f - 2.5f, 1.0f, 0.5f * float(i)));
  pt::writeLitScene(p, {canopy::octreepack::testing::syntheticPlant(40, 0, "a", 4)}, {pt::rampLight(kRgb, 1.0f, 40, 0.03f)}, inst);
  const canopy::CanopyFile f = canopy::CanopyFile::open(p);
  const double pageMb = double(f.pageCount()) * f.header().pageBytes / (1024.0 * 1024.0);
  const std::string path = pt::tmpDir("light") + "/forest-path.json";
  std::ofstream(path) << R"({"keyframes":[{"frame":0,"position":[-12,4,12],"target":[0,0,0],"fov":50},)"
                      << R"({"frame":3,"position":[-2.5,0.5,1.2],"target":[3,0,-2.5],"fov":50},)"
                      << R"({"frame":5,"position":[2.5,0.5,1.2],"target":[-3,0,-2.5],"fov":50},)"
                      << R"({"frame":8,"position":[12,4,12],"target":[0,0,0],"fov":50}]})";
  pl::PlayOptions o = pt::convergedView(p, 40, 30);
  o.camera = path;
  o.frames = 16;
  o.converge = false;
  o.cacheMb = pageMb / 4;
  nlohmann::json r;
  const std::vector<float> last = render(o, &r);
  EXPECT_EQ(int(r["lit_models"]), 1);
  EXPECT_GT(int(r["evictions"]), 0) << r.dump();
  EXPECT_GT(int(r["pages_streamed"]), 0);
  pl::PlayOptions ref = o;
  ref.cacheMb = pageMb * 2;
  ref.converge = true;
  nlohmann::json full;
  const std::vector<float> want = render(ref, &full);
  EXPECT_EQ(int(full["evictions"]), 0);
  double peak = 0;
  for (size_t i = 3; i < want.size(); i += 4) peak = std::max(peak, double(want[i]));
  EXPECT_GT(peak, 0.2);  // the view shows the forest
  EXPECT_LT(pt::imageRms(last, want), 1e-6) << r.dump();
}

// ---- Haar light (format 1.1: the .chaar's bricks, the finest level's exact light) -----------------
namespace {
// The lit ball of litSphere() with its lighting Haar-compressed at threshold 0 (fp32: lossless).
const std::string& haarSphere(float gradient = 0.0f) {
  static std::map<float, std::string> files;
  auto it = files.find(gradient);
  if (it != files.end()) return it->second;
  const std::string f = pt::tmpDir("light") + "/sphere-haar-" + std::to_string(gradient) + ".canopy";
  pt::writeHaarLitScene(f, {pt::sphereModel(24, 10, 0.3f)}, {pt::rampLight(kRgb, gradient, 24)}, {pt::instanceAt(0, 0, 0, 0)}, 0.0f,
                        canopy::haar::Precision::Fp32);
  return files.emplace(gradient, f).first->second;
}
}  // namespace

// Constant bases compressed losslessly: with --light exact the Haar-lit ball renders as the
// float16-lit one (the constants are exact in both), within float rounding (2e-5 relative), with
// the sun's three bases and B_0 taken from the Haar items; at a sun intensity of 2.5 too (both
// paths scale the sun bases, not B_0, by it).
TEST(Light, ExactHaarLightRendersLikeTheSameLightInFloat16Items) {
  const canopy::CanopyFile f = canopy::CanopyFile::open(haarSphere());
  ASSERT_TRUE(f.model(0).flags & canopy::kCanopyModelHaarLight);
  const std::pair<const char*, float> cases[] = {{"0,1,0", 1.0f}, {"0.3,0.8,-0.52", 1.0f}, {"0.3,0.8,-0.52", 2.5f}};
  for (const auto& [sun, intensity] : cases) {
    pl::PlayOptions o = pt::convergedView(litSphere(), 21, 21);
    o.sun = sun;
    o.sunIntensity = intensity;
    o.directSun = false;
    const std::vector<float> items = render(o);
    o.input = haarSphere();
    o.exactLight = true;
    nlohmann::json r;
    const std::vector<float> haar = render(o, &r);
    EXPECT_EQ(int(r["lit_models"]), 1);
    EXPECT_EQ(r["light"], "exact");
    EXPECT_GT(double(r["haar_page_mb"]), 0.0);
    double peak = 0;
    for (size_t i = 0; i < items.size(); ++i) {
      ASSERT_NEAR(haar[i], items[i], 2e-5f * items[i] + 1e-7f) << sun << " value " << i;
      peak = std::max(peak, double(items[i]));
    }
    EXPECT_GT(peak, 0.1) << sun;
  }
}

// Bases that vary along lattice x (+100% over the ball): the Haar items are sampled at the sample's
// own lattice point. The light items (half resolution, box filtered, shared-exponent RGB) give the same
// image within their quantisation (a linear ramp survives the box filter): RMS below 1e-3 of the
// peak (measured 2e-5 of it). A Haar lookup one lattice cell off along x would not: the control,
// light shifted by one cell, differs by more than 3e-3 of the peak (measured 4.8e-3). The default
// (--light fast) reads the light items of the same file and never asks for a Haar page.
TEST(Light, ExactHaarLightIsSampledAtTheSamplesLatticePoint) {
  pl::PlayOptions o = pt::convergedView("", 33, 33);
  o.sun = "0.3,0.8,-0.52";
  o.directSun = false;
  o.camera = "orbit:azimuth=30,elevation=20,turns=0";
  const std::string items = pt::tmpDir("light") + "/sphere-ramp-items.canopy";
  pt::writeLitScene(items, {pt::sphereModel(24, 10, 0.3f)}, {pt::rampLight(kRgb, 1.0f, 24)}, {pt::instanceAt(0, 0, 0, 0)});
  const std::string shifted = pt::tmpDir("light") + "/sphere-ramp-shifted.canopy";
  const auto ramp = pt::rampLight(kRgb, 1.0f, 24);
  pt::writeHaarLitScene(shifted, {pt::sphereModel(24, 10, 0.3f)},
                        {[ramp](int32_t i, int32_t j, int32_t k, float* out) { ramp(i + 1, j, k, out); }}, {pt::instanceAt(0, 0, 0, 0)},
                        0.0f, canopy::haar::Precision::Fp32);
  o.input = items;
  nlohmann::json ri;
  const std::vector<float> ref = render(o, &ri);
  o.input = haarSphere(1.0f);
  nlohmann::json rf;
  const std::vector<float> fast = render(o, &rf);  // --light fast: the items of the Haar-lit file
  o.exactLight = true;
  const std::vector<float> haar = render(o);
  o.input = shifted;
  const std::vector<float> off = render(o);
  double peak = 0;
  for (float v : ref) peak = std::max(peak, double(v));
  const double e = pt::imageRms(haar, ref), eOff = pt::imageRms(off, ref);
  std::printf("Haar vs light items on a ramp: RMS %.3g (one cell off: %.3g), peak %.3g\n", e, eOff, peak);
  EXPECT_GT(peak, 0.1);
  EXPECT_LT(e, 1e-3 * peak);
  EXPECT_GT(eOff, 3e-3 * peak);
  EXPECT_EQ(rf["light"], "fast");
  EXPECT_EQ(int(rf["pages_streamed"]), int(ri["pages_streamed"]));  // no Haar page was wanted
  for (size_t i = 0; i < fast.size(); ++i) ASSERT_NEAR(fast[i], ref[i], 2e-5f * std::fabs(ref[i]) + 1e-6f) << "value " << i;
}

// A Haar-lit model's default frame (--light fast) is rendered by the kernel without the exact
// light's code (scenePaths: no kPathExact, and no kPathDetail without detail levels), and gives the
// every-path kernel's pixels bit for bit; with --light exact the frame takes the every-path kernel.
TEST(Light, AHaarLitFramesDefaultPathsLeaveTheExactLightOutAndChangeNoPixel) {
  pl::PlayOptions o = pt::convergedView(haarSphere(1.0f), 40, 30);
  o.sun = "0.3,0.8,-0.52";
  o.camera = "orbit:azimuth=30,elevation=20,turns=0";
  const pt::FrameView frame(o);
  const pl::SceneView& v = frame.v;
  ASSERT_EQ(v.haarModels, 1u);
  ASSERT_EQ(v.detailModels, 0u);
  ASSERT_EQ(pl::scenePaths(v), pl::kPathTable);
  pl::SceneView exact = v;
  exact.shade.exactLight = 1;
  EXPECT_EQ(pl::scenePaths(exact), pl::kAllPaths);
  const pl::CameraView& c = frame.camera;
  const int64_t n = int64_t(c.width) * c.height;
  std::vector<float> rgba(size_t(n) * 4), rgbaAll(size_t(n) * 4);
  int covered = 0;
  for (int64_t i = 0; i < n; ++i) {
    pl::renderPixelT<false, true, false, false, pl::kPathTable>(v, c, i, rgba.data(), nullptr, 0.0f);
    pl::renderPixelT<false, true, false, false, pl::kAllPaths>(v, c, i, rgbaAll.data(), nullptr, 0.0f);
    covered += rgba[size_t(4 * i + 3)] > 0.02f ? 1 : 0;
  }
  EXPECT_GT(covered, int(n / 20));  // the ball is in view
  EXPECT_EQ(std::memcmp(rgba.data(), rgbaAll.data(), rgba.size() * sizeof(float)), 0);
}

// A 19-base scene light (format 1.2), uniform over the ball: B00 = 0.6 and sun base j = 0.1 + 0.05 j.
// With the sun's direct term off, a pixel of the lit ball is the density-only ball's pixel (no scene
// light: its indirect term is ambient * 1) times
//   (I sum_v w_v (b_v + 1) * sunFactor + ambient / 18 * 0.6) * kRgb[c] / ambient,
// sunFactor = sum_v w'_v (0.1 + 0.05 b'_v) from the sun's lookup in the scene lattice's axes (world
// axes here, as the unrotated instance's: w' = w). The light items (--light fast) and the Haar
// items (--light exact, lossless) alike: the same terms, each with its own factor. Tolerance as in
// IndirectIsTheLookupWeightedSunBasesPlusAmbientB0 (float rounding: 2e-5 relative).
TEST(Light, NineteenBaseSceneLightScalesTheSunTermByTheSunsBasesAndTheAmbientTermByB00) {
  pt::SceneLightData L;
  const double m[12] = {1, 0, 0, -3, 0, 1, 0, -3, 0, 0, 1, -3};
  for (int i = 0; i < 12; ++i) L.header.indexToWorld[i] = m[i];
  for (int a = 0; a < 3; ++a) L.header.min[a] = 0, L.header.dim[a] = 7;
  L.bases = 19;
  for (int j = 0; j < 19; ++j) L.values.insert(L.values.end(), 7 * 7 * 7, j == 0 ? 0.6f : 0.1f + 0.05f * float(j));
  const std::string items = pt::tmpDir("light") + "/sphere-lit-scene19.canopy", haar = pt::tmpDir("light") + "/sphere-haar-scene19.canopy";
  pt::writeLitScene(items, {pt::sphereModel(24, 10, 0.3f)}, {pt::rampLight(kRgb)}, {pt::instanceAt(0, 0, 0, 0)}, true, &L);
  pt::writeHaarLitScene(haar, {pt::sphereModel(24, 10, 0.3f)}, {pt::rampLight(kRgb)}, {pt::instanceAt(0, 0, 0, 0)}, 0.0f,
                        canopy::haar::Precision::Fp32, &L);
  const float intensity = 1.5f;
  pl::PlayOptions o = pt::convergedView(plainSphere(), 21, 21);
  o.ground = "none";  // the volume's shading alone
  o.sun = "0.3,0.8,-0.52";
  o.sunIntensity = intensity;
  o.directSun = false;
  const std::vector<float> ref = render(o);
  canopy::sun::Weights w;
  const pl::V3 toSun = pl::normalize(pl::v3(0.3f, 0.8f, -0.52f));
  ASSERT_TRUE(canopy::sun::lookup(-toSun.x, -toSun.y, -toSun.z, w));
  float sum = 0.0f, sunFactor = 0.0f;
  for (int v = 0; v < 3; ++v) {
    sum += w.weight[v] * float(w.base[v] + 1);
    sunFactor += w.weight[v] * (0.1f + 0.05f * float(w.base[v]));
  }
  for (const bool exact : {false, true}) {
    o.input = exact ? haar : items;
    o.exactLight = exact;
    nlohmann::json r;
    const std::vector<float> lit = render(o, &r);
    EXPECT_EQ(int(r["scene_light_bases"]), 19);
    double peak = 0;
    for (size_t i = 0; i < lit.size(); ++i) {
      if (i % 4 == 3) {
        ASSERT_EQ(lit[i], ref[i]);
        continue;
      }
      const float ratio = (intensity * sum * sunFactor + o.ambient * pl::kAmbientB0Scale * 0.6f) * kRgb[i % 4] / o.ambient;
      const float want = ref[i] * ratio;
      ASSERT_NEAR(lit[i], want, 2e-5f * want + 1e-7f) << (exact ? "exact" : "fast") << " value " << i;
      peak = std::max(peak, double(ref[i]));
    }
    EXPECT_GT(peak, 0.05);
  }
}

// A flipped byte in a Haar page: reported once, never cached, and the samples that wanted it use the
// light items (constant bases: the same values), so the damaged frame equals the intact one
// within float rounding.
TEST(Light, CorruptHaarPageIsReportedAndLitFromTheLightItems) {
  const canopy::CanopyFile f = canopy::CanopyFile::open(haarSphere());
  const canopy::CanopyModel& M = f.model(0);
  ASSERT_GE(M.haarPageCount, 1u);
  ASSERT_EQ(f.pageEntry(M.firstHaarPage).kind, uint32_t(canopy::CanopyPageKind::HaarLight));
  expectCorruptPageIsLitFromElsewhere(haarSphere(), M.firstHaarPage, 700, true);
}
