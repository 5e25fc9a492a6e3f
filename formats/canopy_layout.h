// canopy_layout.h: the byte layout of the packed, streamable scene file (`.canopy`), version 5.0
// (writes the oldest version that holds a file's content, byte for byte; reads 1.0 to 5.0).
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
//                       PageExtents CanopyPageExtent[pageCount]      24 B each (5.0, compressed pages only)
//   pagesOffset       page 0, page 1, ...        pageBytes each (65536), pagesOffset % pageBytes == 0;
//                                                compressed (5.0): each page's stored bytes, back to back
//   fileBytes         end of file (== pagesOffset + pageCount * pageBytes, or + the stored bytes of
//                     every page when compressed; nothing may follow)
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
// brick) plus a one-voxel border (6^3 stored), each sample's RGB in one shared-exponent word
// (canopy/rgb9e5.h: 9-bit mantissas, error <= 1/512 of the sample's largest channel): uint32
// values[19][216], sample (x,y,z) at index x + 6 (y + 6 z), x = 0 and 5 the borders; 16416 B (4.0;
// before 4.0 IEEE float16 planes, half values[19][3][216], 24624 B, which a reader converts when it
// loads the page: canopyPreparePage). Light page p of a model holds items [p * lightItemsPerPage,
// ...) (3 per page; 2 before 4.0). Light levels are the Haar averages (box filter):
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
// for a file with a detail model, and 1.x (as before, byte for byte) otherwise. 3.0 added uniform
// sparse bricks (one density for all the stored voxels of an item: bit 1023 of its mask, which a 2.0
// reader refuses as a voxel past the last); the writer writes 3.0 only for a file with such an item.
// 4.0 stores light items as shared-exponent RGB words (16416 B, 3 per 64 KiB page) instead of
// float16 planes (24624 B, 2 per page): a lit file is a third smaller in its light pages. The
// writer writes 4.0 for a file with light items; a file without any keeps its older version (and
// the header's 1.x-3.0 light item geometry) byte for byte.
//
// 5.0 adds compressed pages (KTX2's supercompression, per page): with header.pageCoding ==
// kCanopyPageZstd each page is stored as one Zstandard frame of its image, after a byte-plane
// filter (CanopyPageExtent::filter: 0 none; 2 or 4: the image's 2- or 4-byte words split into
// planes, plane b holding byte b of every word, plane after plane; the writer picks the one whose
// frame is smallest at level 1), pages back to back from pagesOffset in index order, found through the PageExtents
// section with the CRC of its stored bytes. A page decompresses to exactly pageBytes, and its header
// and CRC are those of the page image, checked as before; streaming reads a page's stored bytes alone. The writer writes 5.0 only
// for a compressed file (canopy-octreepack's default: a lit detail plant takes half the bytes); a
// file of raw pages keeps its older version byte for byte.
//
// This header holds the layout alone: constants, the resident structures and the arithmetic that
// finds a brick, a light item or a level in them. canopy_sample.h samples page images (host and
// device); canopy_file.h is the host reader that validates a file (formats/canopy_file.cpp).
#pragma once
#include <cstdint>

#include "canopy/hd.h"

namespace canopy {

// ------------------------------------------------------------------------------------------------
// Constants
// ------------------------------------------------------------------------------------------------
constexpr char kCanopyMagic[8] = {'C', 'A', 'N', 'O', 'P', 'Y', 'P', 'K'};
// 2.0: detail levels (a model's levels finer than its light lattice); 3.0: uniform sparse bricks;
// 4.0: shared-exponent light items; 5.0: compressed pages
constexpr uint16_t kCanopyMajor = 5;
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
constexpr uint32_t kCanopyLightItemBytes = kCanopyLightBases * kCanopyLightVoxelCount * 4;  // 16416: uint32 [19][216]
constexpr uint32_t kCanopyLightItemBytesHalf = kCanopyLightChannels * kCanopyLightVoxelCount * 2;  // 24624: before 4.0
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
  uint32_t lightItemBytes;         //  80  bytes per light item (16416; 24624 before 4.0)
  uint32_t lightItemsPerPage;      //  84  floor((pageBytes - 32) / lightItemBytes) = 3 (2 before 4.0)
  uint32_t pageCoding;             //  88  kCanopyPageRaw, or (5.0) kCanopyPageZstd; 0 before 5.0
  uint8_t reserved[32];            //  92  zero
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
  // (5.0; exactly when header.pageCoding == kCanopyPageZstd) CanopyPageExtent[pageCount]: where
  // each page's stored bytes lie.
  PageExtents = 10,
};

// How pages are stored (header.pageCoding).
constexpr uint32_t kCanopyPageRaw = 0;   // page images, pageBytes each
constexpr uint32_t kCanopyPageZstd = 1;  // (5.0) one Zstandard frame per page, after its filter

// (5.0) Where page i's stored bytes lie: offset == pagesOffset + the stored bytes of pages 0..i-1.
struct CanopyPageExtent {          // offset
  uint64_t offset;                 //   0  from the start of the file
  uint32_t storedBytes;            //   8  the Zstandard frame's size
  uint32_t filter;                 //  12  0, 2 or 4: the byte planes of the image's 2- or 4-byte words
  uint32_t storedCrc;              //  16  CRC-32 of the stored bytes (checked before they are decoded)
  uint32_t reserved;               //  20  zero
};
static_assert(sizeof(CanopyPageExtent) == 24, "CanopyPageExtent layout");

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
  kCanopyModelHasLight = 1u,   // light items, one per brick
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

// ---- Sparse bricks (2.0: a detail model's detail levels) ---------------------------------------
// The same 10^3 voxels as a brick (interior and border, index canopyVoxelIndex), with only the
// voxels of non-zero density stored. Item: uint32 mask[32] (bit v of word v / 32: voxel v has
// density > 0; bits 1000..1022 zero; bit 1023 the uniform flag, 3.0, below), uint16 prefix[32]
// (set bits in the words before), uint32 empty[16] (the brick's empty-cell mask, bit i of word
// i / 32: cell i as in canopyBrickEmptyCells, which the reader checks against the voxels), then
// float density[n] and uint32 material[n] of the n set voxels in index order: 256 + 8 n bytes.
// Uniform items (3.0): where bit 1023 is set, every stored voxel has the one density that follows
// the head (n >= 1), then material[n]: 256 + 4 + 4 n bytes. The writer flags an item whose n >= 2
// stored densities are all equal; in a detail lattice of canopy-voxelize --detail at k >= 8 (one
// sub-cell per detail cell) every occupied cell has density 1, so nearly all of such a model's
// finest bricks are uniform.
// A sample reads the same voxel values as the dense brick would (canopySampleVoxels), so a
// sparse brick samples bit for bit like its dense form.
constexpr uint32_t kCanopySparseMaskWords = 32;
constexpr uint32_t kCanopySparseEmptyWords = 16;  // 512 empty-cell bits
constexpr uint32_t kCanopySparseHeadBytes = kCanopySparseMaskWords * 4 + kCanopySparseMaskWords * 2 + kCanopySparseEmptyWords * 4;  // 256
constexpr uint32_t kCanopySparseItemBits = 12;  // location = page << 12 | item
constexpr uint32_t kCanopySparseMaxItemsPerPage = 1u << kCanopySparseItemBits;
constexpr uint32_t kCanopySparseUniform = 1u << 31;  // in mask[31]: bit 1023, past the last voxel (999)
constexpr uint32_t kCanopySparseLastVoxels = (1u << (kCanopyBrickVoxelCount % 32)) - 1u;  // mask[31]'s voxel bits
static_assert(kCanopyBrickVoxelCount > 31 * 32 && kCanopyBrickVoxelCount % 32 < 31, "the uniform flag lies past the last voxel");
CANOPY_HD CANOPY_FORCEINLINE uint32_t canopySparseItemBytes(uint32_t voxels, bool uniform = false) {
  return kCanopySparseHeadBytes + 4u * (uniform ? 1u : voxels) + 4u * voxels;
}

// ------------------------------------------------------------------------------------------------
// Addressing: where a brick, a level or a light item of a model is
// ------------------------------------------------------------------------------------------------
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

}  // namespace canopy
