// voxelize.h: mesh -> Canopy density lattice (design/PIPELINE.md §1), callable in-process.
//
// canopy::voxelize(options) loads a mesh (mesh_io.h), removes degenerate and duplicate faces
// (mesh_clean.h), rasterises every triangle into a fine grid (supersample x the lattice resolution
// per axis) with an exact triangle/box overlap test, and averages the fine cells into the lattice:
//   density = fraction of a cell's fine sub-cells touched by counted geometry (0..1),
//   wood    = fraction of those sub-cells touched by wood geometry,
//   albedo  = mean linear base colour over all (triangle, sub-cell) touches in the cell.
// Leaf (alpha-masked) geometry counts in a sub-cell only where its base-colour alpha passes
// alphaCutoff; alpha (and colour) are sampled at the sub-cell centre projected onto the triangle's
// plane and clamped into the triangle, from the texture's mip level matching the sub-cell's
// footprint (texture_sample.h).
// The lattice is a cube of resolution^3 cells: the mesh's bounding cube centred in cells
// 1..resolution-2 with one fine sub-cell of margin, so the outer layer of cells is always empty.
// Work and memory follow the occupied 8^3-cell tiles (TBB, deterministic at any thread count).
//
// With options.detail = D = resolution * k (k = 2, 4, 8, 16) the same pass also averages a
// second, finer lattice of D^3 cells nested in the first (the detail lattice, formats/
// density_lattice.h): detail cell (k c + d) is the (S/k)^3 sub-cells of lattice cell c's
// sub-block d, with the same three values computed the same way. The lattice itself is unchanged.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "mesh_io.h"

namespace canopy {

struct VoxelizeOptions {
  std::string input;             // .glb/.gltf/.obj/.ply/.stl/.off
  std::string output;            // .vdb; empty = compute only (tests, benchmarks)
  int resolution = 128;          // lattice cells per axis, boundary layer included
  int supersample = 8;           // fine sub-cells per lattice cell per axis
  std::string woodPattern = "bark|wood|trunk|branch|stem";  // ECMAScript regex, case-insensitive
  int meshIndex = -1;            // glTF: -1 whole scene with node transforms, N = mesh N alone
  std::string instancesOutput;   // glTF: write the scene instance list (docs/scene-json.md) here
  std::string modelPattern = "{stem}.mesh{N}.density.vdb";  // density paths in that list
  bool clean = true;             // remove degenerate and duplicate faces (CGAL)
  int detail = 0;                // > 0: also the detail lattice of this many cells per axis
  std::string detailOutput;      // its .vdb; empty = output with .density.vdb -> .detail.vdb
};

// The limits checked by validateOptions (usage errors outside them).
constexpr int kMinResolution = 8;
constexpr int kMaxResolution = 2048;  // the lattice reader's limit: 2048^3 = 2^33 cells (lattice_io.cpp checks)
constexpr int kMaxSupersample = 16;
constexpr int64_t kMaxFineResolution = int64_t(1) << 16;  // resolution * supersample
constexpr int kMaxDetailFactor = 16;  // detail / resolution: 2, 4, 8 or 16 (the reader's rule)

// Throws usageError naming the offending option.
void validateOptions(const VoxelizeOptions& options);

// detail / resolution (1 without --detail); validateOptions has checked it.
int detailFactor(const VoxelizeOptions& options);

// Where the detail lattice goes: options.detailOutput, else options.output with its trailing
// ".density.vdb" replaced by ".detail.vdb"; empty without --detail or without any output. Throws
// usageError if there is no such name or it is options.output.
std::string detailOutputPath(const VoxelizeOptions& options);

// One occupied lattice cell.
struct LatticeCell {
  int32_t i, j, k;
  float density, wood;
  float albedo[3];
};

// Where the lattice sits in model space: voxel (i,j,k) centre = origin + voxelSize * (i,j,k).
struct LatticeFrame {
  int resolution = 0;
  double voxelSize = 0;
  double origin[3] = {0, 0, 0};
};

struct VoxelizeStats {
  size_t inputTriangles = 0, degenerateRemoved = 0, duplicatesRemoved = 0, triangles = 0;
  size_t woodTriangles = 0, maskedTriangles = 0;
  size_t occupiedTiles = 0, occupiedCells = 0;
  uint64_t fineTouches = 0;     // (triangle, sub-cell) overlaps found
  uint64_t alphaRejected = 0;   // of those, dropped by the alpha test
  uint64_t exactTests = 0;      // overlap decisions handed to CGAL's exact predicate
  double totalDensity = 0, woodFraction = 0;  // woodFraction = sum(density*wood)/sum(density)
  size_t detailOccupiedCells = 0;             // --detail: the detail lattice's
  double detailTotalDensity = 0;              // (k^3 x totalDensity: its cells are k^3 times smaller)
  double secondsLoad = 0, secondsClean = 0, secondsVoxelize = 0, secondsWrite = 0;
};

struct VoxelizeResult {
  LatticeFrame frame;
  std::vector<LatticeCell> cells;  // sorted by (i, j, k)
  VoxelizeStats stats;
  // --detail: the detail lattice (detailFactor k > 1). Its voxel size is frame.voxelSize / k and
  // its cell j is centred at frame.origin - voxelSize / 2 + (j + 1/2) voxelSize / k.
  int detailFactor = 1;
  LatticeFrame detailFrame;
  std::vector<LatticeCell> detailCells;  // sorted by (i, j, k)
};

// Material classification: wood if the name matches the pattern (ECMAScript, icase).
std::vector<bool> classifyWood(const std::vector<mesh::Material>& materials,
                               const std::string& pattern);

// The core on an already-loaded mesh (tests call this with analytic meshes). Throws
// invalidInput(name + ...) for zero triangles, only degenerate ones, or no occupied cell (e.g.
// every triangle removed by the alpha test).
VoxelizeResult voxelizeMesh(mesh::Mesh mesh, const VoxelizeOptions& options,
                            const std::string& name);

// Load + voxelise + write options.output (if set) and options.instancesOutput (if set).
// Fills `report` (the --json object) when given.
VoxelizeResult voxelize(const VoxelizeOptions& options, nlohmann::json* report = nullptr);

// Writes a result as the OpenVDB lattice file (density, wood, albedo grids + metadata) to
// options.output.
void writeLattice(const VoxelizeResult& result, const VoxelizeOptions& options,
                  const std::string& source);
// Writes its detail lattice to `path`: the same file layout with canopy_resolution = D,
// canopy_supersample = S / k, canopy_voxel_size = its voxel size, canopy_light_resolution = the
// lattice's resolution, and the detail relation on the density grid (formats/density_lattice.h).
void writeDetailLattice(const VoxelizeResult& result, const VoxelizeOptions& options,
                        const std::string& source, const std::string& path);

// Writes the scene instance list of a glTF scene (docs/scene-json.md). Density paths follow
// options.modelPattern ({stem} = input file name without extension, {N} = mesh index,
// {name} = sanitised mesh name), relative to the JSON file's directory.
void writeInstances(const std::string& gltfPath, const std::string& jsonPath,
                    const std::string& modelPattern);

// `canopy-voxelize info`: checks a lattice file and summarises it (detail_factor 1, or k with
// light_lattice_min/max for a detail lattice). Throws invalidInput if the file is not a valid
// Canopy lattice.
nlohmann::json latticeInfo(const std::string& vdbPath);

}  // namespace canopy
