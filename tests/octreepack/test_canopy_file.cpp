// test_canopy_file.cpp: the .canopy reader never trusts its input (built with ASan/UBSan: the
// reader, writer and builder sources are compiled into this test).
//   - the frozen 4.0 file in data/ reads (its light items as built, its Haar light equal to the
//     .chaar sampler's bit for bit, its 19-base scene light as written), and the writer still
//     produces it byte for byte (a layout change must be deliberate: bump the version and add a new
//     frozen file); the frozen 3.0, 2.0, 1.2, 1.1 and 1.0 files still read (their float16 light
//     items converted as pages load), and a file without light items is still written as before;
//   - every truncated prefix, flipped bytes (header, table, sections, padding, pages), trailing
//     bytes, bad magic and a newer major version are rejected with a one-line canopy::Error.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstdlib>
#include <cstring>
#include <functional>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <tuple>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "canopy/hash.h"
#include "formats/canopy_file.h"
#include "formats/canopy_write.h"
#include "formats/chaar.h"
#include "formats/page_coding.h"
#include "tests/octreepack/packed_sampler.h"
#include "tests/octreepack/synthetic.h"

using namespace canopy;
namespace op = canopy::octreepack;

namespace {

// The frozen files of every version (5.0, 4.0, 3.0, 2.0, 1.2, 1.1, 1.0), which must still read.
const std::string kFrozenV50 = std::string(CANOPY_SOURCE_DIR) + "/tests/octreepack/data/small-v5.0.canopy";
const std::string kFrozenV40 = std::string(CANOPY_SOURCE_DIR) + "/tests/octreepack/data/small-v4.0.canopy";
const std::string kFrozen = std::string(CANOPY_SOURCE_DIR) + "/tests/octreepack/data/small-v1.2.canopy";
const std::string kFrozenV30 = std::string(CANOPY_SOURCE_DIR) + "/tests/octreepack/data/small-v3.0.canopy";
const std::string kFrozenV20 = std::string(CANOPY_SOURCE_DIR) + "/tests/octreepack/data/small-v2.0.canopy";
const std::string kFrozenV11 = std::string(CANOPY_SOURCE_DIR) + "/tests/octreepack/data/small-v1.1.canopy";
const std::string kFrozenV1 = std::string(CANOPY_SOURCE_DIR) + "/tests/octreepack/data/small-v1.0.canopy";
const std::string kFrozenChaar = std::string(CANOPY_SOURCE_DIR) + "/tests/haar/data/small_v1_0.chaar";
const std::string kFrozenChaarQuant = std::string(CANOPY_SOURCE_DIR) + "/tests/haar/data/small_v2_0.chaar";

// The Haar-lit model of the 1.1 file: every cell of the frozen .chaar's lattice occupied.
op::ModelSource haarModelSource(const haar::ChaarData& d) {
  op::ModelSource s;
  s.name = "haarlit";
  for (int a = 0; a < 3; ++a) s.latticeMin[a] = d.header.latticeMin[a], s.latticeMax[a] = d.header.latticeMax[a];
  for (int k = s.latticeMin[2]; k <= s.latticeMax[2]; ++k)
    for (int j = s.latticeMin[1]; j <= s.latticeMax[1]; ++j)
      for (int i = s.latticeMin[0]; i <= s.latticeMax[0]; ++i)
        s.cells.push_back({{i, j, k}, 0.1f + 0.05f * float((i + 2 * j + 3 * k) & 7), 0.0f, {0.3f, 0.6f, 0.2f}});
  return s;
}

// The frozen 1.2 file's scene light: a 4x3x5 lattice of 0.5 m cells, base j at node i holding
// 0.01 (i + 1) + 0.1 j (B00 first).
constexpr int kSceneDim[3] = {4, 3, 5};
float sceneLightValue(uint32_t base, uint32_t node) { return 0.01f * float(node + 1) + 0.1f * float(base); }

// The frozen detail models: a 16-cell plant on a lattice twice as fine as its 8-cell light lattice
// (2.0); with `binary`, its cells at density 1, as canopy-voxelize --detail writes a detail
// lattice (3.0: uniform sparse bricks).
op::ModelSource detailSource(bool binary) {
  op::ModelSource s = op::testing::syntheticPlant(16, 4, "detail", 0);
  s.detailLevels = 1;
  if (binary) {
    s.name = "binary";
    for (auto& c : s.cells) c.density = 1.0f;
  }
  return s;
}

// The frozen files' content. Versions 1.0-3.0 (written with float16 light items) hold part of it:
// a 20-cell synthetic plant (depth 2, density only), an 8-cell one with analytic lighting (depth 0)
// and three instances (1.0); a fourth instance of a third model lit by the frozen .chaar (light
// items of its decoded values and its Haar pages: 1.1); a coarse scene light with its 19 bases
// (SceneSunLight's B01..B18: 1.2); a detail model and a fifth instance (2.0); a second detail model
// whose finest level holds density 1 wherever it is occupied (uniform sparse bricks) and a sixth
// instance (3.0). This writer writes all of it as the 4.0 file, and with compressed pages (`coding`
// kCanopyPageZstd) as the 5.0 file.
std::vector<unsigned char> smallFileBytes(uint32_t coding = kCanopyPageRaw) {
  const op::ModelSource src = op::testing::syntheticPlant(20, 2, "frozen", 0);
  const op::BuiltModel m = op::buildOctree(src, "frozen");
  const op::BuiltModel lit = op::buildOctree(op::testing::syntheticPlant(8, 0, "lit", 0), "lit", op::testing::analyticLight);
  const haar::ChaarData chaar = haar::readChaar(kFrozenChaar);
  const CanopyHaarPages haarPages = canopyHaarPagesFromChaar(chaar);
  const op::BuiltModel haarLit = op::buildOctree(haarModelSource(chaar), "haarlit", op::chaarLightFn(chaar.view()));
  const op::BuiltModel detailModel = op::buildOctree(detailSource(false), "detail", op::testing::analyticLight);
  const op::BuiltModel binaryModel = op::buildOctree(detailSource(true), "binary", op::testing::analyticLight);
  CanopyWriteInput in;
  in.models.push_back({m.record, &m.tiles, &m.bricks, nullptr});
  in.models.push_back({lit.record, &lit.tiles, &lit.bricks, &lit.light});
  in.models.push_back({haarLit.record, &haarLit.tiles, &haarLit.bricks, &haarLit.light, &haarPages});
  in.models.push_back({detailModel.record, &detailModel.tiles, &detailModel.bricks, &detailModel.light});
  in.models.push_back({binaryModel.record, &binaryModel.tiles, &binaryModel.bricks, &binaryModel.light});
  CanopyInstance a{}, b{};
  a.modelToWorld[0] = a.modelToWorld[5] = a.modelToWorld[10] = 1.0f;
  b = a;
  b.modelToWorld[3] = 4.0f;
  CanopyInstance c = a;
  c.model = 1;
  CanopyInstance d = a;
  d.model = 2;
  d.modelToWorld[11] = -6.0f;
  CanopyInstance e = a;
  e.model = 3;
  e.modelToWorld[7] = 5.0f;
  CanopyInstance u = e;
  u.model = 4;
  u.modelToWorld[3] = -5.0f;
  in.instances = {a, b, c, d, e, u};
  in.metadata = R"({"tool":"test_canopy_file","note":"frozen .canopy 4.0"})";
  in.hasSceneLight = true;
  const double w[12] = {0.5, 0, 0, -1.0, 0, 0.5, 0, -0.25, 0, 0, 0.5, -7.0};
  for (int i = 0; i < 12; ++i) in.sceneLight.indexToWorld[i] = w[i];
  for (int k = 0; k < 3; ++k) in.sceneLight.min[k] = k - 1, in.sceneLight.dim[k] = kSceneDim[k];
  in.sceneLightBases = kCanopyLightBases;
  const uint32_t n = uint32_t(kSceneDim[0] * kSceneDim[1] * kSceneDim[2]);
  for (uint32_t base = 0; base < kCanopyLightBases; ++base)
    for (uint32_t i = 0; i < n; ++i) in.sceneLightValues.push_back(sceneLightValue(base, i));
  in.pageCoding = coding;
  return writeCanopyBytes(std::move(in));
}

// Checks that the density-only and the analytically lit models of a frozen file read as written.
void checkDensityAndLitModels(CanopyFile& f) {
  ASSERT_GE(f.modelCount(), 2u);
  ASSERT_GE(f.instanceCount(), 3u);
  EXPECT_EQ(f.model(0).lightCount, 0u);
  EXPECT_EQ(f.model(1).lightCount, f.model(1).brickCount);
  EXPECT_EQ(f.instance(2).model, 1u);
  EXPECT_FLOAT_EQ(f.instance(1).modelToWorld[3], 4.0f);
  EXPECT_EQ(std::string(f.model(0).name), "frozen");
  EXPECT_EQ(f.model(0).depth, 2u);
  // Sample every occupied cell of the source through the HD functions.
  op::testing::PackedSampler S(f);
  const op::ModelSource src = op::testing::syntheticPlant(20, 2, "frozen", 0);
  for (const auto& c : src.cells) {
    const CanopySample v = S.sampleLattice(0, float(c.ijk[0]), float(c.ijk[1]), float(c.ijk[2]));
    ASSERT_EQ(v.density, c.density);
    ASSERT_NEAR(v.albedo[1], c.albedo[1], 0.5 / 255 + 1e-6);
  }
  for (uint32_t i = 0; i < f.pageCount(); ++i) EXPECT_NO_THROW(f.readPage(i));
  // The lit model's root light item: voxel centres hold the mean of the analytic light over 2x2x2
  // cells, within the shared exponent's 1/512 of the sample's largest channel (and float16's 2^-11
  // before 4.0, whose pages canopyPreparePage converts).
  const CanopyModel& L = f.model(1);
  ASSERT_EQ(L.depth, 0u);
  auto page = f.readPage(canopyLightPage(L, 0, f.header().lightItemsPerPage));
  canopyPreparePage(page.data(), f.header());
  const uint32_t* item = canopyLightInPage(page.data(), 0);
  float tmp[kCanopyLightChannels];
  for (uint32_t base : {0u, 7u, 18u})
    for (int z = 0; z < 4; ++z)
      for (int x = 0; x < 4; ++x) {
        double ref[3] = {0, 0, 0};
        for (int s = 0; s < 8; ++s) {
          op::testing::analyticLight(L.latticeMin[0] + 2 * x + (s & 1), L.latticeMin[1] + 2 + ((s >> 1) & 1), L.latticeMin[2] + 2 * z + (s >> 2), tmp);
          for (int ch = 0; ch < 3; ++ch) ref[ch] += tmp[3 * base + ch] / 8.0;
        }
        float rgb[3];
        canopySampleLight(item, base, (float(x) + 0.5f) / 4, 1.5f / 4, (float(z) + 0.5f) / 4, rgb);
        const double largest = std::max({std::abs(ref[0]), std::abs(ref[1]), std::abs(ref[2])});
        for (int ch = 0; ch < 3; ++ch)
          ASSERT_NEAR(rgb[ch], ref[ch], largest * (1.0 / 512 + 1.0 / 2048) + 1e-6) << base << " " << x << " " << z;
      }
}

// Makes every section CRC, the table CRC and the header CRC valid again after an edit.
void reseal(std::vector<unsigned char>& b) {
  CanopyFileHeader h;
  std::memcpy(&h, b.data(), sizeof h);
  for (uint32_t i = 0; i < h.sectionCount; ++i) {
    CanopySection s;
    std::memcpy(&s, b.data() + sizeof h + i * sizeof s, sizeof s);
    s.crc = crc32(0, b.data() + s.offset, size_t(s.bytes));
    std::memcpy(b.data() + sizeof h + i * sizeof s, &s, sizeof s);
  }
  h.sectionTableCrc = crc32(0, b.data() + sizeof h, h.sectionCount * sizeof(CanopySection));
  h.headerCrc = crc32(0, &h, offsetof(CanopyFileHeader, headerCrc));
  std::memcpy(b.data(), &h, sizeof h);
}

std::string expectRejected(const std::vector<unsigned char>& bytes, bool readPages = true) {
  try {
    CanopyFile f = CanopyFile::fromMemory(bytes.data(), bytes.size(), "bad.canopy");
    if (readPages)
      for (uint32_t i = 0; i < f.pageCount(); ++i) (void)f.readPage(i);
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("bad.canopy: ", 0), 0u) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    return m;
  }
  ADD_FAILURE() << "corrupt file was accepted";
  return "";
}

// Every prefix of `good` (all of the first `every` bytes, then every `step`th) is refused as truncated.
void expectPrefixesTruncated(const std::vector<unsigned char>& good, size_t every, size_t step) {
  for (size_t n = 0; n < good.size(); n += (n < every ? 1 : step)) {
    try {
      CanopyFile f = CanopyFile::fromMemory(good.data(), n, "bad.canopy");
      FAIL() << "prefix of " << n << " bytes accepted";
    } catch (const Error& e) {
      ASSERT_EQ(e.code(), ExitCode::InvalidInput) << e.what();
      ASSERT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
    }
  }
}

// A bit flipped at each of `positions` of `good` is refused (expectRejected, pages read); one in the
// pages (from pagesOffset on) names `pageProblem`. More than 500 page flips are tried.
void expectFlipsRejected(const std::vector<unsigned char>& good, const std::vector<size_t>& positions, const std::string& pageProblem) {
  CanopyFileHeader h;
  std::memcpy(&h, good.data(), sizeof h);
  size_t pageFlips = 0;
  std::vector<unsigned char> bad = good;
  for (size_t i : positions) {
    bad[i] ^= 0x01;  // flipped in place and restored: no copy per case
    const std::string m = expectRejected(bad);
    bad[i] ^= 0x01;
    if (i >= h.pagesOffset) {
      ++pageFlips;
      EXPECT_NE(m.find(pageProblem), std::string::npos) << m;
    }
  }
  EXPECT_GT(pageFlips, 500u);
}

}  // namespace

// The 1.1 and 1.2 frozen files' Haar-lit model and their content otherwise (1.2: the scene light).
void checkFrozenV11Content(CanopyFile& f);

// A frozen file of the 1.2 content and more, opened, its version and that content checked. The
// current version's file (5.0, compressed pages) is regenerated from smallFileBytes() with
// CANOPY_WRITE_FROZEN=1, for a new format version only.
CanopyFile openFrozen(const std::string& path, int major, int minor) {
  if (std::getenv("CANOPY_WRITE_FROZEN") && major == kCanopyMajor) {
    const auto bytes = smallFileBytes(kCanopyPageZstd);
    writeFileAtomic(path, bytes.data(), bytes.size());
  }
  CanopyFile f = CanopyFile::open(path);
  EXPECT_EQ(f.header().major, major);
  EXPECT_EQ(f.header().minor, minor);
  checkFrozenV11Content(f);
  return f;
}

// The scene light of the 1.2 content (frozen files 1.2 and later).
void checkSceneLight(const CanopyFile& f) {
  // The scene light: B00 in SceneLight, B01..B18 in SceneSunLight, read back base-major.
  ASSERT_TRUE(f.hasSceneLight());
  EXPECT_EQ(f.sceneLightBases(), 19u);
  EXPECT_EQ(f.sceneLight().min[2], 1);
  EXPECT_EQ(f.sceneLight().dim[2], 5);
  EXPECT_EQ(f.sceneLight().indexToWorld[11], -7.0);
  const uint32_t n = uint32_t(kSceneDim[0] * kSceneDim[1] * kSceneDim[2]);
  ASSERT_EQ(f.sceneLightValues().size(), size_t(19 * n));
  for (uint32_t b = 0; b < 19; ++b)
    for (uint32_t i = 0; i < n; ++i) ASSERT_EQ(f.sceneLightValues()[b * n + i], sceneLightValue(b, i)) << b << " " << i;
  const CanopySection* sun = f.findSection(CanopySectionKind::SceneSunLight);
  ASSERT_NE(sun, nullptr);
  EXPECT_EQ(sun->itemCount, 18u);
  EXPECT_EQ(sun->itemBytes, n * 4);
}

TEST(CanopyFile, FrozenSmallFileStillReads) {
  CanopyFile f = openFrozen(kFrozen, 1, 2);
  EXPECT_NE(f.metadata().find("frozen .canopy 1.2"), std::string::npos);
  checkSceneLight(f);
}

// The 2.0 file: the 1.2 content plus a detail model (CanopyModel.detailLevels): light items for its
// light levels only; it reads. Without the detail model the same content is the 1.2 file (above).
TEST(CanopyFile, FrozenVersion20FileStillReads) {
  CanopyFile f = openFrozen(kFrozenV20, 2, 0);
  ASSERT_EQ(f.modelCount(), 4u);
  const CanopyModel& D = f.model(3);
  EXPECT_EQ(D.detailLevels, 1u);
  EXPECT_EQ(D.latticeMin[0], 4);
  EXPECT_EQ(D.latticeMax[0], 19);
  uint32_t lightBricks = 0;  // counted here, not by the reader's helper
  for (uint32_t l = 0; l <= D.depth - D.detailLevels; ++l) lightBricks += D.levelBricks[l];
  EXPECT_EQ(D.lightCount, lightBricks);
  EXPECT_LT(D.lightCount, D.brickCount);
  for (uint32_t i = 0; i < f.pageCount(); ++i) EXPECT_NO_THROW(f.readPage(i));
}

// A detail model's record is checked (valid CRCs): a 2.0 file's sections in a 1.x file, more detail
// levels than levels, bounds that are not whole light cells, sparse brick counts and ranges that do
// not match the detail levels.
TEST(CanopyFile, DetailModelRecordIsChecked) {
  const std::vector<unsigned char> good = readFile(kFrozenV20);
  CanopyFile f = CanopyFile::fromMemory(good.data(), good.size(), "ok.canopy");
  const CanopySection* models = f.findSection(CanopySectionKind::Models);
  ASSERT_NE(models, nullptr);
  const size_t rec = models->offset + 3 * sizeof(CanopyModel);
  auto edited = [&](auto field, uint32_t value) {
    std::vector<unsigned char> bad = good;
    std::memcpy(bad.data() + rec + field, &value, 4);
    reseal(bad);
    return expectRejected(bad, false);
  };
  EXPECT_NE(edited(offsetof(CanopyModel, detailLevels), 0).find("sparse bricks, pages or index out of range"), std::string::npos);
  EXPECT_NE(edited(offsetof(CanopyModel, sparseBricks), 0).find("sparse bricks, pages or index out of range"), std::string::npos);
  EXPECT_NE(edited(offsetof(CanopyModel, latticeMin), 5).find("not whole light cells"), std::string::npos);
  EXPECT_NE(edited(offsetof(CanopyModel, detailLevels), 9).find("more detail levels"), std::string::npos);
  std::vector<unsigned char> v1 = good;  // the same file claiming 1.2
  CanopyFileHeader h;
  std::memcpy(&h, v1.data(), sizeof h);
  h.major = 1;
  h.minor = 2;
  std::memcpy(v1.data(), &h, sizeof h);
  reseal(v1);
  EXPECT_NE(expectRejected(v1, false).find("a 1.x file has a SparseIndex section"), std::string::npos);
}

// A file's last sparse brick page, and copies of the file with that page's payload edited and every
// checksum made valid again (as a crafted file could be).
struct SparsePageForger {
  std::vector<unsigned char> good;
  size_t page = 0, table = 0;
  uint32_t index = kCanopyNone, pageBytes = 0, payloadBytes = 0;
  explicit SparsePageForger(const std::string& path) : good(readFile(path)) {
    CanopyFile f = CanopyFile::fromMemory(good.data(), good.size(), "ok.canopy");
    for (uint32_t i = 0; i < f.pageCount(); ++i)
      if (f.pageEntry(i).kind == uint32_t(CanopyPageKind::SparseBrick)) index = i;
    if (index == kCanopyNone) return;
    pageBytes = f.header().pageBytes;
    page = size_t(f.header().pagesOffset) + size_t(index) * pageBytes;
    table = f.findSection(CanopySectionKind::PageTable)->offset;
    payloadBytes = f.pageEntry(index).payloadBytes;
  }
  const unsigned char* payload() const { return good.data() + page + sizeof(CanopyPageHeader); }
  uint32_t u32(size_t at) const {  // a word of the payload
    uint32_t v;
    std::memcpy(&v, payload() + at, 4);
    return v;
  }
  std::string forged(const std::function<void(unsigned char* payload)>& edit) const {
    std::vector<unsigned char> bad = good;
    unsigned char* p = bad.data() + page;
    edit(p + sizeof(CanopyPageHeader));
    CanopyPageHeader ph;
    std::memcpy(&ph, p, sizeof ph);
    ph.crc = 0;
    std::memcpy(p, &ph, sizeof ph);
    ph.crc = canopyPageCrc(p, pageBytes);
    std::memcpy(p, &ph, sizeof ph);
    std::memcpy(bad.data() + table + size_t(index) * sizeof(CanopyPageEntry), &ph, sizeof ph);
    reseal(bad);
    return expectRejected(bad);
  }
};

void xorU32(unsigned char* p, size_t at, uint32_t with) {
  uint32_t v;
  std::memcpy(&v, p + at, 4);
  v ^= with;
  std::memcpy(p + at, &v, 4);
}

// A detail model's sparse brick pages (2.0): a flipped byte fails the page checksum; a page edited
// with valid checksums (as a crafted file could be) fails the structure check before anything
// indexes into it: an offset, a prefix count, an empty-cell bit, a stored density, a mask bit past
// the last voxel (the 3.0 uniform flag in a 2.0 file). Truncated 2.0 files are refused.
TEST(CanopyFile, SparseBrickPagesAreChecked) {
  const SparsePageForger F(kFrozenV20);
  ASSERT_NE(F.index, kCanopyNone);
  for (size_t off = 32; off < 32 + F.payloadBytes; off += 97) {
    std::vector<unsigned char> bad = F.good;
    bad[F.page + off] ^= 0x04;
    EXPECT_NE(expectRejected(bad).find("checksum mismatch"), std::string::npos) << off;
  }
  const uint32_t first = F.u32(0);  // the first item's offset
  EXPECT_NE(F.forged([&](unsigned char* q) { xorU32(q, 4, 8); }).find("sparse brick 0: "), std::string::npos);
  EXPECT_NE(F.forged([&](unsigned char* q) { xorU32(q, first + 128 + 4, 1); }).find("prefix counts"), std::string::npos);
  EXPECT_NE(F.forged([&](unsigned char* q) { xorU32(q, first + 192 + 8, 1u << 5); }).find("empty cells"), std::string::npos);
  const uint32_t nan = 0x7FC00000u;
  EXPECT_NE(F.forged([&](unsigned char* q) { std::memcpy(q + first + 256, &nan, 4); }).find("density"), std::string::npos);
  EXPECT_NE(F.forged([&](unsigned char* q) { xorU32(q, first + 124, kCanopySparseUniform); }).find("mask bits past the last voxel"),
            std::string::npos);
  for (size_t n = 0; n < F.good.size(); n += 4093) {
    try {
      CanopyFile t = CanopyFile::fromMemory(F.good.data(), n, "trunc.canopy");
      ADD_FAILURE() << "a truncated 2.0 file of " << n << " bytes was accepted";
    } catch (const Error&) {
    }
  }
}

// The 3.0 content (the 2.0 content plus a detail model of density 1 wherever it is occupied, whose
// finest level is stored in uniform sparse bricks: one density per item): its sparse bricks hold
// the built bricks' voxels.
void checkUniformDetailModel(CanopyFile& f) {
  ASSERT_EQ(f.modelCount(), 5u);
  const CanopyModel& U = f.model(4);
  EXPECT_EQ(U.detailLevels, 1u);
  ASSERT_GT(U.sparseBricks, 0u);
  const op::BuiltModel built = op::buildOctree(detailSource(true), "binary", op::testing::analyticLight);
  ASSERT_EQ(built.record.brickCount, U.brickCount);
  uint32_t uniform = 0;
  for (uint32_t id = U.brickCount - U.sparseBricks; id < U.brickCount; ++id) {
    const CanopyFile::BrickLocation at = f.brickLocation(4, id);
    ASSERT_TRUE(at.sparse);
    const std::vector<unsigned char> page = f.readPage(at.page);
    const CanopySparseBrickView sp = canopySparseBrickInPage(page.data(), at.slot);
    const CanopyBrickView dense = canopyBrickAt(built.bricks.data() + size_t(id) * kCanopyBrickBytes);
    uniform += sp.densityRank == 0;
    for (uint32_t v = 0; v < kCanopyBrickVoxelCount; ++v) {
      float d0, d1;
      uint32_t m0, m1;
      canopyLoadVoxel(dense, v, d0, m0);
      sp.load(v, d1, m1);
      ASSERT_EQ(d0, d1) << id << " " << v;
      ASSERT_EQ(d0 != 0.0f ? m0 : 0u, m1) << id << " " << v;
    }
  }
  EXPECT_EQ(uniform, U.sparseBricks);  // every finest brick of a density-1 model (none holds a single voxel here)
  for (uint32_t i = 0; i < f.pageCount(); ++i) EXPECT_NO_THROW(f.readPage(i));
}

// The 3.0 file reads (its float16 light items converted as its pages load).
TEST(CanopyFile, FrozenVersion30FileStillReads) {
  CanopyFile f = openFrozen(kFrozenV30, 3, 0);
  checkUniformDetailModel(f);
}

// The 4.0 file (the 3.0 content with shared-exponent light items) reads, its light items are the
// builder's words, and the writer still produces it byte for byte.
TEST(CanopyFile, FrozenVersion40FileReadsAndIsStillWritten) {
  CanopyFile f = openFrozen(kFrozenV40, 4, 0);
  EXPECT_NE(f.metadata().find("frozen .canopy 4.0"), std::string::npos);
  EXPECT_EQ(f.header().lightItemBytes, kCanopyLightItemBytes);
  EXPECT_EQ(f.header().lightItemsPerPage, 3u);
  checkSceneLight(f);
  checkUniformDetailModel(f);
  const op::BuiltModel lit = op::buildOctree(op::testing::syntheticPlant(8, 0, "lit", 0), "lit", op::testing::analyticLight);
  const CanopyModel& L = f.model(1);
  ASSERT_EQ(L.lightCount, 1u);
  auto page = f.readPage(canopyLightPage(L, 0, f.header().lightItemsPerPage));
  const std::vector<unsigned char> before = page;
  canopyPreparePage(page.data(), f.header());
  EXPECT_EQ(page, before) << "a 4.0 light page is sampled as stored";
  ASSERT_EQ(lit.light.size(), kCanopyLightItemBytes / 4);
  EXPECT_EQ(std::memcmp(canopyLightInPage(page.data(), 0), lit.light.data(), kCanopyLightItemBytes), 0);
  EXPECT_EQ(readFile(kFrozenV40), smallFileBytes()) << "the .canopy layout changed: bump the version";
}

// 5.0: the same content with compressed pages. Its pages decode to the 4.0 file's page images, bit
// for bit; it is smaller; the writer's bytes are the same on every run (each page compressed on its
// own); the frozen 5.0 file (another libzstd may compress to other bytes) reads as written.
TEST(CanopyFile, CompressedPagesDecodeToTheRawPages) {
  const uint32_t h32k = 32768;
  const std::vector<unsigned char> raw = smallFileBytes(), zstd = smallFileBytes(kCanopyPageZstd);
  {
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    EXPECT_EQ(zstd, smallFileBytes(kCanopyPageZstd)) << "compressed pages do not depend on the threads";
  }
  CanopyFile r = CanopyFile::fromMemory(raw.data(), raw.size(), "raw");
  // (a compressed file moved into another keeps its extents)
  CanopyFile z = CanopyFile::fromMemory(raw.data(), raw.size(), "raw");
  {
    CanopyFile opened = CanopyFile::fromMemory(zstd.data(), zstd.size(), "zstd");
    z = std::move(opened);
  }
  CanopyFile frozen = openFrozen(kFrozenV50, 5, 0);
  EXPECT_EQ(r.header().major, 4);
  EXPECT_EQ(r.header().pageCoding, kCanopyPageRaw);
  EXPECT_EQ(z.header().pageCoding, kCanopyPageZstd);
  EXPECT_EQ(frozen.header().pageCoding, kCanopyPageZstd);
  ASSERT_EQ(z.pageCount(), r.pageCount());
  ASSERT_EQ(frozen.pageCount(), r.pageCount());
  ASSERT_EQ(z.pageExtents().size(), size_t(z.pageCount()));
  EXPECT_TRUE(r.pageExtents().empty());
  std::printf("the small file: %zu bytes raw, %zu compressed (pages %llu -> %llu)\n", raw.size(), zstd.size(),
              (unsigned long long)r.storedPageBytes(), (unsigned long long)z.storedPageBytes());
  EXPECT_LT(z.storedPageBytes(), r.storedPageBytes() / 2);
  for (uint32_t i = 0; i < r.pageCount(); ++i) {
    const auto page = r.readPage(i);
    ASSERT_EQ(z.readPage(i), page) << i;
    ASSERT_EQ(frozen.readPage(i), page) << i;
  }
  EXPECT_TRUE(verifyCanopyPages(z).empty());
  // every filter round-trips (the writer keeps the smallest; here each is forced), and a page of
  // float words whose high bytes repeat (a ramp) compresses smaller in byte planes
  std::vector<unsigned char> page(h32k), back(h32k), stored;
  for (uint32_t i = 0; i < h32k / 4; ++i) {
    const float v = 1.0f + float(i) * 1.0e-4f;  // a ramp: its high bytes repeat, its low bytes do not
    std::memcpy(page.data() + 4 * i, &v, 4);
  }
  size_t plain = 0, planes = 0;
  for (int filter : {0, 2, 4}) {
    ASSERT_EQ(canopyPageEncode(page.data(), h32k, 9, stored, filter), uint32_t(filter));
    ASSERT_EQ(canopyPageDecode(stored.data(), stored.size(), uint32_t(filter), back.data(), h32k), "");
    ASSERT_EQ(back, page) << filter;
    if (filter == 0) plain = stored.size();
    if (filter == 4) planes = stored.size();
  }
  EXPECT_LT(planes, plain);
  EXPECT_EQ(canopyPageEncode(page.data(), h32k, 9, stored), 4u) << "the smallest is kept";
  EXPECT_NE(canopyPageDecode(stored.data(), stored.size(), 3, back.data(), h32k).find("unknown page filter"), std::string::npos);
  EXPECT_NE(canopyPageDecode(stored.data(), stored.size(), 4, back.data(), h32k / 2).find("not one Zstandard frame"), std::string::npos);
  checkSceneLight(z);
  checkUniformDetailModel(z);
}

// A compressed file cut anywhere is truncated, and a flip anywhere is caught: in the header and
// tables by their CRCs, in the stored pages by their stored bytes' CRC (before they are decoded).
TEST(CanopyFile, CompressedPagesRejectEveryTruncationAndFlip) {
  const std::vector<unsigned char> good = smallFileBytes(kCanopyPageZstd);
  expectPrefixesTruncated(good, 4096, 7);
  CanopyFileHeader h;
  std::memcpy(&h, good.data(), sizeof h);
  // every byte of the header and section table, every 11th of the rest of the resident part, every
  // 13th of the stored pages
  std::vector<size_t> positions;
  for (size_t i = 0; i < good.size(); i += (i < sizeof h + h.sectionCount * sizeof(CanopySection) ? 1 : (i < h.pagesOffset ? 11 : 13)))
    positions.push_back(i);
  expectFlipsRejected(good, positions, "stored bytes checksum mismatch");
}

// Crafted extents and codings with every CRC valid: each refused with its reason; and a stored
// page that is not one frame of a page, with its stored CRC made valid, refused when it is read.
TEST(CanopyFile, CompressedPageExtentsAreCheckedEvenWithValidChecksums) {
  const std::vector<unsigned char> good = smallFileBytes(kCanopyPageZstd);
  CanopyFileHeader h;
  std::memcpy(&h, good.data(), sizeof h);
  CanopyFile f = CanopyFile::fromMemory(good.data(), good.size(), "good");
  const CanopySection* se = f.findSection(CanopySectionKind::PageExtents);
  ASSERT_NE(se, nullptr);
  const auto edited = [&](auto edit) {
    std::vector<unsigned char> b = good;
    edit(b);
    reseal(b);
    return expectRejected(b, false);
  };
  const auto extentAt = [&](std::vector<unsigned char>& b, uint32_t i) { return reinterpret_cast<CanopyPageExtent*>(b.data() + se->offset) + i; };
  EXPECT_NE(edited([&](auto& b) { extentAt(b, 1)->offset += 1; }).find("extent invalid"), std::string::npos);
  EXPECT_NE(edited([&](auto& b) { extentAt(b, 2)->storedBytes = 0; }).find("extent invalid"), std::string::npos);
  EXPECT_NE(edited([&](auto& b) { extentAt(b, 0)->storedBytes = uint32_t(canopyPageStoredBound(h.pageBytes) + 1); }).find("extent invalid"),
            std::string::npos);
  EXPECT_NE(edited([&](auto& b) { extentAt(b, 0)->filter = 3; }).find("unknown filter"), std::string::npos);
  EXPECT_NE(edited([&](auto& b) { extentAt(b, 0)->reserved = 1; }).find("reserved"), std::string::npos);
  // the last page shorter by a byte: the pages end before the file does
  EXPECT_NE(edited([&](auto& b) { extentAt(b, h.pageCount - 1)->storedBytes -= 1; }).find("not at the end of the file"), std::string::npos);
  const auto header = [&](auto edit) {
    return edited([&](std::vector<unsigned char>& b) {
      CanopyFileHeader x;
      std::memcpy(&x, b.data(), sizeof x);
      edit(x);
      x.headerCrc = crc32(0, &x, offsetof(CanopyFileHeader, headerCrc));
      std::memcpy(b.data(), &x, sizeof x);
    });
  };
  EXPECT_NE(header([](CanopyFileHeader& x) { x.pageCoding = 2; }).find("page coding 2"), std::string::npos);
  EXPECT_NE(header([](CanopyFileHeader& x) { x.major = 4; }).find("page coding 1 is not valid in a 4.0 file"), std::string::npos);
  // 5.0 is the version of compressed pages: a 5.0 header of raw pages is refused
  EXPECT_NE(header([](CanopyFileHeader& x) { x.pageCoding = kCanopyPageRaw; }).find("page coding 0 is not valid in a 5.0 file"),
            std::string::npos);
  // compressed pages without their extents (the section relabelled as a kind this reader skips)
  EXPECT_NE(edited([&](std::vector<unsigned char>& b) {
              for (uint32_t i = 0; i < h.sectionCount; ++i) {
                CanopySection s;
                std::memcpy(&s, b.data() + sizeof h + i * sizeof s, sizeof s);
                if (s.kind == uint32_t(CanopySectionKind::PageExtents)) s.kind = 99;
                std::memcpy(b.data() + sizeof h + i * sizeof s, &s, sizeof s);
              }
            }).find("missing section PageExtents"),
            std::string::npos);
  // A stored page edited with its stored CRC made valid: refused when it is decoded. One byte in
  // the middle of page 0's frame: it no longer decodes, or decodes to an image its page CRC refuses;
  // a legacy Zstandard magic number (v0.7) at its start: refused before any decoder sees it.
  const auto storedEdit = [&](auto edit) {
    std::vector<unsigned char> b = good;
    CanopyPageExtent* e = reinterpret_cast<CanopyPageExtent*>(b.data() + se->offset);
    edit(b.data() + e[0].offset, e[0].storedBytes);
    e[0].storedCrc = crc32(0, b.data() + e[0].offset, e[0].storedBytes);
    reseal(b);
    return expectRejected(b);
  };
  const std::string middle = storedEdit([](unsigned char* p, uint32_t n) { p[n / 2] ^= 0x40; });
  EXPECT_NE(middle.find("page 0: "), std::string::npos) << middle;
  const std::string legacy = storedEdit([](unsigned char* p, uint32_t) {
    const uint32_t v07 = 0xFD2FB527u;
    std::memcpy(p, &v07, 4);
  });
  EXPECT_NE(legacy.find("page 0: stored page is not a Zstandard frame (magic number)"), std::string::npos) << legacy;
}

// The light item geometry must be its version's: a 4.0 file relabelled 3.0 and a 3.0 file relabelled
// 4.0 (valid CRCs) are refused, as is a 4.0 header with another item size or count per page; so are
// truncated 4.0 files.
TEST(CanopyFile, LightItemGeometryMustMatchTheVersion) {
  auto relabelled = [](const std::string& path, const std::function<void(CanopyFileHeader&)>& edit) {
    std::vector<unsigned char> b = readFile(path);
    CanopyFileHeader h;
    std::memcpy(&h, b.data(), sizeof h);
    edit(h);
    std::memcpy(b.data(), &h, sizeof h);
    reseal(b);
    return expectRejected(b, false);
  };
  for (const std::string& m : {relabelled(kFrozenV40, [](CanopyFileHeader& h) { h.major = 3; }),
                               relabelled(kFrozenV30, [](CanopyFileHeader& h) { h.major = 4; }),
                               relabelled(kFrozenV40, [](CanopyFileHeader& h) { h.lightItemBytes += 4; }),
                               relabelled(kFrozenV40, [](CanopyFileHeader& h) { h.lightItemsPerPage = 2; })})
    EXPECT_NE(m.find("unsupported light item geometry"), std::string::npos) << m;
  const std::vector<unsigned char> good = readFile(kFrozenV40);  // and truncated 4.0 files
  for (size_t n = 0; n < good.size(); n += 4093) EXPECT_THROW(CanopyFile::fromMemory(good.data(), n, "trunc.canopy"), Error) << n;
}

// A file without light items keeps the version and the header's light item geometry it had before
// 4.0, byte for byte: density-only content is written as 1.0 (2.0, 3.0 with detail levels).
TEST(CanopyFile, AFileWithoutLightItemsKeepsItsOlderVersion) {
  for (int detail = 0; detail <= 2; ++detail) {
    CanopyWriteInput in;
    const op::BuiltModel m = op::buildOctree(op::testing::syntheticPlant(20, 2, "frozen", 0), "frozen");
    in.models.push_back({m.record, &m.tiles, &m.bricks, nullptr});
    const op::BuiltModel d = op::buildOctree(detailSource(detail >= 2), "detail");
    if (detail) in.models.push_back({d.record, &d.tiles, &d.bricks, nullptr});
    CanopyInstance a{};
    a.modelToWorld[0] = a.modelToWorld[5] = a.modelToWorld[10] = 1.0f;
    in.instances = {a};
    const std::vector<unsigned char> bytes = writeCanopyBytes(std::move(in));
    CanopyFile f = CanopyFile::fromMemory(bytes.data(), bytes.size(), "unlit.canopy");
    EXPECT_EQ(f.header().major, detail == 0 ? 1 : detail == 1 ? 2 : 3) << detail;
    EXPECT_EQ(f.header().minor, 0) << detail;
    EXPECT_EQ(f.header().lightItemBytes, kCanopyLightItemBytesHalf) << detail;
    EXPECT_EQ(f.header().lightItemsPerPage, 2u) << detail;
  }
}

// A uniform sparse brick (3.0) edited with valid checksums: without its flag its size no longer
// matches its voxels, another bit past the last voxel is refused, its one density must be positive
// and finite. Truncated 3.0 files are refused.
TEST(CanopyFile, UniformSparseBricksAreChecked) {
  const SparsePageForger F(kFrozenV30);
  ASSERT_NE(F.index, kCanopyNone);
  const uint32_t first = F.u32(0);
  ASSERT_NE(F.u32(first + 124) & kCanopySparseUniform, 0u);  // the page's first item is uniform
  EXPECT_NE(F.forged([&](unsigned char* q) { xorU32(q, first + 124, kCanopySparseUniform); }).find("size does not match"),
            std::string::npos);
  EXPECT_NE(F.forged([&](unsigned char* q) { xorU32(q, first + 124, 1u << 30); }).find("mask bits past the last voxel"), std::string::npos);
  const uint32_t inf = 0x7F800000u;
  EXPECT_NE(F.forged([&](unsigned char* q) { std::memcpy(q + first + 256, &inf, 4); }).find("density"), std::string::npos);
  for (size_t n = 0; n < F.good.size(); n += 4093) {
    try {
      CanopyFile t = CanopyFile::fromMemory(F.good.data(), n, "trunc.canopy");
      ADD_FAILURE() << "a truncated 3.0 file of " << n << " bytes was accepted";
    } catch (const Error&) {
    }
  }
}

// The 1.1 file (before the scene light's sun bases) still reads.
TEST(CanopyFile, FrozenVersion11FileStillReads) {
  CanopyFile f = CanopyFile::open(kFrozenV11);
  EXPECT_EQ(f.header().major, 1);
  EXPECT_EQ(f.header().minor, 1);
  checkFrozenV11Content(f);
  EXPECT_FALSE(f.hasSceneLight());
  EXPECT_EQ(f.sceneLightBases(), 0u);
  EXPECT_NE(f.metadata().find("frozen .canopy 1.1"), std::string::npos);
}

void checkFrozenV11Content(CanopyFile& f) {
  ASSERT_GE(f.modelCount(), 3u);
  ASSERT_GE(f.instanceCount(), 4u);
  checkDensityAndLitModels(f);
  // The Haar-lit model: its Haar light at any point equals the .chaar sampler's value, bit for bit.
  const CanopyModel& H = f.model(2);
  ASSERT_TRUE(H.flags & kCanopyModelHaarLight);
  ASSERT_EQ(H.lightCount, H.brickCount);  // and float16 items as any lit model
  const haar::ChaarData chaar = haar::readChaar(kFrozenChaar);
  const haar::ChaarView view = chaar.view();
  EXPECT_EQ(H.haarItemCount, chaar.header.slotCount);
  EXPECT_EQ(H.haarPrecision, chaar.header.precision);
  op::testing::PackedSampler S(f);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(-1.0f, 7.0f);  // inside and around the 6x5x6 lattice
  for (int n = 0; n < 4000; ++n) {
    const float p[3] = {H.latticeMin[0] + U(rng), H.latticeMin[1] + U(rng), H.latticeMin[2] + U(rng)};
    const uint32_t base = uint32_t(n) % kCanopyLightBases;
    const haar::Rgb want = haar::chaarSample(view, int(base), p[0], p[1], p[2]);
    const haar::Rgb got = S.sampleHaar(2, base, p[0], p[1], p[2]);
    ASSERT_EQ(std::memcmp(&want, &got, sizeof want), 0) << "base " << base << " at " << p[0] << "," << p[1] << "," << p[2];
  }
}

// The 1.0 file (before Haar light) still reads, with the same content.
TEST(CanopyFile, FrozenVersion10FileStillReads) {
  CanopyFile f = CanopyFile::open(kFrozenV1);
  EXPECT_EQ(f.header().major, 1);
  EXPECT_EQ(f.header().minor, 0);
  ASSERT_EQ(f.modelCount(), 2u);
  ASSERT_EQ(f.instanceCount(), 3u);
  EXPECT_TRUE(f.haarIndex().empty());
  checkDensityAndLitModels(f);
  EXPECT_NE(f.metadata().find("frozen .canopy 1.0"), std::string::npos);
}

// kCanopyModelScatteredSun (1.1): only on a lit model, and not in a 1.0 file (valid CRCs).
TEST(CanopyFile, ScatteredSunFlagNeedsLightAndVersion11) {
  for (const std::string& path : {kFrozen, kFrozenV11, kFrozenV1}) {
    const std::vector<unsigned char> good = readFile(path);
    CanopyFile f = CanopyFile::fromMemory(good.data(), good.size(), "ok.canopy");
    const CanopySection* models = f.findSection(CanopySectionKind::Models);
    ASSERT_NE(models, nullptr);
    for (uint32_t m = 0; m < f.modelCount(); ++m) {
      std::vector<unsigned char> bad = good;
      const uint32_t flags = f.model(m).flags | kCanopyModelScatteredSun;
      std::memcpy(bad.data() + models->offset + m * sizeof(CanopyModel) + offsetof(CanopyModel, flags), &flags, 4);
      reseal(bad);
      const bool lit = f.model(m).flags & kCanopyModelHasLight;
      if (f.header().minor >= 1 && lit) {
        EXPECT_NO_THROW(CanopyFile::fromMemory(bad.data(), bad.size(), "flagged.canopy")) << path << " model " << m;
      } else {
        EXPECT_NE(expectRejected(bad, false).find(f.header().minor == 0 ? "in a 1.0 file" : "but no light"), std::string::npos)
            << path << " model " << m;
      }
    }
  }
}

// 1.1 keeps what a 1.0 reader requires, so that one reads a 1.1 file and skips the Haar light (a
// 1.0 reader skips unknown sections, and the pages of unknown kinds of a newer minor): every lit
// model has one light item per brick, and the Haar pages lie outside every model's brick and light
// page ranges. (Checked once by hand with the 1.0 reader of commit 0b8a7c7: it opens
// small-v1.1.canopy and reads every page.)
TEST(CanopyFile, Version11KeepsWhatA10ReaderRequires) {
  // What 1.0 checked of a model still holds for the Haar-lit one: one light item per brick.
  CanopyFile f = CanopyFile::open(kFrozenV11);
  for (uint32_t m = 0; m < f.modelCount(); ++m) {
    const CanopyModel& M = f.model(m);
    EXPECT_EQ(M.lightCount, (M.flags & kCanopyModelHasLight) ? M.brickCount : 0u);
  }
  // Every Haar page lies outside the 1.0 ranges (brick and light pages) of every model.
  for (uint32_t i = 0; i < f.pageCount(); ++i) {
    if (f.pageEntry(i).kind != uint32_t(CanopyPageKind::HaarLight)) continue;
    for (uint32_t m = 0; m < f.modelCount(); ++m) {
      const CanopyModel& M = f.model(m);
      EXPECT_FALSE(i >= M.firstBrickPage && i < M.firstBrickPage + M.brickPageCount);
      EXPECT_FALSE(i >= M.firstLightPage && i < M.firstLightPage + M.lightPageCount);
    }
  }
}

TEST(CanopyFile, EveryTruncatedPrefixIsRejected) {
  const std::vector<unsigned char> good = readFile(kFrozen);
  expectPrefixesTruncated(good, good.size(), 1);
}

TEST(CanopyFile, TrailingBytesAndBadMagicAreRejected) {
  std::vector<unsigned char> good = readFile(kFrozen);
  auto longer = good;
  longer.push_back(0);
  EXPECT_NE(expectRejected(longer).find("trailing"), std::string::npos);
  auto magic = good;
  magic[0] = 'X';
  EXPECT_NE(expectRejected(magic).find("magic"), std::string::npos);
}

TEST(CanopyFile, NewerMajorVersionIsRejectedClearly) {
  std::vector<unsigned char> bytes = readFile(kFrozen);
  CanopyFileHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  h.major = kCanopyMajor + 1;
  h.headerCrc = crc32(0, &h, offsetof(CanopyFileHeader, headerCrc));
  std::memcpy(bytes.data(), &h, sizeof h);
  try {
    CanopyFile::fromMemory(bytes.data(), bytes.size(), "bad.canopy");
    FAIL() << "newer major accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::Unsupported);
    EXPECT_NE(std::string(e.what()).find("newer than this reader"), std::string::npos) << e.what();
  }
  // A newer minor version of the same major reads.
  bytes = readFile(kFrozen);
  std::memcpy(&h, bytes.data(), sizeof h);
  h.minor = (h.major == 1 ? kCanopyMinor1 : kCanopyMinor) + 1;
  h.headerCrc = crc32(0, &h, offsetof(CanopyFileHeader, headerCrc));
  std::memcpy(bytes.data(), &h, sizeof h);
  EXPECT_NO_THROW(CanopyFile::fromMemory(bytes.data(), bytes.size(), "minor.canopy"));
}

// Every byte of the header and section table, every 11th byte of the rest of the resident part, and
// every 13th byte of every page (plus each page's header): all flips are caught.
TEST(CanopyFile, FlippedBytesAreCaught) {
  const std::vector<unsigned char> good = readFile(kFrozen);
  CanopyFileHeader h;
  std::memcpy(&h, good.data(), sizeof h);
  const size_t tableEnd = sizeof h + h.sectionCount * sizeof(CanopySection);
  std::vector<size_t> positions;
  for (size_t i = 0; i < good.size(); ++i) {
    const bool inPageHeader = i >= h.pagesOffset && (i - h.pagesOffset) % h.pageBytes < sizeof(CanopyPageHeader);
    if (i < tableEnd || inPageHeader || (i < h.pagesOffset && i % 11 == 0) || (i >= h.pagesOffset && i % 61 == 0))
      positions.push_back(i);
  }
  expectFlipsRejected(good, positions, "page");
}

// A node pointing outside its model (with every CRC made valid again) is caught by the structure
// checks, not by luck.
TEST(CanopyFile, OutOfRangePointersAreRejectedEvenWithValidChecksums) {
  std::vector<unsigned char> bytes = readFile(kFrozen);
  CanopyFile f = CanopyFile::fromMemory(bytes.data(), bytes.size(), "ok.canopy");
  const CanopySection* tiles = f.findSection(CanopySectionKind::NodeTiles);
  ASSERT_NE(tiles, nullptr);
  ASSERT_GT(tiles->itemCount, 0u);
  struct Case {
    size_t fieldOffset;
    uint32_t value;
    const char* expect;
  };
  for (const Case& c : {Case{offsetof(CanopyNode, brick), 999999u, "brick id"}, Case{offsetof(CanopyNode, child), 77u, "child tile"},
                        Case{offsetof(CanopyNode, child), 0u, "referenced twice"}}) {
    std::vector<unsigned char> bad = bytes;
    // Put the value into the first node of tile 0 that has a brick (or its child field).
    size_t at = 0;
    for (uint32_t n = 0; n < tiles->itemCount * 8; ++n) {
      CanopyNode node;
      std::memcpy(&node, bad.data() + tiles->offset + n * sizeof node, sizeof node);
      if (node.brick != kCanopyNone) {
        at = tiles->offset + n * sizeof node;
        break;
      }
    }
    ASSERT_NE(at, 0u);
    std::memcpy(bad.data() + at + c.fieldOffset, &c.value, 4);
    reseal(bad);
    const std::string m = expectRejected(bad, false);
    EXPECT_NE(m.find(c.expect), std::string::npos) << m;
  }
}

// A Haar page whose structure is wrong but whose CRCs are all valid (a crafted file) is refused by
// readPage, before any of its offsets could index device memory; so is a HaarIndex location that
// points past its page's items.
TEST(CanopyFile, CraftedHaarPagesAndLocationsAreRejectedEvenWithValidChecksums) {
  const std::vector<unsigned char> good = readFile(kFrozen);
  CanopyFile f = CanopyFile::fromMemory(good.data(), good.size(), "ok.canopy");
  const CanopyModel& H = f.model(2);
  ASSERT_GT(H.haarPageCount, 0u);
  const CanopyFileHeader& hdr = f.header();
  const uint32_t pageIndex = H.firstHaarPage;
  const CanopySection* table = f.findSection(CanopySectionKind::PageTable);
  ASSERT_NE(table, nullptr);
  // Edits the payload at `at` (bytes from the payload start), then re-CRCs the page and its table entry.
  auto craftPage = [&](size_t at, uint32_t value) {
    std::vector<unsigned char> bad = good;
    unsigned char* page = bad.data() + hdr.pagesOffset + size_t(pageIndex) * hdr.pageBytes;
    std::memcpy(page + sizeof(CanopyPageHeader) + at, &value, 4);
    CanopyPageHeader ph;
    std::memcpy(&ph, page, sizeof ph);
    ph.crc = canopyPageCrc(page, hdr.pageBytes);
    std::memcpy(page, &ph, sizeof ph);
    std::memcpy(bad.data() + table->offset + size_t(pageIndex) * sizeof(CanopyPageEntry), &ph, sizeof ph);
    reseal(bad);
    return bad;
  };
  const uint32_t items = f.pageEntry(pageIndex).itemCount;
  uint32_t off0, off1;
  std::memcpy(&off0, good.data() + hdr.pagesOffset + size_t(pageIndex) * hdr.pageBytes + sizeof(CanopyPageHeader), 4);
  std::memcpy(&off1, good.data() + hdr.pagesOffset + size_t(pageIndex) * hdr.pageBytes + sizeof(CanopyPageHeader) + 4, 4);
  ASSERT_EQ(off0, 4 * (items + 1));
  struct Case {
    size_t at;
    uint32_t value;
    const char* expect;
  };
  for (const Case& c : {Case{0, 0u, "offsets"}, Case{4, off1 + 2, "bad offset"}, Case{4, 0xFFFFFFF0u, "bad offset"},
                        Case{size_t(off0) + 18 * 12, 0xFFFFFFFFu, "size does not match"},  // item 0's B18 mask lo: more coefficients
                        Case{size_t(off0) + 8, 5u, "running sum"},                       // item 0's B00 first
                        Case{size_t(off0) + kCanopyHaarRecordBytes, 0x7f807f80u, "non-finite"}}) {  // fp16 infinities
    const std::vector<unsigned char> bad = craftPage(c.at, c.value);
    CanopyFile g = CanopyFile::fromMemory(bad.data(), bad.size(), "bad.canopy");  // the resident part is fine
    try {
      (void)g.readPage(pageIndex);
      ADD_FAILURE() << "crafted Haar page accepted (" << c.expect << ")";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(c.expect), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).rfind("bad.canopy: page " + std::to_string(pageIndex), 0), 0u) << e.what();
    }
  }
  // A model without the Haar flag whose Haar fields are not zero (any of them), with valid CRCs.
  const CanopySection* models = f.findSection(CanopySectionKind::Models);
  ASSERT_NE(models, nullptr);
  for (size_t field : {offsetof(CanopyModel, haarGroupDims), offsetof(CanopyModel, haarThreshold)}) {
    std::vector<unsigned char> bad = good;
    const uint32_t one = 0x3f800000u;  // 1 (as a count) or 1.0f
    std::memcpy(bad.data() + models->offset + field, &one, 4);  // model 0: density only
    reseal(bad);
    EXPECT_NE(expectRejected(bad, false).find("Haar fields but no Haar light flag"), std::string::npos) << field;
  }
  // A brick location past its page's items, with valid CRCs, fails at open.
  const CanopySection* hi = f.findSection(CanopySectionKind::HaarIndex);
  ASSERT_NE(hi, nullptr);
  const uint64_t groups = uint64_t(H.haarGroupDims[0]) * H.haarGroupDims[1] * H.haarGroupDims[2];
  for (uint32_t i = 0; i < kCanopyHaarGroupBricks; ++i) {
    const size_t at = hi->offset + (H.firstHaarIndex + groups + i) * 4;
    uint32_t loc;
    std::memcpy(&loc, good.data() + at, 4);
    if (loc == kCanopyNone) continue;
    std::vector<unsigned char> bad = good;
    const uint32_t past = loc | (kCanopyHaarMaxItemsPerPage - 1u);
    std::memcpy(bad.data() + at, &past, 4);
    reseal(bad);
    EXPECT_NE(expectRejected(bad, false).find("Haar brick location"), std::string::npos);
    const uint32_t twice = loc == 0 ? 1u : 0u;  // another brick's item: referenced twice
    std::memcpy(bad.data() + at, &twice, 4);
    reseal(bad);
    EXPECT_NE(expectRejected(bad, false).find("twice"), std::string::npos);
    break;
  }
}

// The scene light's sun bases (1.2) in crafted files with valid checksums: refused in a 1.1 file,
// with another base count or size than SceneLight's lattice, without SceneLight, or holding a
// negative or non-finite value; the writer refuses to write such a scene light.
TEST(CanopyFile, SceneSunLightIsCheckedEvenWithValidChecksums) {
  const std::vector<unsigned char> good = readFile(kFrozen);
  CanopyFile f = CanopyFile::fromMemory(good.data(), good.size(), "ok.canopy");
  const CanopySection* sl = f.findSection(CanopySectionKind::SceneLight);
  const CanopySection* sun = f.findSection(CanopySectionKind::SceneSunLight);
  ASSERT_NE(sl, nullptr);
  ASSERT_NE(sun, nullptr);
  const size_t sunEntry = size_t(sun - &f.section(0)), slEntry = size_t(sl - &f.section(0));
  auto editSection = [&](std::vector<unsigned char>& b, size_t entry, size_t field, uint32_t value) {
    std::memcpy(b.data() + sizeof(CanopyFileHeader) + entry * sizeof(CanopySection) + field, &value, 4);
  };
  {  // a 1.1 file
    std::vector<unsigned char> bad = good;
    CanopyFileHeader h;
    std::memcpy(&h, bad.data(), sizeof h);
    h.minor = 1;
    std::memcpy(bad.data(), &h, sizeof h);
    reseal(bad);
    EXPECT_NE(expectRejected(bad, false).find("a 1.1 file has a SceneSunLight section"), std::string::npos);
  }
  {  // 36 half-size bases (the same bytes)
    std::vector<unsigned char> bad = good;
    editSection(bad, sunEntry, offsetof(CanopySection, itemBytes), sun->itemBytes / 2);
    editSection(bad, sunEntry, offsetof(CanopySection, itemCount), sun->itemCount * 2);
    reseal(bad);
    EXPECT_NE(expectRejected(bad, false).find("SceneSunLight holds 36 bases"), std::string::npos);
  }
  {  // SceneLight's kind unknown (skipped): the sun bases have no lattice
    std::vector<unsigned char> bad = good;
    editSection(bad, slEntry, offsetof(CanopySection, kind), 99u);
    reseal(bad);
    EXPECT_NE(expectRejected(bad, false).find("SceneSunLight section without a SceneLight section"), std::string::npos);
  }
  const uint64_t n = uint64_t(kSceneDim[0]) * kSceneDim[1] * kSceneDim[2];
  for (const auto& [at, value, base] : {std::tuple<uint64_t, float, const char*>{sun->offset + 4 * (4 * n + 7), -0.5f, "B05"},
                                        {sl->offset + sizeof(CanopySceneLight) + 4 * 3, std::numeric_limits<float>::quiet_NaN(), "B00"},
                                        {sun->offset + 4 * (17 * n), std::numeric_limits<float>::infinity(), "B18"}}) {
    std::vector<unsigned char> bad = good;
    std::memcpy(bad.data() + at, &value, 4);
    reseal(bad);
    const std::string m = expectRejected(bad, false);
    EXPECT_NE(m.find(std::string("scene light base ") + base), std::string::npos) << m;
    EXPECT_NE(m.find("negative or not finite"), std::string::npos) << m;
  }
  // The writer: 1 or 19 bases, values finite and >= 0, base-major sizes.
  CanopyWriteInput in;
  in.hasSceneLight = true;
  for (int a = 0; a < 3; ++a) in.sceneLight.dim[a] = 2;
  in.sceneLight.indexToWorld[0] = in.sceneLight.indexToWorld[5] = in.sceneLight.indexToWorld[10] = 1.0;
  for (auto [bases, count, value, expect] : {std::tuple<uint32_t, size_t, float, const char*>{2, 16, 1.0f, "1 or 19 bases"},
                                              {19, 8 * 18, 1.0f, "size mismatch"},
                                              {19, 8 * 19, -1.0f, "negative or not finite"}}) {
    CanopyWriteInput w = in;
    w.sceneLightBases = bases;
    w.sceneLightValues.assign(count, value);
    try {
      writeCanopyBytes(std::move(w));
      ADD_FAILURE() << "scene light of " << bases << " bases, " << count << " values accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
  CanopyWriteInput ok = in;  // the same input with a valid scene light writes
  ok.sceneLightBases = 19;
  ok.sceneLightValues.assign(8 * 19, 1.0f);
  const std::vector<unsigned char> bytes = writeCanopyBytes(std::move(ok));
  EXPECT_EQ(CanopyFile::fromMemory(bytes.data(), bytes.size(), "ok.canopy").sceneLightBases(), 19u);
}

// Light items are float16 through canopy/half.h; the writer's policy on top is saturation: out of
// range lighting becomes +-65504, never infinity. Pins the bits the frozen file and the player use.
// A quantised .chaar (2.x) packs as float16 light items of its sampler's values; its Haar pages
// (no layout for quantised bricks yet) are refused with Unsupported, not mis-packed.
TEST(CanopyFile, QuantisedChaarPacksAsLightItemsAndItsHaarPagesAreRefused) {
  const haar::ChaarData q = haar::readChaar(kFrozenChaarQuant);
  ASSERT_EQ(q.precision(), haar::Precision::Quant);
  try {
    canopyHaarPagesFromChaar(q);
    ADD_FAILURE() << "quantised Haar pages accepted";
  } catch (const canopy::Error& e) {
    EXPECT_EQ(e.code(), canopy::ExitCode::Unsupported) << e.what();
  }
  const op::LightFn fn = op::chaarLightFn(q.view());
  std::vector<float> o(3 * kCanopyLightBases);
  fn(0, 3, 2, o.data());
  const haar::Rgb s = haar::chaarSample(q.view(), 7, 0.0f, 3.0f, 2.0f);
  EXPECT_EQ(o[3 * 7 + 1], s.g);
  EXPECT_GT(s.g, 0.0f);
  const op::BuiltModel m = op::buildOctree(haarModelSource(q), "quantlit", fn);
  EXPECT_FALSE(m.light.empty());
}

// A light page of a file before 4.0 (float16 planes) becomes 4.0's items as it loads: each sample's
// word is the encoding of its three halves, item by item at 4.0's stride; the file's bytes are
// unchanged (the page read again still verifies).
TEST(CanopyFile, Float16LightPagesAreConvertedAsTheyLoad) {
  CanopyFile f = CanopyFile::open(kFrozenV30);
  ASSERT_EQ(f.header().lightItemBytes, kCanopyLightItemBytesHalf);
  uint32_t converted = 0;
  for (uint32_t i = 0; i < f.pageCount(); ++i) {
    if (f.pageEntry(i).kind != uint32_t(CanopyPageKind::Light)) continue;
    const std::vector<unsigned char> raw = f.readPage(i);
    std::vector<unsigned char> page = raw;
    canopyPreparePage(page.data(), f.header());
    for (uint32_t item = 0; item < f.pageEntry(i).itemCount; ++item) {
      const unsigned char* half = raw.data() + sizeof(CanopyPageHeader) + size_t(item) * kCanopyLightItemBytesHalf;
      const uint32_t* words = canopyLightInPage(page.data(), item);
      for (uint32_t b = 0; b < kCanopyLightBases; ++b)
        for (uint32_t v = 0; v < kCanopyLightVoxelCount; ++v) {
          float rgb[3];
          for (uint32_t ch = 0; ch < 3; ++ch) {
            uint16_t h;
            std::memcpy(&h, half + 2 * ((size_t(3 * b + ch)) * kCanopyLightVoxelCount + v), 2);
            rgb[ch] = halfToFloat(h);
          }
          ASSERT_EQ(words[b * kCanopyLightVoxelCount + v], rgb9e5Encode(rgb[0], rgb[1], rgb[2])) << i << " " << item << " " << b << " " << v;
        }
      ++converted;
    }
    EXPECT_NO_THROW(f.readPage(i));
  }
  EXPECT_GE(converted, 4u);
}
