// canopy_write.cpp: see canopy_write.h.
#include "formats/canopy_write.h"
#include "formats/item_pages.h"
#include "formats/page_coding.h"

#include <algorithm>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <functional>
#include <memory>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "canopy/hash.h"
#include "canopy/parallel.h"

namespace canopy {
namespace {

uint64_t alignUp(uint64_t v, uint64_t a) { return (v + a - 1) / a * a; }

// A dense brick (kCanopyBrickBytes) as a sparse brick item (canopy_layout.h, "Sparse bricks"): the
// voxels of non-zero density only (the others hold density 0 and, as the builder writes them,
// material 0: a sample reads the same values). An item of n >= 2 stored voxels of one density is
// uniform (3.0): that density once. Returns whether it is.
bool appendSparseItem(const unsigned char* dense, std::vector<unsigned char>& out) {
  float d[kCanopyBrickVoxelCount];
  uint32_t m[kCanopyBrickVoxelCount];
  std::memcpy(d, dense, sizeof d);
  std::memcpy(m, dense + sizeof d, sizeof m);
  uint32_t mask[kCanopySparseMaskWords] = {};
  uint16_t prefix[kCanopySparseMaskWords] = {};
  std::vector<float> dv;
  std::vector<uint32_t> mv;
  for (uint32_t v = 0; v < kCanopyBrickVoxelCount; ++v) {
    if (d[v] == 0.0f) continue;
    mask[v >> 5] |= 1u << (v & 31u);
    dv.push_back(d[v]);
    mv.push_back(m[v]);
  }
  for (uint32_t w = 1; w < kCanopySparseMaskWords; ++w) prefix[w] = uint16_t(prefix[w - 1] + __builtin_popcount(mask[w - 1]));
  const bool uniform = dv.size() >= 2 && std::all_of(dv.begin(), dv.end(), [&](float x) { return x == dv[0]; });
  if (uniform) {
    mask[kCanopySparseMaskWords - 1] |= kCanopySparseUniform;
    dv.resize(1);
  }
  uint64_t empty[kCanopyEmptyWords];  // the march's empty cells (as a page reader fills them for dense bricks)
  canopyBrickEmptyCells(canopyBrickAt(dense), empty);
  static_assert(sizeof empty == kCanopySparseEmptyWords * 4, "512 empty-cell bits");
  const size_t at = out.size();
  out.resize(at + canopySparseItemBytes(uint32_t(mv.size()), uniform));
  unsigned char* p = out.data() + at;
  std::memcpy(p, mask, sizeof mask);
  std::memcpy(p + sizeof mask, prefix, sizeof prefix);
  std::memcpy(p + sizeof mask + sizeof prefix, empty, sizeof empty);  // little-endian: bit i in 32-bit word i / 32
  std::memcpy(p + kCanopySparseHeadBytes, dv.data(), dv.size() * 4);
  std::memcpy(p + kCanopySparseHeadBytes + dv.size() * 4, mv.data(), mv.size() * 4);
  return uniform;
}

// A detail model's sparse pages: bricks first..count-1 of `bricks` (dense), in id order, in
// whole-item pages (CanopyItemPager), and the location of each (page << 12 | item).
struct SparsePages {
  std::vector<std::vector<unsigned char>> payloads;
  std::vector<uint32_t> itemCounts, index;
  bool uniform = false;  // an item is uniform (3.0)
};
SparsePages sparsePagesOf(const std::vector<unsigned char>& bricks, uint32_t first, uint32_t count, uint32_t pageBytes) {
  // the items side by side (a detail model has tens of thousands), then paged in id order
  std::vector<std::vector<unsigned char>> items(count - first);
  std::vector<unsigned char> uniform(items.size());
  parallelFor(int64_t(items.size()), [&](int64_t i) {
    uniform[size_t(i)] = appendSparseItem(bricks.data() + (size_t(first) + size_t(i)) * kCanopyBrickBytes, items[size_t(i)]);
  }, 64);
  CanopyItemPager pager(pageBytes, kCanopySparseMaxItemsPerPage);
  SparsePages P;
  for (size_t i = 0; i < items.size(); ++i) {
    if (uniform[i]) P.uniform = true;
    const auto [page, inPage] = pager.add(std::move(items[i]));
    P.index.push_back(page << kCanopySparseItemBits | inPage);
  }
  pager.finish();
  P.payloads = std::move(pager.payloads);
  P.itemCounts = std::move(pager.itemCounts);
  return P;
}

struct Layout {
  std::vector<unsigned char> resident;   // header .. end of resident part (zero padded)
  std::vector<CanopyPageEntry> pages;
  CanopyWriteStats stats;
};

using EmitPage = std::function<void(uint32_t, std::vector<unsigned char>&)>;

// The page geometry the writer lays out with.
struct PageGeometry {
  uint32_t pageBytes = kCanopyPageBytes;
  uint32_t perPage = (pageBytes - uint32_t(sizeof(CanopyPageHeader))) / kCanopyBrickBytes;
  uint32_t lightPerPage = (pageBytes - uint32_t(sizeof(CanopyPageHeader))) / kCanopyLightItemBytes;
};

// The models with their ranges assigned, and the tables and pages those ranges index.
struct Ranges {
  std::vector<CanopyModel> models;
  std::vector<CanopyNode> tiles;
  std::vector<uint32_t> haarIndex;
  std::vector<uint32_t> sparseIndex;            // (2.0) detail models' sparse brick locations
  std::vector<SparsePages> sparse;
  bool detail = false;        // a model with detail levels (2.0)
  bool uniform = false;       // a uniform sparse brick (3.0)
  bool lit = false;           // a model with light items (4.0)
  uint32_t page = 0;          // the next page
};

// Lays out model m's tiles, brick pages and light pages and sets its light flags; returns its dense bricks.
uint32_t placeBricksAndLight(const CanopyWriteModel& wm, CanopyModel& m, Ranges& R, const PageGeometry& g) {
  if (!wm.tiles || !wm.bricks || wm.tiles->size() != size_t(m.tileCount) * 8 ||
      wm.bricks->size() != size_t(m.brickCount) * kCanopyBrickBytes)
    throw invalidInput("canopy writer: model '" + std::string(m.name) + "' has inconsistent tile/brick sizes");
  m.firstTile = uint32_t(R.tiles.size() / 8);
  R.tiles.insert(R.tiles.end(), wm.tiles->begin(), wm.tiles->end());
  // (2.0) a detail model's detail levels go to sparse pages, after its other pages
  const uint64_t lightBricks = canopyLightLevelBricks(m);  // the ones with light items, and the dense ones
  if (m.detailLevels > m.depth || lightBricks > m.brickCount)
    throw invalidInput("canopy writer: model '" + std::string(m.name) + "' has inconsistent level brick counts");
  const uint32_t denseBricks = m.detailLevels != 0 ? uint32_t(lightBricks) : m.brickCount;
  m.sparseBricks = m.brickCount - denseBricks;
  m.firstBrickPage = R.page;
  m.brickPageCount = (denseBricks + g.perPage - 1) / g.perPage;
  R.page += m.brickPageCount;
  const bool lit = wm.light && !wm.light->empty();
  const bool haar = wm.haar != nullptr;
  R.detail = R.detail || m.detailLevels != 0;
  R.lit = R.lit || lit;
  if (lit && (m.lightCount != lightBricks || wm.light->size() * 4 != size_t(m.lightCount) * kCanopyLightItemBytes))
    throw invalidInput("canopy writer: model '" + std::string(m.name) + "' has inconsistent light items");
  if (haar && !lit) throw invalidInput("canopy writer: model '" + std::string(m.name) + "' has Haar light but no light items");
  m.lightCount = lit ? m.lightCount : 0;
  m.firstLightPage = R.page;
  m.lightPageCount = (m.lightCount + g.lightPerPage - 1) / g.lightPerPage;
  R.page += m.lightPageCount;
  m.flags = lit ? (m.flags | kCanopyModelHasLight) : (m.flags & ~uint32_t(kCanopyModelHasLight | kCanopyModelScatteredSun));
  return denseBricks;
}

// Sets model m's Haar fields (all zero without Haar light) and lays out its Haar index and pages.
void placeHaar(const CanopyWriteModel& wm, CanopyModel& m, Ranges& R) {
  const bool haar = wm.haar != nullptr;
  m.flags &= ~uint32_t(kCanopyModelHaarLight);
  m.haarPrecision = m.haarGroups = m.haarItemCount = m.firstHaarIndex = m.haarIndexCount = m.firstHaarPage = m.haarPageCount = 0;
  m.haarThreshold = 0.0f;
  for (int a = 0; a < 3; ++a) m.haarBrickDims[a] = 0, m.haarGroupDims[a] = 0;
  if (haar) {
    const CanopyHaarPages& H = *wm.haar;
    if (H.payloads.size() != H.itemCounts.size() || H.index.size() < size_t(H.groupDims[0]) * H.groupDims[1] * H.groupDims[2])
      throw invalidInput("canopy writer: model '" + std::string(m.name) + "' has inconsistent Haar pages");
    m.flags |= kCanopyModelHaarLight;
    m.haarPrecision = H.precision;
    for (int a = 0; a < 3; ++a) m.haarBrickDims[a] = H.brickDims[a], m.haarGroupDims[a] = H.groupDims[a];
    m.haarGroups = H.groups;
    m.haarItemCount = H.items;
    m.haarThreshold = H.threshold;
    m.firstHaarIndex = uint32_t(R.haarIndex.size());
    m.haarIndexCount = uint32_t(H.index.size());
    R.haarIndex.insert(R.haarIndex.end(), H.index.begin(), H.index.end());
    m.firstHaarPage = R.page;
    m.haarPageCount = uint32_t(H.payloads.size());
    R.page += m.haarPageCount;
  }
}

// Lays out model mi's sparse bricks (2.0: its detail levels), their index entries and pages.
void placeSparse(const CanopyWriteModel& wm, CanopyModel& m, size_t mi, uint32_t denseBricks, Ranges& R, uint32_t pageBytes) {
  m.firstSparsePage = m.sparsePageCount = m.firstSparseIndex = 0;
  if (m.sparseBricks > 0) {
    R.sparse[mi] = sparsePagesOf(*wm.bricks, denseBricks, m.brickCount, pageBytes);
    m.firstSparseIndex = uint32_t(R.sparseIndex.size());
    R.sparseIndex.insert(R.sparseIndex.end(), R.sparse[mi].index.begin(), R.sparse[mi].index.end());
    m.firstSparsePage = R.page;
    m.sparsePageCount = uint32_t(R.sparse[mi].payloads.size());
    R.uniform = R.uniform || R.sparse[mi].uniform;
    R.page += m.sparsePageCount;
  }
}

// Assigns each model its ranges, in model order, and checks the instances' model numbers.
Ranges assignModelRanges(const CanopyWriteInput& in, const PageGeometry& g) {
  Ranges R;
  R.sparse.resize(in.models.size());
  for (size_t mi = 0; mi < in.models.size(); ++mi) {
    const CanopyWriteModel& wm = in.models[mi];
    CanopyModel m = wm.record;
    const uint32_t denseBricks = placeBricksAndLight(wm, m, R, g);
    placeHaar(wm, m, R);
    placeSparse(wm, m, mi, denseBricks, R, g.pageBytes);
    R.models.push_back(m);
  }
  for (const CanopyInstance& inst : in.instances)
    if (inst.model >= R.models.size()) throw invalidInput("canopy writer: instance names a model out of range");
  return R;
}

// Builds page images (header, payload, CRC), appends their headers to the page table and hands
// each image to emitPage.
struct PageBuilder {
  uint32_t pageBytes;
  const EmitPage& emitPage;
  std::vector<CanopyPageEntry>& pages;
  std::vector<unsigned char> img = std::vector<unsigned char>(pageBytes);

  void add(CanopyPageKind kind, uint32_t index, uint32_t model, uint32_t first, uint32_t count, const unsigned char* payload,
           uint32_t payloadBytes) {
    std::fill(img.begin(), img.end(), 0);
    CanopyPageHeader h{};
    std::memcpy(h.magic, kCanopyPageMagic, 4);
    h.kind = uint32_t(kind);
    h.pageIndex = index;
    h.model = model;
    h.firstItem = first;
    h.itemCount = count;
    h.payloadBytes = payloadBytes;
    if (payloadBytes > pageBytes - sizeof h) throw invalidInput("canopy writer: a page payload is larger than a page");
    std::memcpy(img.data() + sizeof h, payload, h.payloadBytes);
    std::memcpy(img.data(), &h, sizeof h);
    h.crc = canopyPageCrc(img.data(), pageBytes);
    std::memcpy(img.data(), &h, sizeof h);
    pages.push_back(h);
    if (emitPage) emitPage(h.pageIndex, img);
  }
};

// The page table (and page images through emitPage): each model's brick, light, Haar and sparse pages.
void buildPages(const CanopyWriteInput& in, const Ranges& R, const PageGeometry& g, const EmitPage& emitPage,
                std::vector<CanopyPageEntry>& pages) {
  const uint32_t perPage = g.perPage, lightPerPage = g.lightPerPage;
  PageBuilder pb{g.pageBytes, emitPage, pages};
  for (uint32_t mi = 0; mi < R.models.size(); ++mi) {
    const CanopyModel& m = R.models[mi];
    for (uint32_t p = 0; p < m.brickPageCount; ++p) {
      const uint32_t n = std::min(perPage, m.brickCount - m.sparseBricks - p * perPage);
      pb.add(CanopyPageKind::Brick, m.firstBrickPage + p, mi, p * perPage, n,
             in.models[mi].bricks->data() + size_t(p) * perPage * kCanopyBrickBytes, n * kCanopyBrickBytes);
    }
    for (uint32_t p = 0; p < m.lightPageCount; ++p) {
      const uint32_t n = std::min(lightPerPage, m.lightCount - p * lightPerPage);
      pb.add(CanopyPageKind::Light, m.firstLightPage + p, mi, p * lightPerPage, n,
             reinterpret_cast<const unsigned char*>(in.models[mi].light->data()) + size_t(p) * lightPerPage * kCanopyLightItemBytes,
             n * kCanopyLightItemBytes);
    }
    uint32_t item = 0;
    for (uint32_t p = 0; p < m.haarPageCount; ++p) {
      const CanopyHaarPages& H = *in.models[mi].haar;
      pb.add(CanopyPageKind::HaarLight, m.firstHaarPage + p, mi, item, H.itemCounts[p], H.payloads[p].data(), uint32_t(H.payloads[p].size()));
      item += H.itemCounts[p];
    }
    uint32_t brick = m.brickCount - m.sparseBricks;
    for (uint32_t p = 0; p < m.sparsePageCount; ++p) {
      const SparsePages& S = R.sparse[mi];
      pb.add(CanopyPageKind::SparseBrick, m.firstSparsePage + p, mi, brick, S.itemCounts[p], S.payloads[p].data(), uint32_t(S.payloads[p].size()));
      brick += S.itemCounts[p];
    }
  }
}

// A resident section's bytes, before it is placed.
struct Blob {
  CanopySectionKind kind;
  uint32_t itemBytes, itemCount;
  std::vector<unsigned char> bytes;
  const char* name;
};

Blob blobOf(CanopySectionKind k, const void* p, uint32_t itemBytes, uint32_t count) {
  Blob b{k, itemBytes, count, {}, canopySectionLabel(uint32_t(k))};
  b.bytes.assign(static_cast<const unsigned char*>(p), static_cast<const unsigned char*>(p) + size_t(itemBytes) * count);
  return b;
}

// Checks the scene light and adds its SceneLight (and 1.2 SceneSunLight) section; returns whether
// the scene lattice's sun bases were added.
bool addSceneLightBlobs(const CanopyWriteInput& in, std::vector<Blob>& blobs) {
  bool sceneSun = false;  // the scene lattice's sun bases (1.2)
  if (in.hasSceneLight) {
    uint64_t n = 1;
    for (int a = 0; a < 3; ++a) n *= uint64_t(std::max(0, in.sceneLight.dim[a]));
    const uint32_t bases = in.sceneLightBases;
    if (bases != 1 && bases != 1 + kCanopySceneSunBases)
      throw invalidInput("canopy writer: a scene light has 1 or 19 bases, not " + std::to_string(bases));
    if (n == 0 || n * bases != in.sceneLightValues.size()) throw invalidInput("canopy writer: scene light size mismatch");
    if (n * sizeof(float) > 0xFFFFFFFFu) throw invalidInput("canopy writer: scene light lattice too large");
    for (float v : in.sceneLightValues)
      if (!(v >= 0.0f) || v > 3.0e38f) throw invalidInput("canopy writer: scene light value negative or not finite");
    Blob b{CanopySectionKind::SceneLight, 0, 1, {}, canopySectionLabel(uint32_t(CanopySectionKind::SceneLight))};
    b.bytes.resize(sizeof(CanopySceneLight) + n * sizeof(float));
    std::memcpy(b.bytes.data(), &in.sceneLight, sizeof(CanopySceneLight));
    std::memcpy(b.bytes.data() + sizeof(CanopySceneLight), in.sceneLightValues.data(), n * sizeof(float));
    blobs.push_back(std::move(b));
    if (bases > 1) {
      blobs.push_back(blobOf(CanopySectionKind::SceneSunLight, in.sceneLightValues.data() + n, uint32_t(n * sizeof(float)),
                             kCanopySceneSunBases));
      sceneSun = true;
    }
  }
  return sceneSun;
}

// The resident sections, in file order; sceneSun: whether the scene lattice's sun bases are among them.
// extents: (5.0) the compressed pages' extents (PageExtents), or null for raw pages.
std::vector<Blob> residentBlobs(const CanopyWriteInput& in, const Ranges& R, const std::vector<CanopyPageEntry>& pages,
                                const std::vector<CanopyPageExtent>* extents, bool& sceneSun) {
  std::vector<Blob> blobs;
  blobs.push_back(blobOf(CanopySectionKind::Models, R.models.data(), sizeof(CanopyModel), uint32_t(R.models.size())));
  blobs.push_back(blobOf(CanopySectionKind::Instances, in.instances.data(), sizeof(CanopyInstance), uint32_t(in.instances.size())));
  blobs.push_back(blobOf(CanopySectionKind::NodeTiles, R.tiles.data(), sizeof(CanopyNode) * 8, uint32_t(R.tiles.size() / 8)));
  blobs.push_back(blobOf(CanopySectionKind::PageTable, pages.data(), sizeof(CanopyPageEntry), uint32_t(pages.size())));
  sceneSun = addSceneLightBlobs(in, blobs);
  if (!R.haarIndex.empty())
    blobs.push_back(blobOf(CanopySectionKind::HaarIndex, R.haarIndex.data(), sizeof(uint32_t), uint32_t(R.haarIndex.size())));
  if (!R.sparseIndex.empty())
    blobs.push_back(blobOf(CanopySectionKind::SparseIndex, R.sparseIndex.data(), sizeof(uint32_t), uint32_t(R.sparseIndex.size())));
  if (extents)
    blobs.push_back(blobOf(CanopySectionKind::PageExtents, extents->data(), sizeof(CanopyPageExtent), uint32_t(extents->size())));
  if (!in.metadata.empty()) {
    Blob b{CanopySectionKind::Metadata, 0, 1, {}, canopySectionLabel(uint32_t(CanopySectionKind::Metadata))};
    b.bytes.assign(in.metadata.begin(), in.metadata.end());
    blobs.push_back(std::move(b));
  }
  return blobs;
}

// The section table and where the pages start.
struct Sections {
  std::vector<CanopySection> table;
  uint64_t pagesOffset;
};

// Places the sections after the table, each aligned, and fills the resident image but its header.
Sections placeSections(const std::vector<Blob>& blobs, uint32_t pageBytes, Layout& L) {
  std::vector<CanopySection> table(blobs.size());
  uint64_t off = alignUp(sizeof(CanopyFileHeader) + blobs.size() * sizeof(CanopySection), kCanopySectionAlign);
  for (size_t i = 0; i < blobs.size(); ++i) {
    CanopySection& s = table[i];
    s.kind = uint32_t(blobs[i].kind);
    s.itemBytes = blobs[i].itemBytes;
    s.itemCount = blobs[i].itemCount;
    s.offset = off;
    s.bytes = blobs[i].bytes.size();
    s.crc = crc32(0, blobs[i].bytes.data(), blobs[i].bytes.size());
    off = alignUp(off + s.bytes, kCanopySectionAlign);
    L.stats.sections.push_back({blobs[i].name, s.bytes});
  }
  const uint64_t pagesOffset = alignUp(off, pageBytes);
  L.resident.assign(pagesOffset, 0);
  for (size_t i = 0; i < blobs.size(); ++i)
    if (!blobs[i].bytes.empty()) std::memcpy(L.resident.data() + table[i].offset, blobs[i].bytes.data(), blobs[i].bytes.size());
  std::memcpy(L.resident.data() + sizeof(CanopyFileHeader), table.data(), table.size() * sizeof(CanopySection));
  return {std::move(table), pagesOffset};
}

// The file header (version, sizes, checksums) into the resident image, and the stats.
void writeHeader(const CanopyWriteInput& in, const Ranges& R, const Sections& S, bool sceneSun, const PageGeometry& g,
                 const std::vector<CanopyPageExtent>* extents, Layout& L) {
  const std::vector<CanopySection>& table = S.table;
  const uint64_t pagesOffset = S.pagesOffset;
  const uint32_t pageBytes = g.pageBytes;
  CanopyFileHeader h{};
  std::memcpy(h.magic, kCanopyMagic, 8);
  // A file with light items is 4.0; without, with a uniform sparse brick 3.0; with a detail model but
  // none, 2.0; else 1.2 with the scene lattice's sun bases and 1.0 without, byte for byte as before.
  // (1.1's features, Haar light and scattered-only sun bases, exist only with light items: a Haar
  // model needs them, and the flag is cleared on a model without them.)
  // Compressed pages (the PageExtents section) are 5.0 whatever else the file holds.
  h.major = extents ? 5 : R.lit ? 4 : R.uniform ? 3 : R.detail ? 2 : 1;
  h.minor = h.major == 1 && sceneSun ? 2 : 0;
  static_assert(kCanopyMajor == 5 && kCanopyMinor == 0 && kCanopyMinor1 == 2, "the writer's versions");
  h.pageCoding = extents ? kCanopyPageZstd : kCanopyPageRaw;
  h.headerBytes = sizeof(CanopyFileHeader);
  h.pageBytes = pageBytes;
  h.pageCount = uint32_t(L.pages.size());
  h.pagesOffset = pagesOffset;
  h.residentBytes = pagesOffset;
  uint64_t pageArea = uint64_t(h.pageCount) * pageBytes;
  if (extents) {
    pageArea = 0;
    for (const CanopyPageExtent& e : *extents) pageArea += e.storedBytes;
  }
  h.fileBytes = pagesOffset + pageArea;
  h.sectionCount = uint32_t(table.size());
  h.sectionTableCrc = crc32(0, table.data(), table.size() * sizeof(CanopySection));
  h.modelCount = uint32_t(R.models.size());
  h.instanceCount = uint32_t(in.instances.size());
  h.brickVoxels = kCanopyBrickVoxels;
  h.brickBytes = kCanopyBrickBytes;
  h.bricksPerPage = g.perPage;
  // The light item geometry of the version written (a file without light items keeps 1.x-3.0's).
  h.lightItemBytes = h.major >= 4 ? kCanopyLightItemBytes : kCanopyLightItemBytesHalf;
  h.lightItemsPerPage = (pageBytes - uint32_t(sizeof(CanopyPageHeader))) / h.lightItemBytes;
  h.headerCrc = crc32(0, &h, offsetof(CanopyFileHeader, headerCrc));
  std::memcpy(L.resident.data(), &h, sizeof h);

  L.stats.fileBytes = h.fileBytes;
  L.stats.residentBytes = h.residentBytes;
  L.stats.pageCount = h.pageCount;
  L.stats.sections.push_back({"pages", pageArea});
  L.stats.pageBytes = uint64_t(h.pageCount) * pageBytes;
  L.stats.pageCoding = h.pageCoding;
}

// The resident image of the page table `pages` (and, compressed, their extents: null gives the
// compressed layout with every extent zero, which has the same size).
void residentImage(const CanopyWriteInput& in, const Ranges& R, const PageGeometry& g, const std::vector<CanopyPageExtent>* extents,
                   Layout& L) {
  std::vector<CanopyPageExtent> zero;
  if (in.pageCoding == kCanopyPageZstd && !extents) {
    zero.assign(L.pages.size(), CanopyPageExtent{});
    extents = &zero;
  }
  if (in.pageCoding != kCanopyPageZstd) extents = nullptr;
  L.stats.sections.clear();
  bool sceneSun = false;
  const std::vector<Blob> blobs = residentBlobs(in, R, L.pages, extents, sceneSun);
  const Sections S = placeSections(blobs, g.pageBytes, L);
  writeHeader(in, R, S, sceneSun, g, extents, L);
}

// Builds the page table of the assigned ranges R (CRCs need page contents: `emitPage` is called for
// every page) and the resident image (compressed: with every extent zero).
Layout layout(const CanopyWriteInput& in, const Ranges& R, const PageGeometry& g, const EmitPage& emitPage) {
  Layout L;
  buildPages(in, R, g, emitPage, L.pages);
  residentImage(in, R, g, nullptr, L);
  return L;
}

// (5.0) Compresses the pages given in index order, a batch at a time on all cores (each page on its
// own, so the bytes do not depend on the threads), and hands their stored bytes on in order:
// write(bytes, n). The extents of the pages so far, their offsets from the first page's start.
class PageCompressor {
 public:
  PageCompressor(uint32_t pageBytes, int level, std::function<void(const unsigned char*, size_t)> write)
      : pageBytes_(pageBytes), level_(level), write_(std::move(write)) {}
  void add(const std::vector<unsigned char>& img) {
    images_.push_back(img);
    if (images_.size() == kBatch) flush();
  }
  void flush() {
    std::vector<std::vector<unsigned char>> stored(images_.size());
    std::vector<uint32_t> filter(images_.size());
    parallelFor(
        int64_t(images_.size()),
        [&](int64_t i) { filter[size_t(i)] = canopyPageEncode(images_[size_t(i)].data(), pageBytes_, level_, stored[size_t(i)]); }, 1);
    for (size_t i = 0; i < images_.size(); ++i) {
      if (stored[i].empty()) throw runtimeError("canopy writer: Zstandard could not compress a page");
      extents.push_back(CanopyPageExtent{at_, uint32_t(stored[i].size()), filter[i], crc32(0, stored[i].data(), stored[i].size()), 0u});
      at_ += stored[i].size();
      write_(stored[i].data(), stored[i].size());
    }
    images_.clear();
  }
  std::vector<CanopyPageExtent> extents;

 private:
  static constexpr size_t kBatch = 256;  // 16 MiB of page images
  uint32_t pageBytes_;
  int level_;
  uint64_t at_ = 0;
  std::function<void(const unsigned char*, size_t)> write_;
  std::vector<std::vector<unsigned char>> images_;
};

void checkCoding(const CanopyWriteInput& in) {
  if (in.pageCoding != kCanopyPageRaw && in.pageCoding != kCanopyPageZstd) throw invalidInput("canopy writer: unknown page coding");
  if (in.pageCoding == kCanopyPageZstd && (in.zstdLevel < 1 || in.zstdLevel > 19))
    throw invalidInput("canopy writer: the Zstandard level must be 1..19");
}

// Builds the pages and hands them on in index order, compressed (5.0) or not, to write(bytes, n),
// the first to lie at the end of the resident part. Returns the layout, its resident image with the
// compressed pages' extents (the resident part has the same size with every extent zero, which is
// how layout() first lays it out: that size is where the pages begin).
Layout writePages(const CanopyWriteInput& in, const Ranges& R, const PageGeometry& g,
                  const std::function<void(const unsigned char*, size_t)>& write) {
  const bool zstd = in.pageCoding == kCanopyPageZstd;
  PageCompressor packer(g.pageBytes, in.zstdLevel, write);
  Layout L = layout(in, R, g, [&](uint32_t, std::vector<unsigned char>& img) {
    if (zstd)
      packer.add(img);
    else
      write(img.data(), img.size());
  });
  if (zstd) {
    packer.flush();
    for (CanopyPageExtent& e : packer.extents) e.offset += L.resident.size();
    residentImage(in, R, g, &packer.extents, L);
  }
  return L;
}

}  // namespace

CanopyWriteStats writeCanopyFile(const std::string& path, CanopyWriteInput input) {
  checkCoding(input);
  AtomicOutput out(path);
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(out.tempPath().c_str(), "wb"), &std::fclose);
  if (!f) throw ioError(path + ": cannot write output");
  // The resident part holds the page table (page CRCs), so it is known only after every page has
  // been built. Pass 1 lays out without output (resident image); pass 2 streams the pages to their
  // offsets; both passes must agree. The ranges (and the sparse items they hold) are assigned once.
  // Compressed pages (5.0): the extents are known only once every page is compressed, so the
  // resident part is written again last, with them.
  const PageGeometry g;
  const Ranges R = assignModelRanges(input, g);
  const Layout probe = layout(input, R, g, nullptr);
  const uint64_t pagesOffset = probe.resident.size();
  bool ok = std::fwrite(probe.resident.data(), 1, probe.resident.size(), f.get()) == probe.resident.size();
  if (ok && std::fseek(f.get(), long(pagesOffset), SEEK_SET) != 0) ok = false;
  const auto write = [&](const unsigned char* p, size_t n) {
    if (ok) ok = std::fwrite(p, 1, n, f.get()) == n;
  };
  const Layout L = writePages(input, R, g, write);
  // deterministic layout: both passes agree (compressed: but for the extents, in a section of the
  // same size; the page tables, which hold every page's CRC, agree)
  if (input.pageCoding == kCanopyPageZstd) {
    if (L.resident.size() != pagesOffset || L.pages.size() != probe.pages.size() ||
        std::memcmp(L.pages.data(), probe.pages.data(), L.pages.size() * sizeof(CanopyPageEntry)) != 0)
      ok = false;
    if (ok && std::fseek(f.get(), 0, SEEK_SET) != 0) ok = false;
    write(L.resident.data(), L.resident.size());
  } else if (L.resident != probe.resident) {
    ok = false;
  }
  if (std::fclose(f.release()) != 0) ok = false;
  if (!ok) throw ioError(path + ": write failed (disk full?)");
  out.commit();
  return L.stats;
}

std::vector<unsigned char> writeCanopyBytes(CanopyWriteInput input, CanopyWriteStats* stats) {
  checkCoding(input);
  const PageGeometry g;
  std::vector<unsigned char> pageArea;
  Layout L = writePages(input, assignModelRanges(input, g), g,
                        [&](const unsigned char* p, size_t n) { pageArea.insert(pageArea.end(), p, p + n); });
  std::vector<unsigned char> bytes = std::move(L.resident);
  bytes.insert(bytes.end(), pageArea.begin(), pageArea.end());
  if (stats) *stats = L.stats;
  return bytes;
}

}  // namespace canopy
