// test_play_detail.cpp: detail lattices (canopy-voxelize --detail; format 2.0's detailLevels): a
// model whose density lattice is finer than its light lattice. The packer gives light items to the
// light levels only; the player samples the light of a detail sample from the light lattice (the
// light items of its light-level ancestor, or the Haar light at its light lattice point) and
// counts extinction per light cell.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>

#include "formats/canopy_file.h"
#include "runtime/backend.h"
#include "runtime/cone.h"
#include "runtime/scene.h"
#include "tests/play/resident.h"
#include "tests/play/scenes.h"
#include "tests/play/views.h"

namespace pl = canopy::play;
namespace pt = canopy::play::testing;
using canopy::octreepack::ModelSource;

namespace {

constexpr int kFactor = 4;                   // detail cells per light cell per axis
constexpr int kDetailLevels = 2;
constexpr int kLightEdge = 16;               // light lattice cells per axis
constexpr int kEdge = kLightEdge * kFactor;  // detail lattice cells per axis
constexpr double kLightCell = 0.1;           // metres

// A leafy detail model: sheets one detail cell thick (density 1, as canopy-voxelize --detail makes
// them at one sub-cell per detail cell) inside a ball, on a lattice kFactor times finer than the
// light lattice [0, kLightEdge), light cell c covering detail cells [4c, 4c + 4).
ModelSource detailModel() {
  ModelSource s;
  s.name = "leafy";
  s.sourceLabel = "synthetic:leafy";
  for (int a = 0; a < 3; ++a) s.latticeMin[a] = 0, s.latticeMax[a] = kEdge - 1;
  const double h = kLightCell / kFactor, c = 0.5 * kEdge;
  // detail voxel j centred at (j + 0.5) h - c h: the box [-c h, c h) per axis
  s.indexToModel = {h, 0, 0, (0.5 - c) * h, 0, h, 0, (0.5 - c) * h, 0, 0, h, (0.5 - c) * h};
  s.detailLevels = kDetailLevels;
  for (int k = 0; k < kEdge; ++k)
    for (int j = 0; j < kEdge; ++j)
      for (int i = 0; i < kEdge; ++i) {
        const double x = i + 0.5 - c, y = j + 0.5 - c, z = k + 0.5 - c;
        if (x * x + y * y + z * z > 22.0 * 22.0) continue;
        if ((i + 2 * j + 3 * k) % 7 != 0 && (3 * i + j) % 5 != 0) continue;  // sheets with gaps between them
        const float t = float(i) / kEdge;
        s.cells.push_back({{i, j, k}, 1.0f, 0.0f, {0.2f + 0.6f * t, 0.5f, 0.3f}});
      }
  return s;
}

// The same lattice box at the light resolution: each light cell the mean of its 4^3 detail cells
// (exact: counts of ones over 64), the light lattice canopy-voxelize writes beside the detail one.
ModelSource lightModel(const ModelSource& d) {
  ModelSource s;
  s.name = "leafy-light";
  s.sourceLabel = "synthetic:leafy-light";
  for (int a = 0; a < 3; ++a) s.latticeMin[a] = 0, s.latticeMax[a] = kLightEdge - 1;
  const double c = 0.5 * kLightEdge, h = kLightCell;
  s.indexToModel = {h, 0, 0, (0.5 - c) * h, 0, h, 0, (0.5 - c) * h, 0, 0, h, (0.5 - c) * h};
  std::vector<double> sum(size_t(kLightEdge) * kLightEdge * kLightEdge, 0.0);
  std::vector<double> albedo(sum.size() * 3, 0.0);
  for (const auto& cell : d.cells) {
    const size_t l = size_t(cell.ijk[0] / kFactor) + kLightEdge * (size_t(cell.ijk[1] / kFactor) + kLightEdge * size_t(cell.ijk[2] / kFactor));
    sum[l] += cell.density;
    for (int a = 0; a < 3; ++a) albedo[3 * l + size_t(a)] += double(cell.density) * cell.albedo[a];
  }
  for (int k = 0; k < kLightEdge; ++k)
    for (int j = 0; j < kLightEdge; ++j)
      for (int i = 0; i < kLightEdge; ++i) {
        const size_t l = size_t(i) + kLightEdge * (size_t(j) + kLightEdge * size_t(k));
        if (sum[l] == 0) continue;
        s.cells.push_back({{i, j, k}, float(sum[l] / 64.0), 0.0f,
                           {float(albedo[3 * l] / sum[l]), float(albedo[3 * l + 1] / sum[l]), float(albedo[3 * l + 2] / sum[l])}});
      }
  return s;
}

// Light affine in light lattice coordinates (so its trilinear interpolation anywhere is exact):
// base b, channel ch = (b + 1) (0.2 + 0.1 ch) (1 + 0.05 i + 0.03 j - 0.02 k).
void affineLight(int32_t i, int32_t j, int32_t k, float* out) {
  const float g = 1.0f + 0.05f * float(i) + 0.03f * float(j) - 0.02f * float(k);
  for (int b = 0; b < 19; ++b)
    for (int ch = 0; ch < 3; ++ch) out[3 * b + ch] = float(b + 1) * (0.2f + 0.1f * float(ch)) * g;
}
double affineLightAt(double i, double j, double k, int base, int ch) {
  return double(base + 1) * (0.2 + 0.1 * ch) * (1.0 + 0.05 * i + 0.03 * j - 0.02 * k);
}

// Writes the detail model lit by a lossless fp32 .chaar of affineLight over its light lattice
// (light items for the light levels, and the Haar pages).
void writeDetailPack(const std::string& path, const ModelSource& detail) {
  const canopy::haar::ChaarData chaar = pt::chaarOf(lightModel(detail), affineLight, 0.0f, canopy::haar::Precision::Fp32);
  canopy::CanopyHaarPages pages = canopy::canopyHaarPagesFromChaar(chaar);
  canopy::octreepack::BuiltModel b = canopy::octreepack::buildOctree(detail, detail.name, canopy::octreepack::chaarLightFn(chaar.view()));
  b.record.flags |= canopy::kCanopyModelScatteredSun;
  canopy::CanopyWriteInput w;
  w.models.push_back({b.record, &b.tiles, &b.bricks, &b.light, &pages});
  w.instances = {pt::instanceAt(0, 0, 0, 0)};
  w.metadata = "{\"tool\":\"tests/play\"}";
  canopy::writeCanopyFile(path, std::move(w));
}

}  // namespace

// The packer: light items for the light levels only, and they (with those levels' bricks) are
// exactly the light lattice model's: a detail pack's levels 0..depth - 2 are the light lattice's
// octree, byte for byte.
TEST(DetailPack, LightLevelsAreTheLightLatticesOctree) {
  const ModelSource detail = detailModel();
  const ModelSource light = lightModel(detail);
  const auto d = canopy::octreepack::buildOctree(detail, "detail", affineLight);
  const auto l = canopy::octreepack::buildOctree(light, "light", affineLight);
  EXPECT_EQ(d.record.depth, l.record.depth + kDetailLevels);
  EXPECT_EQ(d.record.detailLevels, uint32_t(kDetailLevels));
  EXPECT_EQ(canopy::canopyLightDepth(d.record), l.record.depth);
  ASSERT_EQ(d.record.lightCount, l.record.brickCount);
  ASSERT_GT(d.record.brickCount, d.record.lightCount);  // the detail levels have bricks, without items
  for (uint32_t level = 0; level <= l.record.depth; ++level) EXPECT_EQ(d.record.levelBricks[level], l.record.levelBricks[level]) << level;
  ASSERT_EQ(d.light.size(), l.light.size());
  EXPECT_TRUE(d.light == l.light);
  // the light levels' bricks: the same densities, bit for bit (means of ones: exact); albedo within
  // one unorm8 step (the detail MIP quantises each level's mean, the light lattice only once)
  ASSERT_LE(l.bricks.size(), d.bricks.size());
  int worstStep = 0;
  for (size_t b = 0; b < l.bricks.size() / canopy::kCanopyBrickBytes; ++b) {
    const unsigned char* bd = d.bricks.data() + b * canopy::kCanopyBrickBytes;
    const unsigned char* bl = l.bricks.data() + b * canopy::kCanopyBrickBytes;
    ASSERT_EQ(std::memcmp(bd, bl, canopy::kCanopyBrickVoxelCount * sizeof(float)), 0) << "brick " << b;
    for (size_t v = 0; v < canopy::kCanopyBrickVoxelCount; ++v) {
      uint32_t md, ml;
      std::memcpy(&md, bd + canopy::kCanopyBrickVoxelCount * sizeof(float) + 4 * v, 4);
      std::memcpy(&ml, bl + canopy::kCanopyBrickVoxelCount * sizeof(float) + 4 * v, 4);
      for (int c = 0; c < 4; ++c) worstStep = std::max(worstStep, std::abs(int((md >> (8 * c)) & 255u) - int((ml >> (8 * c)) & 255u)));
    }
  }
  EXPECT_LE(worstStep, 1);
  // bounds that are not whole light cells, or more than 4 detail levels, are refused
  ModelSource bad = detail;
  bad.latticeMax[1] = kEdge - 2;
  EXPECT_THROW(canopy::octreepack::buildOctree(bad, "bad"), canopy::Error);
  bad = detail;
  bad.detailLevels = 5;
  EXPECT_THROW(canopy::octreepack::buildOctree(bad, "bad"), canopy::Error);
}

// The file: a lit detail model whose finest level holds density 1 wherever it is occupied (as
// canopy-voxelize --detail writes it) makes a 4.0 file (uniform sparse bricks are 3.0, light items
// 4.0), the same model unlit a 3.0 file; a file without a detail model or light stays 1.x.
TEST(DetailPack, ADetailModelMakesA30File) {
  const std::string dir = pt::tmpDir("detail");
  const ModelSource detail = detailModel();
  writeDetailPack(dir + "/leafy.canopy", detail);
  const canopy::CanopyFile f = canopy::CanopyFile::open(dir + "/leafy.canopy");
  EXPECT_EQ(f.header().major, 4);
  EXPECT_EQ(f.header().minor, 0);
  EXPECT_EQ(f.model(0).detailLevels, uint32_t(kDetailLevels));
  pt::writeScene(dir + "/dark.canopy", {detail}, {pt::instanceAt(0, 0, 0, 0)});
  EXPECT_EQ(canopy::CanopyFile::open(dir + "/dark.canopy").header().major, 3);
  pt::writeScene(dir + "/light.canopy", {lightModel(detail)}, {pt::instanceAt(0, 0, 0, 0)});
  EXPECT_EQ(canopy::CanopyFile::open(dir + "/light.canopy").header().major, 1);
}

// The detail levels' bricks are stored sparse (format 2.0: occupied voxels only; 3.0: one density
// for an item whose stored voxels share it) and sample bit for
// bit like their dense form, at voxel centres, borders and random points, with the same empty cells
// for the march; the file holds them in fewer bytes than dense bricks.
TEST(DetailPack, SparseBricksSampleLikeTheirDenseForm) {
  const std::string dir = pt::tmpDir("detail");
  const ModelSource detail = detailModel();
  writeDetailPack(dir + "/leafy.canopy", detail);
  const canopy::CanopyFile f = canopy::CanopyFile::open(dir + "/leafy.canopy");
  const canopy::octreepack::BuiltModel b = canopy::octreepack::buildOctree(detail, detail.name, affineLight);
  const canopy::CanopyModel& M = f.model(0);
  ASSERT_EQ(M.brickCount, b.record.brickCount);
  ASSERT_EQ(M.brickCount - M.sparseBricks, M.lightCount);
  ASSERT_GT(M.sparseBricks, 0u);
  uint64_t samples = 0, sparseBytes = 0, uniformBricks = 0;
  uint32_t seed = 12345;
  auto rnd = [&]() { return float((seed = seed * 1664525u + 1013904223u) >> 8) / float(1u << 24); };
  for (uint32_t id = M.brickCount - M.sparseBricks; id < M.brickCount; ++id) {
    const canopy::CanopyFile::BrickLocation at = f.brickLocation(0, id);
    ASSERT_TRUE(at.sparse);
    const std::vector<unsigned char> page = f.readPage(at.page);
    const canopy::CanopyBrickView dense = canopy::canopyBrickAt(b.bricks.data() + size_t(id) * canopy::kCanopyBrickBytes);
    const canopy::CanopySparseBrickView sp = canopy::canopySparseBrickInPage(page.data(), at.slot);
    const bool uniform = sp.densityRank == 0;
    uniformBricks += uniform;
    sparseBytes += canopy::canopySparseItemBytes(canopy::canopySparseVoxelCount(sp.mask, sp.prefix), uniform);
    for (uint32_t v = 0; v < canopy::kCanopyBrickVoxelCount; ++v) {  // every stored voxel
      float d0, d1;
      uint32_t m0, m1;
      canopy::canopyLoadVoxel(dense, v, d0, m0);
      sp.load(v, d1, m1);
      ASSERT_EQ(d0, d1) << id << " " << v;
      if (d0 != 0.0f) {
        ASSERT_EQ(m0, m1) << id << " " << v;
      }
    }
    // the empty cells the march skips: the same as the dense brick's masks
    uint64_t mask[canopy::kCanopyEmptyWords];
    canopy::canopyBrickEmptyCells(dense, mask);
    uint32_t words[canopy::kCanopySparseEmptyWords];
    std::memcpy(words, mask, sizeof words);
    const pl::EmptyCellBits sparseEmpty{sp.empty}, denseEmpty{words};
    for (int c = 0; c < 512; ++c) {
      ASSERT_EQ(sparseEmpty(c & 7, (c >> 3) & 7, c >> 6), denseEmpty(c & 7, (c >> 3) & 7, c >> 6)) << id << " " << c;
      ASSERT_EQ(canopy::canopySparseCellEmpty(sp.mask, c & 7, (c >> 3) & 7, c >> 6), denseEmpty(c & 7, (c >> 3) & 7, c >> 6)) << id << " " << c;
    }
    for (int k = 0; k < 24; ++k) {
      const float l[3] = {k < 8 ? (float(k) + 0.5f) / 8 : rnd(), k < 8 ? 0.0f : rnd(), k < 8 ? 1.0f : rnd()};
      const canopy::CanopySample a = canopy::canopySampleBrick(dense, l[0], l[1], l[2]);
      const canopy::CanopySample c = canopy::canopySampleBrickInPage(page.data(), at.slot, true, l[0], l[1], l[2]);
      ASSERT_EQ(std::memcmp(&a, &c, sizeof a), 0) << "brick " << id;
      ++samples;
    }
  }
  std::printf("%u sparse bricks (%llu uniform): %llu samples equal to the dense form's; %.1f KB sparse against %.1f KB dense\n",
              M.sparseBricks, (unsigned long long)uniformBricks, (unsigned long long)samples, sparseBytes / 1024.0,
              M.sparseBricks * double(canopy::kCanopyBrickBytes) / 1024.0);
  EXPECT_LT(sparseBytes, uint64_t(M.sparseBricks) * canopy::kCanopyBrickBytes / 2);
  EXPECT_GT(uniformBricks, 0u);  // the finest level's (density 1), sampled above like the others'
  EXPECT_LT(uniformBricks, M.sparseBricks);  // the coarser detail levels' means are not uniform
}

// The player at a detail sample takes the light lattice's light: with the fast path, the item and
// node-local coordinates of its light-level ancestor; with --light exact, the Haar light at its
// light lattice point, which for this affine light is the light itself to float rounding.
TEST(DetailPack, DetailSamplesTakeTheLightLatticesLight) {
  const std::string dir = pt::tmpDir("detail");
  const ModelSource detail = detailModel();
  writeDetailPack(dir + "/leafy.canopy", detail);
  const canopy::CanopyFile f = canopy::CanopyFile::open(dir + "/leafy.canopy");
  const pl::HostScene scene = pl::buildScene(f);
  pt::ResidentPages pages(f);  // every page resident
  pl::SceneView s = pages.view(scene);
  const pl::ModelView& m = s.models[0];
  ASSERT_EQ(m.lightDepth + kDetailLevels, m.depth);
  ASSERT_EQ(m.lightRootCells * kFactor, m.rootCells);
  int checked = 0;
  double worst = 0;
  for (const auto& cell : detail.cells) {
    if (checked >= 400 || (cell.ijk[0] * 31 + cell.ijk[1] * 17 + cell.ijk[2]) % 13 != 0) continue;
    // a point inside the detail cell, off its centre
    const pl::V3 u = pl::v3(float((cell.ijk[0] + 0.3) / m.rootCells), float((cell.ijk[1] + 0.6) / m.rootCells), float((cell.ijk[2] + 0.45) / m.rootCells));
    const pl::Descent fine = pl::descendResident(s, m, u, m.depth, true);
    const pl::Descent coarse = pl::descendResident(s, m, u, m.lightDepth, true);
    ASSERT_EQ(fine.level, m.depth);
    ASSERT_EQ(coarse.level, m.lightDepth);
    pl::Segment gf{}, gc{};
    s.shade.exactLight = 0;
    pl::segmentLight(s, m, fine, u, 1.0f, gf);
    pl::segmentLight(s, m, coarse, u, 1.0f, gc);
    ASSERT_NE(gf.lightItem, nullptr);
    EXPECT_EQ(gf.lightItem, gc.lightItem);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(gf.light[a], gc.light[a]);
    // exact: the light lattice point of u, through the model transforms: light index
    // p = (detail index + 0.5) / 4 - 0.5
    s.shade.exactLight = 1;
    pl::Segment ge{};
    pl::segmentLight(s, m, fine, u, 1.0f, ge);
    ASSERT_NE(ge.haarLocal, pl::kHaarNone);
    ASSERT_NE(ge.haarItem, nullptr);
    const double p[3] = {double(u.x) * kLightEdge - 0.5, double(u.y) * kLightEdge - 0.5, double(u.z) * kLightEdge - 0.5};
    canopy::haar::BrickLookup at;
    at.slot = 0;
    at.lx = int(ge.haarLocal & 3u), at.ly = int((ge.haarLocal >> 2) & 3u), at.lz = int((ge.haarLocal >> 4) & 3u);
    at.fx = ge.light[0], at.fy = ge.light[1], at.fz = ge.light[2];
    for (int base : {0, 5, 18}) {
      const canopy::haar::Rgb v = canopy::canopyHaarSampleAt(ge.haarItem, 0, uint32_t(base), at);
      const float got[3] = {v.r, v.g, v.b};
      for (int ch = 0; ch < 3; ++ch) {
        // inside the lattice's outer half cell the sampler clamps: compare inside only
        if (p[0] < 0 || p[1] < 0 || p[2] < 0 || p[0] > kLightEdge - 1 || p[1] > kLightEdge - 1 || p[2] > kLightEdge - 1) continue;
        const double want = affineLightAt(p[0], p[1], p[2], base, ch);
        worst = std::max(worst, std::fabs(got[ch] - want) / want);
        EXPECT_NEAR(got[ch], want, 2e-5 * want) << "base " << base << " at (" << p[0] << "," << p[1] << "," << p[2] << ")";
      }
    }
    ++checked;
  }
  std::printf("%d detail samples: the fast path's item and coordinates are the light level's; exact light within %.2e of the light lattice's trilinear value\n",
              checked, worst);
  EXPECT_GT(checked, 100);
}

// A detail pack renders the silhouette of the same cells packed as an ordinary (dense fine)
// lattice: extinction is per light cell, so the ordinary pack at sigma / 4 has the same optical
// depth everywhere, bit for bit (scaling by a power of two is exact). Alpha RMS: 0 (stated bound
// 1e-6); the colours differ only by the light (the ordinary pack is unlit here).
TEST(DetailPack, SilhouetteEqualsTheDenseFineLattice) {
  const std::string dir = pt::tmpDir("detail");
  const ModelSource detail = detailModel();
  writeDetailPack(dir + "/leafy.canopy", detail);
  ModelSource dense = detail;
  dense.detailLevels = 0;
  pt::writeScene(dir + "/dense.canopy", {dense}, {pt::instanceAt(0, 0, 0, 0)});
  pl::PlayOptions a = pt::convergedView(dir + "/leafy.canopy", 96, 64);
  a.ground = "none";
  pl::PlayOptions b = pt::convergedView(dir + "/dense.canopy", 96, 64);
  b.ground = "none";
  b.sigma = a.sigma / kFactor;
  const std::vector<float> ia = pt::render(a), ib = pt::render(b);
  ASSERT_EQ(ia.size(), ib.size());
  double s = 0, covered = 0;
  for (size_t i = 3; i < ia.size(); i += 4) {
    s += double(ia[i] - ib[i]) * (ia[i] - ib[i]);
    covered += ia[i];
  }
  const double rms = std::sqrt(s / double(ia.size() / 4));
  std::printf("alpha RMS detail vs dense fine lattice: %.3g (covered %.1f px of %zu)\n", rms, covered, ia.size() / 4);
  EXPECT_LE(rms, 1e-6);
  EXPECT_GT(covered, 200.0);
}
