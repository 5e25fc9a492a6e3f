// voxelize_run.cpp: canopy::voxelize() (load, voxelise, write, report) and the scene list writer.
#include <chrono>
#include <cstdio>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "canopy/errors.h"
#include "formats/lattice_vdb.h"
#include "formats/scene_json.h"
#include "gltf_scene.h"
#include "voxelize.h"

namespace canopy {

void writeInstances(const std::string& gltfPath, const std::string& jsonPath,
                    const std::string& modelPattern) {
  Scene scene = mesh::sceneFromGltf(gltfPath);
  mesh::applyModelPattern(scene, gltfPath, modelPattern);
  writeSceneJson(jsonPath, scene);
}

namespace {

// Writes the lattice and, with --detail, the detail lattice: the detail first, removed again if
// the lattice then fails, so a failed run leaves neither.
void writeLattices(const VoxelizeResult& r, const VoxelizeOptions& o, const std::string& source,
                   const std::string& detailPath) {
  if (!detailPath.empty()) writeDetailLattice(r, o, source, detailPath);
  if (o.output.empty()) return;
  try {
    writeLattice(r, o, source);
  } catch (...) {
    if (!detailPath.empty()) std::remove(detailPath.c_str());
    throw;
  }
}

void fillReport(nlohmann::json& j, const VoxelizeResult& r, const VoxelizeOptions& o, const std::string& source,
                const std::string& detailPath) {
  const VoxelizeStats& s = r.stats;
  j["input"] = o.input;
  j["source"] = source;
  j["output"] = o.output;
  if (!o.instancesOutput.empty()) j["instances"] = o.instancesOutput;
  j["resolution"] = o.resolution;
  j["supersample"] = o.supersample;
  j["mesh_index"] = o.meshIndex;
  j["wood_pattern"] = o.woodPattern;
  j["voxel_size"] = r.frame.voxelSize;
  j["origin"] = {r.frame.origin[0], r.frame.origin[1], r.frame.origin[2]};
  j["lattice_min"] = {0, 0, 0};
  j["lattice_max"] = {o.resolution - 1, o.resolution - 1, o.resolution - 1};
  j["triangles"] = {{"input", s.inputTriangles}, {"degenerate_removed", s.degenerateRemoved},
                    {"duplicates_removed", s.duplicatesRemoved}, {"voxelized", s.triangles},
                    {"wood", s.woodTriangles}, {"alpha_tested", s.maskedTriangles}};
  j["occupied_tiles"] = s.occupiedTiles;
  j["occupied_cells"] = s.occupiedCells;
  j["total_density"] = s.totalDensity;
  j["wood_fraction"] = s.woodFraction;
  j["fine_touches"] = s.fineTouches;
  j["alpha_rejected"] = s.alphaRejected;
  j["exact_tests"] = s.exactTests;
  j["detail"] = nullptr;
  if (r.detailFactor > 1)
    j["detail"] = {{"resolution", r.detailFrame.resolution}, {"factor", r.detailFactor},
                   {"supersample", o.supersample / r.detailFactor}, {"voxel_size", r.detailFrame.voxelSize},
                   {"output", detailPath}, {"occupied_cells", s.detailOccupiedCells},
                   {"total_density", s.detailTotalDensity}};
}

}  // namespace

VoxelizeResult voxelize(const VoxelizeOptions& o, nlohmann::json* report) {
  const auto t0 = std::chrono::steady_clock::now();
  validateOptions(o);
  if (o.input.empty()) throw usageError("no input mesh given");
  const std::string detailPath = detailOutputPath(o);
  // Fail on an unwritable destination before any work (the probe's temporary file is removed).
  if (!o.output.empty()) AtomicOutput probe(o.output);
  if (!detailPath.empty()) AtomicOutput probe(detailPath);
  if (!o.instancesOutput.empty()) AtomicOutput probe(o.instancesOutput);

  mesh::LoadOptions lo;
  lo.meshIndex = o.meshIndex;
  logInfo("canopy-voxelize: loading " + o.input);
  auto tl = std::chrono::steady_clock::now();
  mesh::Mesh m = mesh::loadMesh(o.input, lo);
  const double secondsLoad = secondsSince(tl);
  if (m.droppedNonTriangles) logWarn(o.input + ": skipped " + std::to_string(m.droppedNonTriangles) +
                                     " point/line primitives");
  VoxelizeResult r = voxelizeMesh(std::move(m), o, o.input);
  r.stats.secondsLoad = secondsLoad;
  logInfo("canopy-voxelize: " + std::to_string(r.stats.triangles) + " triangles -> " +
          std::to_string(r.stats.occupiedCells) + " occupied cells of " + std::to_string(o.resolution) + "^3" +
          (r.detailFactor > 1 ? ", " + std::to_string(r.stats.detailOccupiedCells) + " of the detail lattice's " +
                                    std::to_string(o.detail) + "^3"
                              : std::string()));
  const std::string source = vdbio::describeSource(o.input);
  auto tw = std::chrono::steady_clock::now();
  writeLattices(r, o, source, detailPath);
  if (!o.instancesOutput.empty()) writeInstances(o.input, o.instancesOutput, o.modelPattern);
  r.stats.secondsWrite = secondsSince(tw);

  if (report) {
    fillReport(*report, r, o, source, detailPath);
    const VoxelizeStats& s = r.stats;
    (*report)["seconds"] = {{"load", s.secondsLoad}, {"clean", s.secondsClean},
                            {"voxelize", s.secondsVoxelize}, {"write", s.secondsWrite},
                            {"total", secondsSince(t0)}};
  }
  return r;
}

}  // namespace canopy
