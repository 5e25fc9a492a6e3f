// test_play_cuda.cpp: the CUDA backend against the CPU reference (same cone.h code). Every case
// has "cuda" in its name and skips where no GPU is present.
//
// Tolerances: both backends run the same float code, but nvcc contracts multiply-adds into FMAs
// and its expf/log2f differ from glibc's in the last ulps; a rare pixel may then pick a different
// LOD or step boundary. RMS over all RGBA values < 2e-3 and 99% of values within 1e-2.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "canopy/device.h"
#include "formats/canopy_file.h"
#include "runtime/player.h"
#include "tests/octreepack/synthetic.h"
#include "tests/play/adaptive_check.h"
#include "tests/play/scenes.h"
#include "tests/play/views.h"

namespace pl = canopy::play;
namespace pt = canopy::play::testing;

namespace {

canopy::Device cuda() {
  canopy::Device d;
  d.kind = canopy::Device::Kind::Cuda;
  d.index = 0;
  return d;
}

double fractionWithin(const std::vector<float>& a, const std::vector<float>& b, float tol) {
  size_t n = 0;
  for (size_t i = 0; i < a.size(); ++i) n += std::fabs(a[i] - b[i]) <= tol;
  return double(n) / double(a.size());
}

// The forest: 24 instances of two synthetic plants (the models and placements of every file below).
std::vector<canopy::octreepack::ModelSource> forestModels() {
  return {canopy::octreepack::testing::syntheticPlant(64, 0, "a", 6), canopy::octreepack::testing::syntheticPlant(48, 0, "b", 4)};
}
std::vector<canopy::CanopyInstance> forestInstances() {
  std::vector<canopy::CanopyInstance> inst;
  for (int i = 0; i < 24; ++i)
    inst.push_back(pt::instanceAt(uint32_t(i % 2), float(i % 6) * 2.5f - 6.25f, 0, float(i / 6) * 2.5f - 3.75f, 1.0f, 0.7f * float(i)));
  return inst;
}
// Spatially varying bases for the two models (tests/play/scenes.h rampLight).
std::vector<canopy::octreepack::LightFn> forestLights() {
  const float rgb[3] = {1.0f, 0.8f, 0.6f};
  return {pt::rampLight(rgb, 1.0f, 64, 0.03f), pt::rampLight(rgb, -0.5f, 48, 0.03f)};
}

std::string forestFile() {
  const std::string p = pt::tmpDir("cuda") + "/forest.canopy";
  pt::writeScene(p, forestModels(), forestInstances());
  return p;
}

// The forest with LB light on both models.
std::string litForestFile() {
  const std::string p = pt::tmpDir("cuda") + "/forest-lit.canopy";
  pt::writeLitScene(p, forestModels(), forestLights(), forestInstances());
  return p;
}

// A converged w x h frame of the lit forest from `camera`, the sun fixed (the stereo and warp-tile tests).
pl::PlayOptions litForestOptions(int w, int h, const char* camera) {
  pl::PlayOptions o = pt::convergedView(litForestFile(), w, h, camera);
  o.sun = "0.3,0.8,-0.52";
  return o;
}

// The lit forest with its lighting Haar-compressed (fp16, threshold 0.01): with --light exact the
// finest level's light comes from Haar pages in the same device pool (canopyHaarSampleAt).
std::string haarForestFile() {
  const std::string p = pt::tmpDir("cuda") + "/forest-haar.canopy";
  pt::writeHaarLitScene(p, forestModels(), forestLights(), forestInstances(), 0.01f, canopy::haar::Precision::Fp16);
  return p;
}

// The Haar-lit forest with its geometry on detail lattices twice as fine (format 2.0): the descent
// to detail levels, their light from the light level (items, and Haar light at the light lattice
// point with --light exact), extinction per light cell.
std::string detailForestFile() {
  const std::string p = pt::tmpDir("cuda") + "/forest-detail.canopy";
  pt::writeHaarLitScene(p, forestModels(), forestLights(), forestInstances(), 0.01f, canopy::haar::Precision::Fp16, nullptr, 1);
  return p;
}

// The lit forest with a 19-base coarse scene light (format 1.2) over it: smooth synthetic bases,
// each its own pattern, so that the sun's lookup on them (rebuilt and uploaded per frame as the
// sun moves) selects different factors than B00.
std::string sceneLitForestFile() {
  const std::string p = pt::tmpDir("cuda") + "/forest-scene-light.canopy";
  pt::SceneLightData L;
  const double cell = 0.75, lo[3] = {-9.0, -1.5, -7.5};
  const int dim[3] = {25, 8, 21};
  const double m[12] = {cell, 0, 0, lo[0], 0, cell, 0, lo[1], 0, 0, cell, lo[2]};
  for (int i = 0; i < 12; ++i) L.header.indexToWorld[i] = m[i];
  for (int a = 0; a < 3; ++a) L.header.min[a] = 0, L.header.dim[a] = dim[a];
  L.bases = 19;
  for (int j = 0; j < 19; ++j)
    for (int z = 0; z < dim[2]; ++z)
      for (int y = 0; y < dim[1]; ++y)
        for (int x = 0; x < dim[0]; ++x)
          L.values.push_back(float(0.55 + 0.45 * std::sin(0.4 * x + 0.3 * (j + 1) * z + 0.2 * y + j)));
  pt::writeLitScene(p, forestModels(), forestLights(), forestInstances(), true, &L);
  return p;
}

}  // namespace

// The forest unlit, then lit (LB light on both models: the light pages go through the same device
// pool and page table, and the kernel samples them with the same canopySampleLight / lbIndirect
// code; the lit file also with the sun off, so that the indirect term alone is compared), then
// Haar-lit with --light exact (the finest level's light from Haar pages, canopyHaarSampleAt on the
// device), then lit with a 19-base scene light (format 1.2: the sun factor rebuilt on the host and
// uploaded per frame as the sun moves over three frames; the last frame is compared), then the
// Haar-lit forest on detail lattices (format 2.0: fast light and map, exact light and cones), then
// the lit forest with --step-growth 0.2, all in one test case.
TEST(PlayCuda, cuda_FrameMatchesTheCpuReference) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  struct Case {
    std::string file;
    bool direct;  // the direct sun term (off: the indirect light alone)
    int litModels;
    const char* shadows;  // the sun transmittance map (default) or the per-sample shadow cones
    bool exact = false;   // --light exact (the Haar-lit file's Haar pages)
    bool movingSun = false;  // three frames, the sun orbiting (the scene light's sun factor changes per frame)
    float stepGrowth = pl::PlayOptions{}.stepGrowthT;  // --step-growth (brick steps grow behind dense matter; the default 0.1, 0 in four cases)
    const char* farField = "auto";  // --far-field (a distance: the far field from there on)
    bool descentTable = true;       // off: --no-descent-table (the same image as with the descent tables)
  };
  const std::string lit = litForestFile(), unlit = forestFile(), haar = haarForestFile(), sceneLit = sceneLitForestFile(),
                    detail = detailForestFile();
  for (const Case& k : {Case{unlit, true, 0, "map"}, Case{unlit, true, 0, "cone"}, Case{lit, true, 2, "map"}, Case{lit, false, 2, "map"},
                        Case{haar, true, 2, "map", true}, Case{haar, false, 2, "map", true}, Case{sceneLit, true, 2, "map", false, true},
                        Case{sceneLit, false, 2, "map", false, true}, Case{detail, true, 2, "map", false}, Case{detail, true, 2, "cone", true},
                        Case{lit, true, 2, "map", false, false, 0.2f}, Case{lit, true, 2, "map", false, false, 0.0f, "3"},
                        Case{unlit, true, 0, "cone", false, false, 0.0f, "3"}, Case{lit, true, 2, "map", false, false, 0.0f, "auto", false},
                        Case{detail, true, 2, "map", true, false, 0.0f, "auto", false}}) {
    pl::PlayOptions o;
    o.input = k.file;
    o.shadowMethod = k.shadows;
    o.width = 96;
    o.height = 64;
    o.converge = true;
    o.directSun = k.direct;
    o.exactLight = k.exact;
    o.stepGrowthT = k.stepGrowth;
    o.farField = k.farField;
    o.descentTable = k.descentTable;
    if (k.litModels) o.sun = "0.3,0.8,-0.52";
    if (k.movingSun) o.sun = "orbit:azimuth=40,elevation=35,turns=0.3", o.frames = 3;
    // the whole forest (coarse levels), and a close view among the trees (finest bricks,
    // overlapping crowns, long shadow cones)
    for (const char* camera : {"orbit:azimuth=25,elevation=20,turns=0", "orbit:azimuth=60,elevation=8,distance=5,turns=0"}) {
      o.camera = camera;
      std::vector<float> cpu, gpu;
      pl::play(o, canopy::Device{}, &cpu);
      const nlohmann::json rg = pl::play(o, cuda(), &gpu);
      EXPECT_EQ(int(rg["lit_models"]), k.litModels) << k.file;
      EXPECT_EQ(int(rg["scene_light_bases"]), k.movingSun ? 19 : 0) << k.file;
      ASSERT_EQ(cpu.size(), gpu.size());
      std::printf("%s %s shadows %s direct %s: RMS %.2e, within 1e-2: %.4f\n", k.file.c_str(), camera, k.shadows, k.direct ? "on" : "off",
                  pt::imageRms(cpu, gpu), fractionWithin(cpu, gpu, 1e-2f));
      EXPECT_LT(pt::imageRms(cpu, gpu), 2e-3) << k.file << " " << camera << " direct " << k.direct << " " << k.shadows;
      EXPECT_GT(fractionWithin(cpu, gpu, 1e-2f), 0.99) << k.file << " " << camera << " direct " << k.direct << " " << k.shadows;
    }
  }
}

// A quarter-size cache along a camera path through the forest (real-time mode: one pass per
// frame, loads land between frames): the path completes, pages are evicted; after warm-up (the
// last view held for 8 frames) the frame equals the converged full-cache GPU frame (RMS < 1e-3:
// the same data and code once the last view's pages are resident; the CPU twin of this test,
// Render.SmallCacheStreamsAForestAndConvergesToTheFullCacheImage, measures 0).
TEST(PlayCuda, cuda_QuarterCacheCameraPathMatchesFullCacheAfterWarmUp) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  const std::string p = forestFile();
  const canopy::CanopyFile f = canopy::CanopyFile::open(p);
  const double pageMb = double(f.pageCount()) * f.header().pageBytes / (1024.0 * 1024.0);
  const std::string path = pt::tmpDir("cuda") + "/path.json";
  // far -> through the forest among the trees (fine pages, more than the cache holds) -> far view
  // on the other side, held from frame 24 (its coarse pages fit in a quarter of the cache)
  std::ofstream(path) << R"({"keyframes":[{"frame":0,"position":[-20,6,16],"target":[0,0,0],"fov":50},)"
                      << R"({"frame":8,"position":[-5,1.0,1.2],"target":[6,0,-3],"fov":50},)"
                      << R"({"frame":16,"position":[5,1.0,1.2],"target":[-6,0,-3],"fov":50},)"
                      << R"({"frame":24,"position":[20,6,16],"target":[0,0,0],"fov":50}]})";
  pl::PlayOptions o;
  o.input = p;
  o.width = 160;
  o.height = 96;
  o.camera = path;
  o.frames = 32;
  o.cacheMb = pageMb / 4;
  std::vector<float> small, full;
  const nlohmann::json r = pl::play(o, cuda(), &small);
  EXPECT_EQ(int(r["frames"]), 32);
  EXPECT_GT(int(r["pages_streamed"]), 0);
  EXPECT_GT(int(r["evictions"]), 0) << r.dump();
  pl::PlayOptions ref = o;
  ref.cacheMb = pageMb * 2;
  ref.converge = true;
  pl::play(ref, cuda(), &full);
  EXPECT_LT(pt::imageRms(small, full), 1e-3) << r.dump();
}

// Stereo on the GPU (stereo.h: the splat with atomicMax/atomicAdd, the resolve, the holes compacted
// in two halves and traced) against the CPU reference, on the lit forest from among the trees: the
// left eye as every GPU frame (RMS < 2e-3); the right eye likewise where both reprojected or both
// traced the same pixels; the hole sets may differ at a few pixels where a disparity lies on a
// threshold (nvcc's fast-math division): the traced fractions within 1 % of the pixels.
TEST(PlayCuda, cuda_StereoPairMatchesTheCpuReference) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  pl::PlayOptions o = litForestOptions(160, 96, "orbit:azimuth=60,elevation=8,distance=9,turns=0");
  o.stereoIpd = 0.3f;
  std::vector<float> cl, cr, gl, gr;
  const nlohmann::json rc = pl::play(o, canopy::Device{}, &cl, &cr);
  const nlohmann::json rg = pl::play(o, cuda(), &gl, &gr);
  const double fc = rc["stereo"]["traced_fraction_mean"], fg = rg["stereo"]["traced_fraction_mean"];
  std::printf("stereo: traced fraction cpu %.4f cuda %.4f (behind a front: cpu %.4f cuda %.4f); left RMS %.2e, right RMS %.2e (within 1e-2: %.4f)\n", fc, fg,
              double(rc["stereo"]["traced_behind_fraction_mean"]), double(rg["stereo"]["traced_behind_fraction_mean"]), pt::imageRms(cl, gl), pt::imageRms(cr, gr),
              fractionWithin(cr, gr, 1e-2f));
  EXPECT_GT(fc, 0.0);
  EXPECT_NEAR(fc, fg, 0.01);
  // holes traced behind a reprojected front, on both (14.2 % of the pixels on the CPU, 2026-12-05)
  const double bc = rc["stereo"]["traced_behind_fraction_mean"], bg = rg["stereo"]["traced_behind_fraction_mean"];
  EXPECT_GT(bc, 0.02);
  EXPECT_NEAR(bc, bg, 0.01);
  EXPECT_LT(pt::imageRms(cl, gl), 2e-3);
  EXPECT_LT(pt::imageRms(cr, gr), 4e-3);
  EXPECT_GT(fractionWithin(cr, gr, 1e-2f), 0.98);
  // the order the holes are traced in (the default: by kind; here one list in tile order) changes
  // no bit of either eye
  o.stereoHoleOrder = "tile";
  std::vector<float> tl, tr;
  const nlohmann::json rt = pl::play(o, cuda(), &tl, &tr);
  EXPECT_DOUBLE_EQ(double(rt["stereo"]["traced_fraction_mean"]), fg);
  ASSERT_EQ(tl.size(), gl.size());
  ASSERT_EQ(tr.size(), gr.size());
  EXPECT_EQ(std::memcmp(tl.data(), gl.data(), gl.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(tr.data(), gr.data(), gr.size() * sizeof(float)), 0);
}

// The warp tile's shape (--warp-tile, 4x8 by default) moves no pixel: each thread computes its own
// pixel with the same code, so converged frames are equal bit for bit with every shape (and the
// tiles cross the frame's last row and column where 96 x 60 is not a multiple of the tile).
TEST(PlayCuda, cuda_WarpTileShapeChangesNoPixel) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  pl::PlayOptions o = litForestOptions(96, 60, "orbit:azimuth=60,elevation=8,distance=5,turns=0");
  std::vector<float> ref;
  pl::play(o, cuda(), &ref);
  for (int w : {1, 2, 8, 16, 32}) {
    o.warpTileWidth = w;
    std::vector<float> img;
    pl::play(o, cuda(), &img);
    ASSERT_EQ(img.size(), ref.size());
    EXPECT_EQ(std::memcmp(img.data(), ref.data(), ref.size() * sizeof(float)), 0) << w << "x" << 32 / w << " rms " << pt::imageRms(img, ref);
  }
}

// Adaptive sampling on the GPU (adaptive.h: the lattice in warp tiles of the half-size grid, the
// blocks' tests, the fill, the failing blocks' off-lattice pixels compacted in tile order and
// traced), on the lit forest from among the trees: block by block against the GPU's own full trace
// (expectAdaptiveBlocks: each block filled from the full trace's corners or traced to its bits, as
// the test on the full trace says; the report's count of filled pixels), at 160x96 with 4x8 blocks
// and at 161x97 with 8x4 ones; against the CPU reference as every GPU frame is (the two fill the
// same blocks but where a corner's few-1e-4 difference between the backends moves a cell across
// the tolerance; measured 2026-12-06: the same traced fraction, RMS 6e-7); and bands (3 on block
// rows, 40 on single rows that cut blocks) give the one-band frame bit for bit.
TEST(PlayCuda, cuda_AdaptiveFrameMatchesTheFullTraceBlockByBlock) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  for (const int tileW : {4, 8}) {
    const int w = tileW == 4 ? 160 : 161, h = tileW == 4 ? 96 : 97, tileH = 32 / tileW;
    pl::PlayOptions o = litForestOptions(w, h, "orbit:azimuth=60,elevation=8,distance=9,turns=0");
    o.warpTileWidth = tileW;
    std::vector<float> full, c, g, gb;
    pl::play(o, cuda(), &full);
    o.adaptive = "0.02";
    const nlohmann::json rc = pl::play(o, canopy::Device{}, &c);
    const nlohmann::json rg = pl::play(o, cuda(), &g);
    const double fc = rc["adaptive"]["traced_fraction_mean"], fg = rg["adaptive"]["traced_fraction_mean"];
    std::printf("adaptive %dx%d: traced fraction cpu %.4f cuda %.4f; RMS %.2e (within 1e-2: %.4f)\n", w, h, fc, fg, pt::imageRms(c, g),
                fractionWithin(c, g, 1e-2f));
    int passing = 0, failing = 0;
    const uint64_t filled = pt::expectAdaptiveBlocks(g, full, w, h, tileW, tileH, 0.02f, passing, failing);
    EXPECT_GT(passing, 0);
    EXPECT_GT(failing, 0);
    EXPECT_DOUBLE_EQ(fg, 1.0 - double(filled) / (double(w) * h));
    EXPECT_NEAR(fc, fg, 0.02);
    EXPECT_LT(pt::imageRms(c, g), 4e-3);
    EXPECT_GT(fractionWithin(c, g, 1e-2f), 0.98);
    for (const int tiles : {3, 40}) {
      o.tiles = tiles;
      pl::play(o, cuda(), &gb);
      ASSERT_EQ(gb.size(), g.size());
      EXPECT_EQ(std::memcmp(gb.data(), g.data(), g.size() * sizeof(float)), 0) << tiles << " bands: rms " << pt::imageRms(gb, g);
    }
  }
}

// Bands on one GPU (--tiles 3 on cuda:0: three backends, three caches, three threads; what several
// GPUs do, on one): converged frames equal the one-band frame bit for bit, with stereo on.
TEST(PlayCuda, cuda_BandsOnOneGpuGiveTheSameImageAsOneBand) {
  if (canopy::cudaDeviceCount() == 0) GTEST_SKIP() << "no CUDA device";
  // 96 rows: bands on whole warp tiles; 10 rows: fewer than 3 x the tile height, bands of 3, 3, 4
  // rows that end inside a tile (the kernels stop at the band's last row)
  for (int height : {96, 10}) {
    pl::PlayOptions o;
    o.input = litForestFile();
    o.width = 160;
    o.height = height;
    o.frames = 3;
    o.converge = true;
    o.camera = "orbit:azimuth=25,elevation=20,turns=0.1";
    o.stereoIpd = 0.3f;
    std::vector<float> l1, r1, l3, r3;
    pl::play(o, cuda(), &l1, &r1);
    o.tiles = 3;
    const nlohmann::json r = pl::play(o, cuda(), &l3, &r3);
    ASSERT_EQ(r["bands"].size(), 3u);
    ASSERT_EQ(l1.size(), l3.size());
    EXPECT_EQ(std::memcmp(l1.data(), l3.data(), l1.size() * sizeof(float)), 0) << height << " rms " << pt::imageRms(l1, l3);
    EXPECT_EQ(std::memcmp(r1.data(), r3.data(), r1.size() * sizeof(float)), 0) << height << " rms " << pt::imageRms(r1, r3);
  }
}
