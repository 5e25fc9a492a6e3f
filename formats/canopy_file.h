// canopy_file.h: the host reader of the packed, streamable scene file (`.canopy`): open, validate
// and read pages (formats/canopy_file.cpp; no OpenVDB), the page checks of `canopy-octreepack
// verify`, and host-side matrix helpers. The layers below it:
//   canopy_layout.h   the byte layout: constants, resident structures, addressing
//   canopy_sample.h   per-sample functions on page images (host and device)
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "formats/canopy_layout.h"
#include "formats/canopy_sample.h"

namespace canopy {

// Checks the structure of a Haar page's payload (host): item offsets increasing, 4-aligned and inside
// the payload, every item's records consistent with its coefficient count (the running sum of the
// masks' popcounts, as in a .chaar), every coefficient finite. Returns "" or the first problem.
std::string canopyCheckHaarPage(const void* page, uint32_t pageBytes, bool fp16);
// The same for a sparse brick page (2.0): offsets, every item's prefix counts against its mask, its
// size against its voxel count, its empty cells against its voxels, stored densities positive and
// finite; uniform items (3.0) only where `uniform` allows them, and only with a stored voxel.
std::string canopyCheckSparsePage(const void* page, uint32_t pageBytes, bool uniform);
// A section kind's name in reports (`info`, the writer's stats): "node_tiles", ...; "unknown" for a
// kind this reader does not know.
const char* canopySectionLabel(uint32_t kind);

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
  // (5.0) Where page i's stored bytes lie (compressed pages: header().pageCoding == kCanopyPageZstd).
  const std::vector<CanopyPageExtent>& pageExtents() const { return extents_; }
  // The bytes the pages take in the file (pageCount x pageBytes, or their stored bytes), and page i's.
  uint64_t storedPageBytes() const { return header_.fileBytes - header_.pagesOffset; }
  uint64_t storedBytes(uint32_t i) const { return extents_.empty() ? header_.pageBytes : extents_[i].storedBytes; }
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

  // Reads page `index` into dst (pageBytes) with one pread (of its stored bytes, decompressed, in a
  // 5.0 file of compressed pages) and checks it against the page table and its CRC. Thread-safe (no
  // shared file offset).
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
  std::vector<CanopyPageExtent> extents_;  // (5.0) compressed pages only
};

// Page check for `canopy-octreepack verify`: reads and checks every page of an opened file (whose
// resident part CanopyFile::open already validated). Returns the problems found, one line each
// (empty = every page is good); never throws for a problem in a page's content.
std::vector<std::string> verifyCanopyPages(const CanopyFile& file);

// CRC-32 of a page image with its crc field read as 0.
uint32_t canopyPageCrc(const void* page, uint32_t pageBytes);

}  // namespace canopy
