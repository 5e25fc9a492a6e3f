// canopy_file.h: the packed, streamable scene file (`.canopy`), version 1.2 (reads 1.0 and 1.1 too).
//
// A .canopy file holds plant models (each a sparse GigaVoxels-style octree of bricks, thesis ch. 5),
// instances of those models (model id + transform) and an optional coarse scene lighting lattice.
// It is split into a small RESIDENT part that a player reads once at start-up and fixed-size,
// aligned PAGES that it streams on demand; every page can be read and verified on its own.
//
// Byte layout (little-endian; every offset is from the start of the file):
//
//   0                 CanopyFileHeader           128 B   magic "CANOPYPK", major.minor, sizes, CRCs
//   128               CanopySection[n]           32 B each: kind, offset, bytes, item size/count, CRC
//   (64-aligned)      sections (written in this order; found through the table), each on a
//                     64-byte boundary, zero padding between them:
//                       Models      CanopyModel[modelCount]         512 B each
//                       Instances   CanopyInstance[instanceCount]    64 B each
//                       NodeTiles   CanopyNode[8 * tiles]            16 B each (2x2x2 tiles)
//                       PageTable   CanopyPageEntry[pageCount]       32 B each
//                       SceneLight  CanopySceneLight + float[dim]    (optional)
//                       SceneSunLight  float[18][dim]  (1.2, optional: the scene lattice's sun bases)
//                       Metadata    UTF-8 JSON: tool version, inputs and their hashes (optional)
//                       HaarIndex   uint32[]: Haar-lit models' group tables + brick locations (1.1)
//   pagesOffset       page 0, page 1, ...        pageBytes each (65536), pagesOffset % pageBytes == 0
//   fileBytes         end of file (== pagesOffset + pageCount * pageBytes; nothing may follow)
//
//   resident part = [0, pagesOffset): header, section table, every section. All node tiles are
//   resident (16 B per node; the whole resident part measured 0.1-0.7% of a file); bricks and
//   light live in pages.
//
// Octree of one model (thesis §5.1): the root covers lattice cells [octreeOrigin, octreeOrigin +
// rootCells) on each axis, rootCells = brickSize * 2^depth; level 0 is the root, level `depth` the
// finest, where one brick voxel is one lattice cell. A node at level d covers rootCells / 2^d
// cells and holds a brick of brickSize^3 voxels (each rootCells / (brickSize 2^d) cells wide), or a
// constant value (empty = density 0). Every level is a pre-filtered MIP of the level below: a voxel
// is the box filter (mean) of the 2x2x2 voxels below it; density is averaged, wood and albedo are
// density-weighted means (0 where the density is 0). A node that is not constant at level < depth
// points to a tile of 8 children; child c = x + 2y + 4z (x, y, z in {0,1} = upper half on that
// axis). Constant nodes are terminal (the whole subtree is that constant).
//
// Bricks: brickSize = 8 voxels per axis plus a one-voxel border on every side (10^3 stored), as
// GigaVoxels' default (node-centred voxels, §5.1.4): the border holds the neighbouring voxels of the
// same level (0 outside the lattice), so a trilinear sample anywhere inside the node reads one brick
// only. 8^3 keeps the border overhead at 95% (4^3 would be 240%) and the tree shallow. A brick is
// stored as float density[1000] then uint32 material[1000] (8000 B; voxel (x,y,z) at index
// x + 10 (y + 10 z), x = 0 and 9 the borders). material = r | g << 8 | b << 16 | wood << 24, each an
// unsigned normalised 8-bit value of linear albedo / wood fraction, rounded to nearest: albedo and
// wood round-trip within 0.5/255; density is stored exactly (float32).
//
// Pages: a CanopyPageHeader (32 B) then the payload, zero padded to pageBytes. Brick pages hold
// bricksPerPage (8) consecutive bricks of one model: brick b of model m is in page
// model.firstBrickPage + b / bricksPerPage at payload offset (b % bricksPerPage) * brickBytes.
// Brick ids are assigned level by level, coarse to fine (siblings adjacent), so a model's first
// pages hold its coarse levels. The page CRC covers the whole page with the crc field read as 0; the
// page table repeats each page's header fields and CRC so a reader can check a page it just read.
//
// Light pages (kind Light) carry the model's pre-filtered LB lighting, one light item per brick
// (light item b belongs to brick b; model.lightCount is 0 or brickCount). A light item holds the 19
// base solutions (B00 ambient, B01..B18) x RGB on a 4^3 grid over its node (each light voxel two
// brick voxels wide: lighting is smooth, and half resolution makes an item 3x, not 24x, a density
// brick) plus a one-voxel border (6^3 stored), as IEEE float16: half values[19][3][216], sample
// (x,y,z) at index x + 6 (y + 6 z), x = 0 and 5 the borders; 24624 B. Light page p of a model holds
// items [p * lightItemsPerPage, ...) (2 per page). Light levels are the Haar averages (box filter):
// the finest light grid (2 cells per voxel) is the mean of the source lighting over its 2x2x2
// lattice cells; each coarser grid is the mean of the 2x2x2 voxels below it that lie in occupied
// blocks. Border voxels come from the neighbouring block of the same level, or repeat the edge voxel
// where that block is empty. A constant node has no light item: use its nearest brick ancestor's.
// A model without lighting (density only) has no light pages; the player then shows direct and
// ambient light.
//
// Haar light pages (kind HaarLight, 1.1; models flagged kCanopyModelHaarLight, packed from a
// .chaar): besides its light items (one per brick, as above), the model carries the .chaar's own
// compressed bricks (formats/chaar.h: 3^3 cells + a forward border, 19 records of a 64-bit mask and
// a first-coefficient index, the kept coefficients), re-paged unchanged, so a sample of them equals
// haar::chaarSample bit for bit: the finest level's exact light at the .chaar's threshold, for a
// player that asks for it (canopy-play --light exact; the items are the fast path). The chaar
// bricks are grouped 4^3 per group; items are stored group by group (groups in x-fastest order,
// bricks in a group x-fastest) and pages are filled greedily with whole items. Payload of a Haar
// page with n items:
//   uint32 offset[n + 1]   byte offset of item i from the payload start (offset[0] = 4 (n + 1),
//                          increasing, multiples of 4; offset[n] = payloadBytes)
//   item i                 BrickRecord rec[19] (12 B each: mask lo, mask hi, first | raw << 31;
//                          `first` counts coefficient entries from the item's own first entry),
//                          then the item's coefficient entries (RGB, float32 or float16 after
//                          model.haarPrecision), zero padded to 4 bytes.
// HaarIndex entries of a model (from model.firstHaarIndex): groupDims x*y*z entries (x fastest),
// each the group's block number b or kCanopyNone, then 64 entries per block b (brick x + 4y + 16z
// in the group): the brick's location (Haar page within the model's Haar pages << 12 | item), or
// kCanopyNone (no light in any base there). canopyHaarLocate / canopyHaarSampleAt sample it.
//
// Checksums: CRC-32 (zlib polynomial, canopy::crc32) of the header bytes [0, 124), of the section
// table, of every section, and of every page. A reader rejects bad magic, a newer major version,
// truncation, trailing bytes, any CRC mismatch and any pointer out of range (canopy::Error).
//
// Versioning: major changes on any layout change (a reader refuses a newer major); minor adds
// optional sections/page kinds that older readers may ignore. 1.1 added Haar light (the HaarIndex
// section, HaarLight pages, model fields in 1.0's reserved bytes); the writer writes 1.0 when no
// model has Haar light, so such files are byte-identical to 1.0 ones. 1.2 added the scene lattice's
// sun bases (the SceneSunLight section, beside SceneLight's B00, which keeps its 1.0 layout): a 1.1
// reader skips the unknown section and lights the scene with B00 alone, as before; the writer
// writes 1.2 only for a file with that section. 2.0 added detail levels (CanopyModel.detailLevels):
// octree levels finer than the model's light lattice, whose bricks have no light items (their light
// is their light-level ancestor's); a 1.x reader could not play them, so the writer writes 2.0 only
// for a file with a detail model, and 1.x (as before, byte for byte) otherwise.
#pragma once
#include <math.h>
#include <string.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "canopy/half.h"
#include "canopy/hd.h"
#include "formats/haar_view.h"

namespace canopy {

// ------------------------------------------------------------------------------------------------
// Constants
// ------------------------------------------------------------------------------------------------
constexpr char kCanopyMagic[8] = {'C', 'A', 'N', 'O', 'P', 'Y', 'P', 'K'};
constexpr uint16_t kCanopyMajor = 2;  // 2.0: detail levels (a model's levels finer than its light lattice)
constexpr uint16_t kCanopyMinor = 0;
// The 1.x minors this reader knows: 1.1: Haar light pages (optional; a 1.0 reader skips them),
// kCanopyModelScatteredSun; 1.2: the scene lattice's sun bases (SceneSunLight; a 1.1 reader skips it)
constexpr uint16_t kCanopyMinor1 = 2;
constexpr uint32_t kCanopyPageBytes = 65536;   // page size written (readers accept powers of two >= 32 KiB)
constexpr uint32_t kCanopySectionAlign = 64;   // every section starts on a 64-byte boundary
constexpr uint32_t kCanopyBrickSize = 8;       // interior voxels per axis
constexpr uint32_t kCanopyBrickBorder = 1;     // border voxels on every side
constexpr uint32_t kCanopyBrickVoxels = kCanopyBrickSize + 2 * kCanopyBrickBorder;  // 10 per axis
constexpr uint32_t kCanopyBrickVoxelCount = kCanopyBrickVoxels * kCanopyBrickVoxels * kCanopyBrickVoxels;
constexpr uint32_t kCanopyBrickBytes = kCanopyBrickVoxelCount * 8;  // float + uint32 per voxel
constexpr uint32_t kCanopyLightBases = 19;     // B00 (ambient) .. B18
constexpr uint32_t kCanopyLightSize = 4;       // interior light voxels per axis (2 brick voxels each)
constexpr uint32_t kCanopyLightVoxels = kCanopyLightSize + 2;  // 6 with the border
constexpr uint32_t kCanopyLightVoxelCount = kCanopyLightVoxels * kCanopyLightVoxels * kCanopyLightVoxels;
constexpr uint32_t kCanopyLightChannels = kCanopyLightBases * 3;  // 57 planes per item
constexpr uint32_t kCanopyLightItemBytes = kCanopyLightChannels * kCanopyLightVoxelCount * 2;  // 24624
constexpr uint32_t kCanopyMaxDepth = 15;       // levels 0..15: up to 8 * 2^15 cells per axis
constexpr uint32_t kCanopyNone = 0xFFFFFFFFu;  // "no child tile" / "no brick"

// ------------------------------------------------------------------------------------------------
// Resident structures
// ------------------------------------------------------------------------------------------------
struct CanopyFileHeader {          // offset
  char magic[8];                   //   0  "CANOPYPK"
  uint16_t major;                  //   8  kCanopyMajor
  uint16_t minor;                  //  10  kCanopyMinor
  uint32_t headerBytes;            //  12  sizeof(CanopyFileHeader) = 128
  uint64_t fileBytes;              //  16  total file size
  uint64_t residentBytes;          //  24  == pagesOffset: bytes a player reads at start-up
  uint64_t pagesOffset;            //  32  offset of page 0 (multiple of pageBytes)
  uint32_t pageBytes;              //  40  kCanopyPageBytes
  uint32_t pageCount;              //  44
  uint32_t sectionCount;           //  48  entries in the section table at offset 128
  uint32_t sectionTableCrc;        //  52  CRC-32 of the section table
  uint32_t modelCount;             //  56
  uint32_t instanceCount;          //  60
  uint32_t brickVoxels;            //  64  stored voxels per brick axis (10)
  uint32_t brickBytes;             //  68  bytes per brick (8000)
  uint32_t bricksPerPage;          //  72  floor((pageBytes - 32) / brickBytes) = 8
  uint32_t flags;                  //  76  0 in 1.0
  uint32_t lightItemBytes;         //  80  bytes per light item (24624)
  uint32_t lightItemsPerPage;      //  84  floor((pageBytes - 32) / lightItemBytes) = 2
  uint8_t reserved[36];            //  88  zero
  uint32_t headerCrc;              // 124  CRC-32 of bytes [0, 124)
};
static_assert(sizeof(CanopyFileHeader) == 128, "CanopyFileHeader layout");

enum class CanopySectionKind : uint32_t {
  Models = 1,      // CanopyModel[modelCount]
  Instances = 2,   // CanopyInstance[instanceCount]
  NodeTiles = 3,   // CanopyNode[8 * tiles], every model's tiles, model.firstTile onwards
  PageTable = 4,   // CanopyPageEntry[pageCount]
  SceneLight = 5,  // CanopySceneLight then float values[dim.x * dim.y * dim.z] (optional)
  Metadata = 6,    // UTF-8 JSON (optional)
  HaarIndex = 7,   // uint32[]: every Haar-lit model's group table and brick locations (1.1; optional)
  // (1.2; optional, only with SceneLight) the scene lattice's sun bases B01..B18: 18 items (one per
  // base, in order), each float values[dim.x * dim.y * dim.z] on SceneLight's lattice (x fastest),
  // itemBytes = 4 * dim.x * dim.y * dim.z. Finite and >= 0 (1 = unoccluded), like SceneLight's B00.
  SceneSunLight = 8,
  // (2.0; with detail models) uint32[]: every detail model's sparse brick locations, from
  // model.firstSparseIndex: entry i is detail brick (denseBricks + i)'s location, its sparse page
  // within the model's sparse pages << 12 | its item in that page.
  SparseIndex = 9,
};

struct CanopySection {             // offset
  uint32_t kind;                   //   0  CanopySectionKind
  uint32_t itemBytes;              //   4  size of one item (0 for byte blobs)
  uint64_t offset;                 //   8  from the start of the file, multiple of 64
  uint64_t bytes;                  //  16  == itemBytes * itemCount for arrays
  uint32_t itemCount;              //  24
  uint32_t crc;                    //  28  CRC-32 of the section's bytes
};
static_assert(sizeof(CanopySection) == 32, "CanopySection layout");

// One octree node. Its kind follows from the fields:
//   brick != kCanopyNone      -> a brick (density and material below hold the brick's mean)
//   brick == kCanopyNone      -> constant: density and material hold the value (density 0: empty)
//   child != kCanopyNone      -> children in tile `child` (model-relative), nodes 8*child .. +7
struct CanopyNode {                // offset
  uint32_t child;                  //   0  model-relative child tile index, or kCanopyNone
  uint32_t brick;                  //   4  model-relative brick id, or kCanopyNone
  float density;                   //   8  constant density (or the brick's mean density)
  uint32_t material;               //  12  packed albedo rgb + wood (see canopyUnpackMaterial)
};
static_assert(sizeof(CanopyNode) == 16, "CanopyNode layout");

enum CanopyModelFlags : uint32_t {
  kCanopyModelHasLight = 1u,   // float16 light items, one per brick
  kCanopyModelHaarLight = 2u,  // also the .chaar's Haar bricks: the finest level's exact light (Haar pages, HaarIndex)
  // (1.1) The sun bases B01..B18 (items and Haar pages) hold only scattered light: canopy-lbsolve
  // removed their direct beam, which the player adds as its shadowed direct sun. Without it (1.0
  // files, or lbsolve --sun-bases total) the bases include the beam and the player counts it twice.
  kCanopyModelScatteredSun = 4u,
};

struct CanopyModel {               // offset
  double indexToModel[12];         //   0  3x4 row-major: model-space position of lattice index
                                   //      (i,j,k) (cell centre) = M * (i, j, k, 1); metres, +Y up
  char name[64];                   //  96  NUL-terminated label
  int32_t latticeMin[3];           // 160  inclusive lattice bounds of the source (§0 contract)
  int32_t latticeMax[3];           // 172
  int32_t octreeOrigin[3];         // 184  lattice index of the root's first cell (== latticeMin)
  uint32_t rootCells;              // 196  cells per axis under the root = brickSize << depth
  uint32_t depth;                  // 200  finest level (levels 0..depth)
  uint32_t brickSize;              // 204  8
  uint32_t brickBorder;            // 208  1
  uint32_t firstTile;              // 212  index of this model's tile 0 in NodeTiles (in tiles)
  uint32_t tileCount;              // 216
  uint32_t brickCount;             // 220
  uint32_t firstBrickPage;         // 224
  uint32_t brickPageCount;         // 228  == ceil(brickCount / bricksPerPage)
  uint32_t lightCount;             // 232  light items: 0 (density only) or brickCount
  uint32_t firstLightPage;         // 236
  uint32_t lightPageCount;         // 240
  uint32_t flags;                  // 244  CanopyModelFlags
  CanopyNode root;                 // 248  level-0 node
  uint32_t levelBricks[16];        // 264  bricks per level
  uint32_t levelTiles[16];         // 328  child tiles per level (tiles whose nodes are at level d)
  // Haar light of the finest level (flag kCanopyModelHaarLight, format 1.1; all zero otherwise):
  // the .chaar's bricks re-paged, see "Haar light pages" above.
  uint32_t haarPrecision;          // 392  coefficients: 0 float32, 1 float16 (haar::Precision)
  int32_t haarBrickDims[3];        // 396  chaar bricks per axis: ceil((latticeMax - latticeMin + 1) / 3)
  uint32_t haarGroupDims[3];       // 408  brick groups per axis: ceil(haarBrickDims / 4)
  uint32_t haarGroups;             // 420  groups holding at least one stored brick
  uint32_t haarItemCount;          // 424  stored chaar bricks (Haar items) over all Haar pages
  uint32_t firstHaarIndex;         // 428  this model's first entry in the HaarIndex section
  uint32_t haarIndexCount;         // 432  its entries: groupDims x*y*z + 64 * haarGroups
  uint32_t firstHaarPage;          // 436
  uint32_t haarPageCount;          // 440
  float haarThreshold;             // 444  the .chaar's threshold (informative; -1 under --max-error)
  // (2.0) Levels finer than the light lattice (0: the light lattice is the density lattice). With
  // n = detailLevels > 0 the density lattice is a detail lattice (canopy-voxelize --detail): light
  // cell c covers lattice cells [2^n c, 2^n c + 2^n) per axis, the light lattice is
  // [latticeMin >> n, latticeMax >> n], light items exist for the bricks of levels
  // 0..depth - n only (lightCount = their number: breadth-first ids make them the first ones),
  // a brick below takes the light of its level depth - n ancestor, and the Haar light's lattice is
  // the light lattice. Extinction (sigma per cell) is per light cell.
  uint32_t detailLevels;           // 448
  // (2.0) The detail levels' bricks (ids denseBricks..brickCount-1) are sparse bricks (the occupied
  // voxels of the 10^3 grid only, see "Sparse bricks"), in sparse pages; the brick pages hold the
  // bricks 0..denseBricks-1 (brickPageCount = ceil(denseBricks / bricksPerPage)). denseBricks =
  // brickCount - sparseBricks = the bricks of levels 0..depth - detailLevels; all zero without
  // detail levels.
  uint32_t sparseBricks;           // 452
  uint32_t firstSparsePage;        // 456
  uint32_t sparsePageCount;        // 460
  uint32_t firstSparseIndex;       // 464  this model's first entry in the SparseIndex section (sparseBricks entries)
  uint32_t reserved[11];           // 468  zero
};
static_assert(sizeof(CanopyModel) == 512, "CanopyModel layout");

struct CanopyInstance {            // offset
  float modelToWorld[12];          //   0  3x4 row-major, metres, +Y up
  uint32_t model;                  //  48  index into Models
  uint32_t flags;                  //  52  0
  uint32_t reserved[2];            //  56  zero
};
static_assert(sizeof(CanopyInstance) == 64, "CanopyInstance layout");

enum class CanopyPageKind : uint32_t { Brick = 1, Light = 2, HaarLight = 3, SparseBrick = 4 };

// Both the first 32 bytes of every page and (with magic replaced by the same fields) an entry of
// the resident page table.
struct CanopyPageHeader {          // offset
  char magic[4];                   //   0  "CPAG"
  uint32_t kind;                   //   4  CanopyPageKind
  uint32_t pageIndex;              //   8  this page's index (a misplaced page is detected)
  uint32_t model;                  //  12
  uint32_t firstItem;              //  16  first brick / light item id (model-relative) in the page
  uint32_t itemCount;              //  20  items in the page (1..bricksPerPage or lightItemsPerPage)
  uint32_t payloadBytes;           //  24  itemCount * brickBytes (or lightItemBytes)
  uint32_t crc;                    //  28  CRC-32 of the whole page with these 4 bytes read as 0
};
static_assert(sizeof(CanopyPageHeader) == 32, "CanopyPageHeader layout");
using CanopyPageEntry = CanopyPageHeader;  // the page table holds copies of every page header
constexpr char kCanopyPageMagic[4] = {'C', 'P', 'A', 'G'};

// Coarse scene lighting lattice (lbsolve --scene): a dense float grid of luminance factors in
// world space, followed by dim[0]*dim[1]*dim[2] floats, x fastest: B00, the ambient factor (1 =
// unoccluded sky). A 1.2 file may add the 18 sun bases B01..B18 of the same lattice in the
// SceneSunLight section (1 = unoccluded sun); without them B00 is the factor of all indirect light.
struct CanopySceneLight {          // offset
  double indexToWorld[12];         //   0  3x4 row-major
  int32_t min[3];                  //  96  lattice index of value 0
  int32_t dim[3];                  // 108  values per axis
  uint32_t reserved[2];            // 120  zero
};
constexpr uint32_t kCanopySceneSunBases = 18;  // SceneSunLight's items: B01..B18
static_assert(sizeof(CanopySceneLight) == 128, "CanopySceneLight layout");

// ------------------------------------------------------------------------------------------------
// Per-sample functions (CANOPY_HD: the player's CUDA kernels and its CPU reference share them).
// Coordinates: "octree unit space" u in [0,1)^3 covers the root; lattice index p (VDB index space,
// cell centres at integers) maps to u = (p - octreeOrigin + 0.5) / rootCells.
// ------------------------------------------------------------------------------------------------
struct CanopySample {
  float density;
  float wood;
  float albedo[3];
};

// The float with bits b (host and device alike: the same code runs in CPU tests and kernels).
CANOPY_HD CANOPY_FORCEINLINE float canopyFloatFromBits(uint32_t b) {
  float f;
  memcpy(&f, &b, sizeof f);
  return f;
}

// The low byte of v as a float in [0, 1]. The byte becomes a float through the mantissa of 2^23
// (exactly the value of float(v & 0xFF)): on the device the integer-to-float instruction runs on a
// slow pipe, and a trilinear brick sample converts 24 bytes (canopySampleBrick).
CANOPY_HD CANOPY_FORCEINLINE float canopyUnorm8(uint32_t v) {
  return (canopyFloatFromBits(0x4B000000u | (v & 0xFFu)) - 8388608.0f) * (1.0f / 255.0f);
}

CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyToUnorm8(float v) {
  v = v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v);
  return uint32_t(v * 255.0f + 0.5f);
}

CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyPackMaterial(float r, float g, float b, float wood) {
  return canopyToUnorm8(r) | canopyToUnorm8(g) << 8 | canopyToUnorm8(b) << 16 | canopyToUnorm8(wood) << 24;
}

// A constant node's (or one voxel's) value.
CANOPY_HD CANOPY_FORCEINLINE CanopySample canopyUnpack(float density, uint32_t material) {
  CanopySample s;
  s.density = density;
  s.albedo[0] = canopyUnorm8(material);
  s.albedo[1] = canopyUnorm8(material >> 8);
  s.albedo[2] = canopyUnorm8(material >> 16);
  s.wood = canopyUnorm8(material >> 24);
  return s;
}

// One brick's arrays inside a page payload (see canopyBrickInPage).
struct CanopyBrickView {
  const float* density;      // kCanopyBrickVoxelCount values
  const uint32_t* material;  // kCanopyBrickVoxelCount values
};

CANOPY_HD CANOPY_FORCEINLINE CanopyBrickView canopyBrickAt(const void* brickBytes) {
  CanopyBrickView v;
  v.density = static_cast<const float*>(brickBytes);
  v.material = reinterpret_cast<const uint32_t*>(static_cast<const unsigned char*>(brickBytes) +
                                                 kCanopyBrickVoxelCount * sizeof(float));
  return v;
}

// The brick `slot` (= brick id % bricksPerPage) of a page image (pageBytes long, header included).
CANOPY_HD CANOPY_FORCEINLINE CanopyBrickView canopyBrickInPage(const void* page, uint32_t slot) {
  return canopyBrickAt(static_cast<const unsigned char*>(page) + sizeof(CanopyPageHeader) +
                       size_t(slot) * kCanopyBrickBytes);
}

// Stored voxel (x,y,z) in [0,10)^3 (0 and 9 are the border).
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyVoxelIndex(uint32_t x, uint32_t y, uint32_t z) {
  return x + kCanopyBrickVoxels * (y + kCanopyBrickVoxels * z);
}

// Empty-cell masks: derived by the reader, not stored in the file. A brick's node is cut into
// kCanopyEmptyCells^3 cells; cell (jx, jy, jz) is the node-local box [j/n, (j+1)/n) on each axis
// (n = kCanopyEmptyCells, 8/n brick voxels wide), where a trilinear sample (canopySampleBrick)
// reads only stored voxels 8j/n .. 8(j+1)/n + 1 on each axis. Bit i = jx + n (jy + n jz) of the
// mask (word i / 64, bit i % 64) is set when all of those voxels have density 0, so the density is
// exactly 0 everywhere in the cell. A set bit is a proof; a clear one proves nothing (a page
// without masks reads as all clear).
constexpr uint32_t kCanopyEmptyCells = 8;  // 4: 1.08x slower forest orbit (docs/performance.md, 'Empty cells inside bricks')
constexpr uint32_t kCanopyEmptyWords = (kCanopyEmptyCells * kCanopyEmptyCells * kCanopyEmptyCells + 63) / 64;

inline void canopyBrickEmptyCells(CanopyBrickView b, uint64_t mask[kCanopyEmptyWords]) {
  constexpr uint32_t n = kCanopyEmptyCells, w = kCanopyBrickSize / n;
  for (uint32_t i = 0; i < kCanopyEmptyWords; ++i) mask[i] = 0;
  for (uint32_t jz = 0; jz < n; ++jz)
    for (uint32_t jy = 0; jy < n; ++jy)
      for (uint32_t jx = 0; jx < n; ++jx) {
        bool empty = true;
        for (uint32_t z = w * jz; empty && z < w * jz + w + 2; ++z)
          for (uint32_t y = w * jy; empty && y < w * jy + w + 2; ++y)
            for (uint32_t x = w * jx; empty && x < w * jx + w + 2; ++x) empty = b.density[canopyVoxelIndex(x, y, z)] == 0.0f;
        const uint32_t i = jx + n * (jy + n * jz);
        if (empty) mask[i / 64] |= 1ull << (i % 64);
      }
}

// Whether cell (x, y, z) of canopyBrickEmptyCells is empty, from a sparse brick's occupancy mask
// (n = 8: the cell's trilinear samples read stored voxels x..x+2, y..y+2, z..z+2).
static_assert(kCanopyEmptyCells == kCanopyBrickSize, "empty cells one voxel wide");
CANOPY_HD inline bool canopySparseCellEmpty(const uint32_t* occupancy, uint32_t x, uint32_t y, uint32_t z) {
  uint32_t any = 0;
  for (uint32_t dz = 0; dz < 3; ++dz)
    for (uint32_t dy = 0; dy < 3; ++dy)
      for (uint32_t dx = 0; dx < 3; ++dx) {
        const uint32_t v = canopyVoxelIndex(x + dx, y + dy, z + dz);
        any |= occupancy[v >> 5] >> (v & 31u);
      }
  return (any & 1u) == 0;
}

// Where a page image keeps its bricks' masks (kCanopyEmptyWords x 8 bytes per brick slot, after
// the last brick's payload, in the page's zero padding), or 0 when the padding cannot hold them.
inline uint32_t canopyBrickMaskOffset(uint32_t pageBytes, uint32_t bricksPerPage) {
  const uint64_t off = sizeof(CanopyPageHeader) + uint64_t(bricksPerPage) * kCanopyBrickBytes;
  return off + 8ull * kCanopyEmptyWords * bricksPerPage <= pageBytes ? uint32_t(off) : 0u;
}

// Fills a verified brick page image's masks (a reader does this after the checksum, so the image
// no longer matches the file's bytes there; nothing checks them again). Other kinds: unchanged.
inline void canopyFillBrickMasks(void* page, uint32_t pageBytes, uint32_t bricksPerPage) {
  CanopyPageHeader ph;
  std::memcpy(&ph, page, sizeof ph);
  const uint32_t off = canopyBrickMaskOffset(pageBytes, bricksPerPage);
  if (ph.kind != uint32_t(CanopyPageKind::Brick) || off == 0) return;
  unsigned char* masks = static_cast<unsigned char*>(page) + off;
  for (uint32_t i = 0; i < bricksPerPage; ++i) {
    uint64_t m[kCanopyEmptyWords] = {};
    if (i < ph.itemCount) canopyBrickEmptyCells(canopyBrickInPage(page, i), m);
    std::memcpy(masks + 8 * kCanopyEmptyWords * i, m, sizeof m);
  }
}

// ---- Sparse bricks (2.0: a detail model's detail levels) ---------------------------------------
// The same 10^3 voxels as a brick (interior and border, index canopyVoxelIndex), with only the
// voxels of non-zero density stored. Item: uint32 mask[32] (bit v of word v / 32: voxel v has
// density > 0; bits 1000..1023 zero), uint16 prefix[32] (set bits in the words before), uint32
// empty[16] (the brick's empty-cell mask, bit i of word i / 32: cell i as in canopyBrickEmptyCells,
// which the reader checks against the voxels), then float density[n] and uint32 material[n] of the
// n set voxels in index order. 256 + 8 n bytes.
// A sample reads the same voxel values as the dense brick would (canopySampleVoxels), so a
// sparse brick samples bit for bit like its dense form.
constexpr uint32_t kCanopySparseMaskWords = 32;
constexpr uint32_t kCanopySparseEmptyWords = 16;  // 512 empty-cell bits
constexpr uint32_t kCanopySparseHeadBytes = kCanopySparseMaskWords * 4 + kCanopySparseMaskWords * 2 + kCanopySparseEmptyWords * 4;  // 256
constexpr uint32_t kCanopySparseItemBits = 12;  // location = page << 12 | item
constexpr uint32_t kCanopySparseMaxItemsPerPage = 1u << kCanopySparseItemBits;
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopySparseItemBytes(uint32_t voxels) { return kCanopySparseHeadBytes + 8u * voxels; }

struct CanopySparseBrickView {
  const uint32_t* mask;
  const uint16_t* prefix;
  const uint32_t* empty;  // the empty-cell bits (canopyBrickEmptyCells' cells, 32 per word)
  const float* density;
  const uint32_t* material;
  // The stored voxel idx's values (0 and 0 where not stored).
  CANOPY_HD CANOPY_FORCEINLINE void load(uint32_t idx, float& d, uint32_t& m) const {
    const uint32_t w = mask[idx >> 5], bit = 1u << (idx & 31u);
    if (!(w & bit)) {
      d = 0.0f, m = 0u;
      return;
    }
    const uint32_t rank = uint32_t(prefix[idx >> 5]) + haar::popcount32(w & (bit - 1u));
    d = density[rank], m = material[rank];
  }
};

// Item `item` of a sparse page image: the payload starts with uint32 offset[itemCount + 1].
CANOPY_HD CANOPY_FORCEINLINE CanopySparseBrickView canopySparseBrickInPage(const void* page, uint32_t item) {
  const unsigned char* payload = static_cast<const unsigned char*>(page) + sizeof(CanopyPageHeader);
  const unsigned char* p = payload + reinterpret_cast<const uint32_t*>(payload)[item];
  CanopySparseBrickView v;
  v.mask = reinterpret_cast<const uint32_t*>(p);
  v.prefix = reinterpret_cast<const uint16_t*>(p + kCanopySparseMaskWords * 4);
  v.empty = reinterpret_cast<const uint32_t*>(p + kCanopySparseMaskWords * 6);
  const uint32_t n = uint32_t(v.prefix[kCanopySparseMaskWords - 1]) + haar::popcount32(v.mask[kCanopySparseMaskWords - 1]);
  v.density = reinterpret_cast<const float*>(p + kCanopySparseHeadBytes);
  v.material = reinterpret_cast<const uint32_t*>(p + kCanopySparseHeadBytes + 4u * n);
  return v;
}

// A dense brick's voxel loads, for canopySampleVoxels.
CANOPY_HD CANOPY_FORCEINLINE void canopyLoadVoxel(const CanopyBrickView& b, uint32_t idx, float& d, uint32_t& m) {
  d = b.density[idx], m = b.material[idx];
}
CANOPY_HD CANOPY_FORCEINLINE void canopyLoadVoxel(const CanopySparseBrickView& b, uint32_t idx, float& d, uint32_t& m) { b.load(idx, d, m); }

// Trilinear sample of a brick (either form) at node-local coordinates l in [0,1]^3 (0 = the node's
// lower corner). Density is interpolated; albedo and wood are density-weighted (the same weighting
// as the MIP), so empty voxels do not darken a leaf's colour. At the centre of an interior voxel the
// result is that voxel's stored value.
template <class Voxels>
CANOPY_HD inline CanopySample canopySampleVoxels(const Voxels& b, float lx, float ly, float lz) {
  const float l[3] = {lx, ly, lz};
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    // voxel centres at (i + 0.5) / 8 in node-local space map to stored index i + 1
    float t = l[a] * float(kCanopyBrickSize) + float(kCanopyBrickBorder) - 0.5f;
    const float hi = float(kCanopyBrickVoxels - 1) - 1e-6f;
    t = t < 0.0f ? 0.0f : (t > hi ? hi : t);
    const float fl = floorf(t);
    i0[a] = int(fl);
    f[a] = t - fl;
  }
  // The 16 loads first, unconditionally (every corner is inside the brick: i0 <= kCanopyBrickVoxels
  // - 2), so that the GPU has them all in flight at once; corners of weight 0 are then skipped
  // as before.
  float cd[8];
  uint32_t cm[8];
  for (int c = 0; c < 8; ++c) {
    const uint32_t idx = canopyVoxelIndex(uint32_t(i0[0] + (c & 1)), uint32_t(i0[1] + ((c >> 1) & 1)), uint32_t(i0[2] + ((c >> 2) & 1)));
    canopyLoadVoxel(b, idx, cd[c], cm[c]);
  }
  float dens = 0.0f, w = 0.0f, r = 0.0f, g = 0.0f, bl = 0.0f, wsum = 0.0f;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const float wt = (dx ? f[0] : 1.0f - f[0]) * (dy ? f[1] : 1.0f - f[1]) * (dz ? f[2] : 1.0f - f[2]);
    if (wt == 0.0f) continue;
    const float d = cd[c];
    const CanopySample m = canopyUnpack(d, cm[c]);
    dens += wt * d;
    const float wd = wt * d;
    wsum += wd;
    w += wd * m.wood;
    r += wd * m.albedo[0];
    g += wd * m.albedo[1];
    bl += wd * m.albedo[2];
  }
  CanopySample s;
  s.density = dens;
  const float inv = wsum > 0.0f ? 1.0f / wsum : 0.0f;
  s.wood = w * inv;
  s.albedo[0] = r * inv;
  s.albedo[1] = g * inv;
  s.albedo[2] = bl * inv;
  return s;
}
CANOPY_HD inline CanopySample canopySampleBrick(CanopyBrickView b, float lx, float ly, float lz) { return canopySampleVoxels(b, lx, ly, lz); }
CANOPY_HD inline CanopySample canopySampleBrick(const CanopySparseBrickView& b, float lx, float ly, float lz) {
  return canopySampleVoxels(b, lx, ly, lz);
}
// A brick of either form in a page image: slot (dense) or item (sparse).
CANOPY_HD inline CanopySample canopySampleBrickInPage(const void* page, uint32_t slot, bool sparse, float lx, float ly, float lz) {
  return sparse ? canopySampleBrick(canopySparseBrickInPage(page, slot), lx, ly, lz) : canopySampleBrick(canopyBrickInPage(page, slot), lx, ly, lz);
}

// The light item `slot` (= item id % lightItemsPerPage) of a light page image.
CANOPY_HD CANOPY_FORCEINLINE const uint16_t* canopyLightInPage(const void* page, uint32_t slot) {
  return reinterpret_cast<const uint16_t*>(static_cast<const unsigned char*>(page) + sizeof(CanopyPageHeader) +
                                           size_t(slot) * kCanopyLightItemBytes);
}

// The trilinear corners of node-local l in [0,1]^3 in a light item: voxel indices and weights,
// computed once for all the bases sampled at one point (the player samples four).
struct CanopyLightCorners {
  uint32_t offset[8];  // voxel index of corner c (x + 6 (y + 6 z)), c = dx + 2 dy + 4 dz
  float weight[8];     // its trilinear weight (0: the corner is skipped)
};

CANOPY_HD inline CanopyLightCorners canopyLightCorners(float lx, float ly, float lz) {
  const float l[3] = {lx, ly, lz};
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; ++a) {
    float t = l[a] * float(kCanopyLightSize) + 0.5f;  // light voxel centres (i + 0.5) / 4 -> index i + 1
    const float hi = float(kCanopyLightVoxels - 1) - 1e-6f;
    t = t < 0.0f ? 0.0f : (t > hi ? hi : t);
    const float fl = floorf(t);
    i0[a] = int(fl);
    f[a] = t - fl;
  }
  CanopyLightCorners k;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    k.weight[c] = (dx ? f[0] : 1.0f - f[0]) * (dy ? f[1] : 1.0f - f[1]) * (dz ? f[2] : 1.0f - f[2]);
    k.offset[c] = uint32_t((i0[0] + dx) + int(kCanopyLightVoxels) * ((i0[1] + dy) + int(kCanopyLightVoxels) * (i0[2] + dz)));
  }
  return k;
}

// Base `base` (0..18) of a light item at the corners k, RGB into rgb.
CANOPY_HD CANOPY_FORCEINLINE void canopySampleLightAt(const uint16_t* item, uint32_t base, const CanopyLightCorners& k,
                                                      float rgb[3]) {
  for (int ch = 0; ch < 3; ++ch) {
    const uint16_t* plane = item + size_t(base * 3 + uint32_t(ch)) * kCanopyLightVoxelCount;
    float v = 0.0f;
    for (int c = 0; c < 8; ++c) {
      if (k.weight[c] == 0.0f) continue;
      v += k.weight[c] * halfToFloat(plane[k.offset[c]]);
    }
    rgb[ch] = v;
  }
}

// Trilinear sample of base `base` (0..18) of a light item at node-local l in [0,1]^3, RGB into rgb.
CANOPY_HD inline void canopySampleLight(const uint16_t* item, uint32_t base, float lx, float ly, float lz, float rgb[3]) {
  canopySampleLightAt(item, base, canopyLightCorners(lx, ly, lz), rgb);
}

// float -> IEEE binary16 for light items: canopy::floatToHalf (round to nearest even, NaN stays
// NaN) with values beyond the half range clamped to +-65504 (lighting is never infinite). Readers
// decode with canopy::halfToFloat.
inline uint16_t canopyFloatToHalf(float f) { return floatToHalf(f > kHalfMax ? kHalfMax : (f < -kHalfMax ? -kHalfMax : f)); }

// One step down the octree: x (the point in the current node, [0,1)^3) becomes the point in the
// child that holds it, lo and size (the node's corner and edge in octree unit space) become the
// child's. Returns the child index c = x + 2y + 4z. Shared by canopyDescend and the player.
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyStepDown(float x[3], float lo[3], float& size) {
  uint32_t c = 0;
  size *= 0.5f;
  for (int a = 0; a < 3; ++a) {
    const float t = x[a] * 2.0f;
    const uint32_t off = t >= 1.0f ? 1u : 0u;
    x[a] = t - float(off);
    c |= off << a;
    lo[a] += float(off) * size;
  }
  return c;
}

// The result of descending the octree to a point.
struct CanopyLookup {
  CanopyNode node;       // the node reached
  CanopyNode parent;     // its parent (== node at the root), for quadrilinear LOD blending
  uint32_t level;        // level of `node`
  float local[3];        // the point in node-local coordinates [0,1)^3
  float nodeMin[3];      // node's lower corner in octree unit space
  float nodeSize;        // node's edge in octree unit space (2^-level)
};

// Descends from the root towards unit-space point u (clamped into [0,1)) until `maxLevel`, the
// finest level, or a terminal node (constant, or a brick without children). `tiles` are the
// model's node tiles (model-relative child indices); `tileCount` bounds them: a child index out of
// range stops the descent (a verified file never has one).
CANOPY_HD inline CanopyLookup canopyDescend(const CanopyNode* tiles, uint32_t tileCount, CanopyNode root,
                                            uint32_t depth, float ux, float uy, float uz,
                                            uint32_t maxLevel) {
  float x[3] = {ux, uy, uz};
  for (int a = 0; a < 3; ++a) x[a] = x[a] < 0.0f ? 0.0f : (x[a] >= 1.0f ? 0.99999994f : x[a]);
  CanopyLookup r;
  r.node = root;
  r.parent = root;
  r.level = 0;
  r.nodeSize = 1.0f;
  r.nodeMin[0] = r.nodeMin[1] = r.nodeMin[2] = 0.0f;
  if (maxLevel > depth) maxLevel = depth;
  while (r.level < maxLevel && r.node.child != kCanopyNone && r.node.child < tileCount) {
    const uint32_t c = canopyStepDown(x, r.nodeMin, r.nodeSize);
    r.parent = r.node;
    r.node = tiles[size_t(r.node.child) * 8 + c];
    ++r.level;
  }
  for (int a = 0; a < 3; ++a) r.local[a] = x[a];
  return r;
}

// Lattice index space -> octree unit space for one model (see the comment above).
CANOPY_HD CANOPY_FORCEINLINE void canopyLatticeToUnit(const int32_t origin[3], uint32_t rootCells,
                                                      float px, float py, float pz, float u[3]) {
  const float inv = 1.0f / float(rootCells);
  u[0] = (px - float(origin[0]) + 0.5f) * inv;
  u[1] = (py - float(origin[1]) + 0.5f) * inv;
  u[2] = (pz - float(origin[2]) + 0.5f) * inv;
}

// p' = M p for a 3x4 row-major affine matrix (instances: model -> world; canopyModelToUnit).
CANOPY_HD CANOPY_FORCEINLINE void canopyTransformPoint(const float m[12], const float p[3], float out[3]) {
  for (int r = 0; r < 3; ++r) out[r] = m[4 * r] * p[0] + m[4 * r + 1] * p[1] + m[4 * r + 2] * p[2] + m[4 * r + 3];
}
// d' = M d (directions: no translation).
CANOPY_HD CANOPY_FORCEINLINE void canopyTransformDirection(const float m[12], const float d[3], float out[3]) {
  for (int r = 0; r < 3; ++r) out[r] = m[4 * r] * d[0] + m[4 * r + 1] * d[1] + m[4 * r + 2] * d[2];
}

// Which page holds brick `brick` of a model, and the slot in it.
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyBrickPage(const CanopyModel& m, uint32_t brick, uint32_t bricksPerPage) {
  return m.firstBrickPage + brick / bricksPerPage;
}
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyBrickSlot(uint32_t brick, uint32_t bricksPerPage) {
  return brick % bricksPerPage;
}
// The finest level with light items: depth - detailLevels (canopyLightDepth <= depth).
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyLightDepth(const CanopyModel& m) { return m.depth - m.detailLevels; }
// The bricks of levels 0..canopyLightDepth(m): the ones with light items (in a lit model) and,
// in a detail model (2.0), the dense ones (the rest are sparse). Levels past 15 do not exist.
inline uint64_t canopyLightLevelBricks(const CanopyModel& m) {
  uint64_t n = 0;
  for (uint32_t l = 0; l <= canopyLightDepth(m) && l <= kCanopyMaxDepth; ++l) n += m.levelBricks[l];
  return n;
}
// Which page holds light item `item` (== the brick id) of a model (model.lightCount > 0).
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopyLightPage(const CanopyModel& m, uint32_t item, uint32_t lightItemsPerPage) {
  return m.firstLightPage + item / lightItemsPerPage;
}

// ---- Haar light (format 1.1, models flagged kCanopyModelHaarLight) -----------------------------
constexpr uint32_t kCanopyHaarGroupEdge = 4;                              // chaar bricks per group edge
constexpr uint32_t kCanopyHaarGroupBricks = 64;                           // 4^3 per group
constexpr uint32_t kCanopyHaarItemBits = 12;                              // location = page << 12 | item
constexpr uint32_t kCanopyHaarMaxItemsPerPage = 1u << kCanopyHaarItemBits;
constexpr uint32_t kCanopyHaarRecordBytes = kCanopyLightBases * 12;      // 19 BrickRecords = 228 B

// What a sampler needs of one Haar-lit model (resident): its HaarIndex entries and geometry.
struct CanopyHaarView {
  const uint32_t* index;  // the model's HaarIndex entries: group table, then 64 locations per group
  int32_t latticeMin[3];
  int32_t latticeMax[3];
  uint32_t groupDims[3];
  uint32_t firstPage;     // page index of the model's first Haar page
  uint32_t fp16;          // coefficients are float16 (else float32)
};

struct CanopyHaarLocation {
  uint32_t page;         // page holding the chaar brick, or kCanopyNone: no light there (every base 0)
  uint32_t item;         // item index in that page
  haar::BrickLookup at;  // the brick-local texel footprint and fractions (at.slot unused)
};

// Finds the chaar brick of lattice index point p (the rule of haar::chaarSample: p clamped to the
// lattice, brick floor(p - latticeMin) / 3) through the model's HaarIndex.
CANOPY_HD inline CanopyHaarLocation canopyHaarLocate(const CanopyHaarView& v, float px, float py, float pz) {
  int b[3];
  CanopyHaarLocation r;
  r.at = haar::locateInLattice(v.latticeMin, v.latticeMax, px, py, pz, b);
  r.page = kCanopyNone;
  r.item = 0;
  const uint32_t E = kCanopyHaarGroupEdge;
  const uint32_t g = (uint32_t(b[2]) / E * v.groupDims[1] + uint32_t(b[1]) / E) * v.groupDims[0] + uint32_t(b[0]) / E;
  const uint32_t block = v.index[g];
  if (block == kCanopyNone) return r;
  const uint32_t groups = v.groupDims[0] * v.groupDims[1] * v.groupDims[2];
  const uint32_t local = uint32_t(b[0]) % E + E * (uint32_t(b[1]) % E + E * (uint32_t(b[2]) % E));
  const uint32_t loc = v.index[groups + kCanopyHaarGroupBricks * block + local];
  if (loc == kCanopyNone) return r;
  r.page = v.firstPage + (loc >> kCanopyHaarItemBits);
  r.item = loc & (kCanopyHaarMaxItemsPerPage - 1u);
  return r;
}

// Item `item` of a Haar page image (pageBytes long, header included): its 19 records, then its
// coefficients.
CANOPY_HD CANOPY_FORCEINLINE const unsigned char* canopyHaarItemInPage(const void* page, uint32_t item) {
  const unsigned char* payload = static_cast<const unsigned char*>(page) + sizeof(CanopyPageHeader);
  return payload + reinterpret_cast<const uint32_t*>(payload)[item];
}

// A Haar item's coefficient entries in either precision (one instantiation of the sampler serves
// both: the branch is uniform per model).
struct CanopyHaarCoefReader {
  const unsigned char* p;
  uint32_t fp16;
  CANOPY_HD CANOPY_FORCEINLINE haar::Rgb operator()(uint64_t i) const {
    if (fp16) return haar::CoefReader16{reinterpret_cast<const uint16_t*>(p)}(i);
    return haar::CoefReader32{reinterpret_cast<const float*>(p)}(i);
  }
};

// Trilinear sample of base `base` of one Haar item at the footprint `at`: haar::sampleBrick on the
// item's record and coefficients, so it equals haar::chaarSample of the source .chaar bit for bit.
CANOPY_HD inline haar::Rgb canopyHaarSampleAt(const unsigned char* item, uint32_t fp16, uint32_t base, const haar::BrickLookup& at) {
  const haar::BrickRecord rec = reinterpret_cast<const haar::BrickRecord*>(item)[base];
  return haar::sampleBrick(rec, CanopyHaarCoefReader{item + kCanopyHaarRecordBytes, fp16}, at.lx, at.ly, at.lz, at.fx, at.fy, at.fz);
}

// Checks the structure of a Haar page's payload (host): item offsets increasing, 4-aligned and inside
// the payload, every item's records consistent with its coefficient count (the running sum of the
// masks' popcounts, as in a .chaar), every coefficient finite. Returns "" or the first problem.
std::string canopyCheckHaarPage(const void* page, uint32_t pageBytes, bool fp16);
// The same for a sparse brick page (2.0): offsets, every item's prefix counts against its mask, its
// size against its voxel count, stored densities positive and finite.
std::string canopyCheckSparsePage(const void* page, uint32_t pageBytes);

// Host-side matrix helpers (double precision, then rounded to float for the device).
// The inverse of a 3x4 affine matrix; false if it is singular.
bool canopyInvertAffine(const double m[12], double out[12]);
// Model space -> octree unit space of model M (inverse of indexToModel, then the unit mapping);
// false if indexToModel is singular.
bool canopyModelToUnit(const CanopyModel& M, float out[12]);
// World space -> octree unit space of an instance: canopyModelToUnit * inverse(modelToWorld).
bool canopyWorldToUnit(const CanopyModel& M, const CanopyInstance& inst, float out[12]);

// ------------------------------------------------------------------------------------------------
// Host reader (formats/canopy_file.cpp; no OpenVDB). Every failure throws canopy::Error naming the
// file: Io (missing, unreadable), InvalidInput (bad magic, truncated, CRC mismatch, pointer out of
// range), Unsupported (newer major version).
// ------------------------------------------------------------------------------------------------
class CanopyFile {
 public:
  // Reads and validates the resident part of `path` (header, section table and every section's CRC,
  // every node pointer and page-table entry in range); pages are read on demand with readPage().
  static CanopyFile open(const std::string& path);
  // The same from a whole file image in memory (tests, fuzzer); `name` labels errors. The image is
  // not copied: it must outlive the CanopyFile (readPage reads from it).
  static CanopyFile fromMemory(const void* data, size_t size, const std::string& name = "<memory>");

  CanopyFile(CanopyFile&&) noexcept;
  CanopyFile& operator=(CanopyFile&&) noexcept;
  ~CanopyFile();

  const std::string& path() const { return path_; }
  const CanopyFileHeader& header() const { return header_; }
  uint32_t sectionCount() const { return uint32_t(sections_.size()); }
  const CanopySection& section(uint32_t i) const { return sections_[i]; }
  const CanopySection* findSection(CanopySectionKind kind) const;

  uint32_t modelCount() const { return uint32_t(models_.size()); }
  const CanopyModel& model(uint32_t i) const { return models_[i]; }
  uint32_t instanceCount() const { return uint32_t(instances_.size()); }
  const CanopyInstance& instance(uint32_t i) const { return instances_[i]; }
  // A model's node tiles (8 nodes each, model-relative child indices).
  const CanopyNode* tiles(uint32_t model) const { return tiles_.data() + size_t(models_[model].firstTile) * 8; }
  const std::vector<CanopyNode>& allTiles() const { return tiles_; }
  uint32_t pageCount() const { return uint32_t(pages_.size()); }
  const CanopyPageEntry& pageEntry(uint32_t i) const { return pages_[i]; }
  bool hasSceneLight() const { return hasSceneLight_; }
  const CanopySceneLight& sceneLight() const { return sceneLight_; }
  // The scene lattice's bases: 1 (B00 only) or 19 (B00 and the SceneSunLight section's B01..B18);
  // 0 without a scene light.
  uint32_t sceneLightBases() const { return sceneLightBases_; }
  // Every base's values, base-major (B00's dim.x*dim.y*dim.z values first, then B01's, ...).
  const std::vector<float>& sceneLightValues() const { return sceneLightValues_; }
  const std::string& metadata() const { return metadata_; }
  // The HaarIndex section (every Haar-lit model's entries, from model.firstHaarIndex; empty if none).
  const std::vector<uint32_t>& haarIndex() const { return haarIndex_; }
  // The SparseIndex section (every detail model's sparse brick locations, from model.firstSparseIndex).
  const std::vector<uint32_t>& sparseIndex() const { return sparseIndex_; }
  // Where model m's brick b lies: its page, its slot (dense) or item (sparse) in it, and its form.
  struct BrickLocation {
    uint32_t page, slot;
    bool sparse;
  };
  BrickLocation brickLocation(uint32_t m, uint32_t brick) const;
  // Model m's Haar light view over haarIndex() (m must be flagged kCanopyModelHaarLight).
  CanopyHaarView haarView(uint32_t m) const;
  // The resident bytes [0, pagesOffset) as read (a player may upload NodeTiles from here).
  const std::vector<unsigned char>& resident() const { return resident_; }

  // Descends model `m` (CPU convenience over canopyDescend).
  CanopyLookup descend(uint32_t m, float ux, float uy, float uz, uint32_t maxLevel = kCanopyMaxDepth) const;

  // Reads page `index` into dst (pageBytes) with one pread and checks it against the page table and
  // its CRC. Thread-safe (no shared file offset).
  void readPage(uint32_t index, void* dst) const;
  std::vector<unsigned char> readPage(uint32_t index) const;

 private:
  CanopyFile() = default;
  void parseResident(uint64_t fileBytes);
  void readAt(uint64_t offset, void* dst, size_t bytes) const;

  std::string path_;
  int fd_ = -1;                          // file mode
  const unsigned char* memory_ = nullptr;  // memory mode (whole image, not owned)
  size_t memorySize_ = 0;
  std::vector<unsigned char> resident_;
  CanopyFileHeader header_{};
  std::vector<CanopySection> sections_;
  std::vector<CanopyModel> models_;
  std::vector<CanopyInstance> instances_;
  std::vector<CanopyNode> tiles_;
  std::vector<CanopyPageEntry> pages_;
  bool hasSceneLight_ = false;
  CanopySceneLight sceneLight_{};
  uint32_t sceneLightBases_ = 0;
  std::vector<float> sceneLightValues_;
  std::string metadata_;
  std::vector<uint32_t> haarIndex_;
  std::vector<uint32_t> sparseIndex_;
};

// Page check for `canopy-octreepack verify`: reads and checks every page of an opened file (whose
// resident part CanopyFile::open already validated). Returns the problems found, one line each
// (empty = every page is good); never throws for a problem in a page's content.
std::vector<std::string> verifyCanopyPages(const CanopyFile& file);

// CRC-32 of a page image with its crc field read as 0.
uint32_t canopyPageCrc(const void* page, uint32_t pageBytes);

}  // namespace canopy
