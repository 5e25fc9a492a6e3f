// octreepack.h: canopy-octreepack's callable core (main.cpp only parses arguments).
//   octreepack():  density lattices (+ scene instances, + coarse scene lighting) -> one .canopy
//   canopyInfo():  the `info` report of a .canopy file (models, levels, counts, bytes per section)
//   canopyVerify(): the `verify` check (every CRC, every pointer); throws on the first class of
//                  problem with all problems listed in the report.
#pragma once
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "formats/canopy_file.h"

namespace canopy::octreepack {

struct OctreepackOptions {
  // One plant: PLANT.density.vdb [PLANT.light.chaar|.vdb]. With scene = SCENE.glb: the density
  // lattice of every mesh the scene uses (canopy-voxelize SCENE.glb --mesh N), in any order, each
  // followed by its optional lighting (.chaar or .light.vdb). Empty with scene = SCENE.json.
  std::vector<std::string> inputs;
  std::string scene;                 // SCENE.json (docs/scene-json.md) or SCENE.glb|.gltf
  std::string output;                // OUT.canopy
  std::string sceneLight;            // coarse scene lighting lattice (VDB), optional
  // Empty: the 19 bases B00..B18 of lbsolve --scene (the player weights the sun term by the sun's
  // bases, the ambient term by B00). A name: that one float grid, the factor of all indirect light.
  std::string sceneLightGrid;
  bool ignoreLight = false;          // pack density only even where a .chaar is named
  bool noHaarLight = false;          // a .chaar's bricks are not packed (light items only)
  std::string pageCoding = "zstd";   // zstd: compressed pages (format 5.0); raw: page images (the older versions)
  int zstdLevel = 15;                // 1..19
};

// Packs; returns the JSON report (models, levels, bytes, seconds). Throws canopy::Error.
nlohmann::json octreepack(const OctreepackOptions& options);

// Report of `info` (also used by octreepack's own report).
nlohmann::json canopyInfo(const CanopyFile& file);
// Human-readable rendering of canopyInfo (for stdout without --json).
std::string formatInfo(const nlohmann::json& info);

// Opens and checks everything; fills report["problems"]; throws canopy::Error(InvalidInput) if any
// page is bad (errors opening the resident part propagate with their own code).
void canopyVerify(const std::string& path, nlohmann::json& report);

}  // namespace canopy::octreepack
