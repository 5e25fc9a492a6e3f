// canopy_write.h: writes a .canopy file (layout in canopy_layout.h) atomically and deterministically.
//
// The caller supplies built models (record + node tiles + brick bytes), instances, an optional
// scene lighting lattice and a metadata string; the writer assigns each model's firstTile and
// page ranges, lays out the resident sections, fills the pages with their headers and CRCs and
// writes everything through canopy::AtomicOutput (temporary file + rename). The same input gives
// the same bytes (all padding is zero, no timestamps).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "formats/canopy_file.h"

namespace canopy {

namespace haar {
struct ChaarData;
}

// A model's Haar light (format 1.1, canopy_layout.h "Haar light pages"): a .chaar's bricks re-paged.
struct CanopyHaarPages {
  uint32_t precision = 0;                  // haar::Precision of the coefficients
  int32_t brickDims[3] = {0, 0, 0};
  uint32_t groupDims[3] = {0, 0, 0};
  uint32_t groups = 0;                     // groups with a stored brick
  uint32_t items = 0;                      // stored bricks
  float threshold = 0.0f;
  std::vector<uint32_t> index;             // the model's HaarIndex entries
  std::vector<std::vector<unsigned char>> payloads;  // one per page: offsets then items
  std::vector<uint32_t> itemCounts;        // items per page
};

// Re-pages the 19 bases of a parsed .chaar (lattice = the model's, checked by the caller) into
// pages of `pageBytes`. Deterministic. Throws canopy::Error(InvalidInput) for a base count != 19.
CanopyHaarPages canopyHaarPagesFromChaar(const haar::ChaarData& chaar, uint32_t pageBytes = kCanopyPageBytes);

struct CanopyWriteModel {
  CanopyModel record{};                  // firstTile / firstBrickPage / ... are filled by the writer
  const std::vector<CanopyNode>* tiles = nullptr;      // 8 per tile
  const std::vector<unsigned char>* bricks = nullptr;  // record.brickCount * kCanopyBrickBytes
  const std::vector<uint32_t>* light = nullptr;        // null/empty (density only) or record.lightCount items
  // Optional Haar light (format 1.1: the finest level's exact light), for a lit model only.
  const CanopyHaarPages* haar = nullptr;
};

struct CanopyWriteInput {
  std::vector<CanopyWriteModel> models;
  std::vector<CanopyInstance> instances;
  bool hasSceneLight = false;
  CanopySceneLight sceneLight{};
  // 1: B00 only (the SceneLight section; a 1.0/1.1 file). 19: B00..B18, the sun bases B01..B18 in
  // the SceneSunLight section (a 1.2 file).
  uint32_t sceneLightBases = 1;
  std::vector<float> sceneLightValues;   // sceneLightBases x dim.x*dim.y*dim.z, base-major (B00 first)
  std::string metadata;                  // UTF-8 JSON; empty = no Metadata section
  // How pages are stored: kCanopyPageRaw (the oldest version that holds the content) or
  // kCanopyPageZstd (5.0: one Zstandard frame per page at zstdLevel, 1..19).
  uint32_t pageCoding = kCanopyPageRaw;
  int zstdLevel = 15;
};

struct CanopyWriteStats {
  uint64_t fileBytes = 0;
  uint64_t residentBytes = 0;
  uint32_t pageCount = 0;
  struct Section {
    std::string name;
    uint64_t bytes;
  };
  std::vector<Section> sections;         // resident sections, then "pages" (their stored bytes)
  uint64_t pageBytes = 0;                // the pages' images: pageCount x the page size
  uint32_t pageCoding = kCanopyPageRaw;  // as written
};

// Throws canopy::Error (Io for an unwritable path, InvalidInput for inconsistent input).
CanopyWriteStats writeCanopyFile(const std::string& path, CanopyWriteInput input);

// The same into memory (tests and the fuzzer's seed corpus).
std::vector<unsigned char> writeCanopyBytes(CanopyWriteInput input, CanopyWriteStats* stats = nullptr);

}  // namespace canopy
