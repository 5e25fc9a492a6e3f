// density_lattice.h: the density lattice file (canopy-voxelize's output, canopy-lbsolve's and
// canopy-octreepack's input): its one writer and its one read-and-validate contract.
//
// The file is an OpenVDB file (formats/lattice_vdb.h: §0 metadata, atomic deterministic writes,
// content checksum in the UUID) holding three grids on one lattice (design/PIPELINE.md §0, §1):
//   density  FloatGrid, class fog volume, background 0: the biomass fraction of each cell, in [0, 1]
//   wood     FloatGrid: the fraction of that biomass that is wood/bark, in [0, 1]
//   albedo   Vec3SGrid: the coverage-weighted base colour (linear sRGB), finite
// each with canopy_lattice_min/max (the same bounds on all three), canopy_version, canopy_source
// ("<mesh file> xxh64:<hash>"), and a linear index -> model transform (metres, +Y up). File-level
// metadata: the writer's options (canopy_tool, canopy_resolution, ..., canopy_mesh_index).
//
// A **detail lattice** (canopy-voxelize --detail) is the same file on a finer lattice nested in a
// light lattice: its density grid also carries canopy_detail_factor (int32 k: 2, 4, 8 or 16) and
// canopy_light_lattice_min / canopy_light_lattice_max (vec3i, inclusive), with light cell c covering
// the detail cells [k c, k c + k) per axis (so min = k lightMin, max = k lightMax + k - 1) and the
// light lattice's transform = this one's scaled by k about the box corner: light cell c is centred at
// this transform's index point k c + (k - 1) / 2. canopy-lbsolve solves on the light lattice (the
// same mesh voxelised at the light resolution); canopy-octreepack packs the detail lattice with
// that light (docs/octreepack.md).
//
// readDensityLattice checks all of it: every active density value finite and in [0, 1] (the
// spec's rule, one for every reader), every non-zero one inside the lattice bounds, wood in [0, 1]
// and albedo finite at every occupied cell. Failures are one-line canopy::Errors naming the file:
// Io (missing, unreadable) or InvalidInput (anything else). The boundary layer is not required to
// be empty: that is how canopy-voxelize builds lattices, not a property of the file.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>

#include "formats/lattice_vdb.h"

namespace canopy::vdbio {

// One occupied lattice cell.
struct DensityCell {
  int32_t ijk[3];
  float density;    // (0, 1]
  float wood;       // [0, 1]
  float albedo[3];  // linear sRGB
};

// What the writer writes (and the reader returns, with the file's own metadata).
struct DensityLatticeData {
  LatticeMeta meta;                          // inclusive bounds; source = canopy_source (the mesh)
  openvdb::math::Transform::Ptr transform;   // index -> model space, linear
  std::vector<DensityCell> cells;            // written: every cell as given; read: density > 0 only
  openvdb::MetaMap fileMeta;                 // the writer's options (canopy_tool, canopy_mesh_index ...)
  int detailFactor = 1;                      // > 1: a detail lattice nested in [lightMin, lightMax]
  openvdb::Coord lightMin{0}, lightMax{0};   // the light lattice (inclusive); only with detailFactor > 1
};

// The detail relation's metadata names (on the density grid).
constexpr const char* kDetailFactorMeta = "canopy_detail_factor";
constexpr const char* kLightLatticeMinMeta = "canopy_light_lattice_min";
constexpr const char* kLightLatticeMaxMeta = "canopy_light_lattice_max";
constexpr int kMaxDetailFactor = 16;

// The three grids of `data` (names, class, values, transform, §0 metadata), in file order
// density, wood, albedo. Every cell is written to all three grids, as given (no checks: tests
// forge bad files from these grids; readDensityLattice is the check).
openvdb::GridPtrVec densityLatticeGrids(const DensityLatticeData& data);
// Writes them with data.fileMeta, atomically and deterministically (vdbio::writeVdb).
void writeDensityLattice(const std::string& path, const DensityLatticeData& data);

// A grid of the file as read (canopy-voxelize info lists them).
struct DensityGridInfo {
  std::string name, type;
  uint64_t activeVoxels = 0;
};

struct DensityLattice : DensityLatticeData {
  std::string path;
  std::vector<DensityGridInfo> grids;  // every grid of the file, in the order OpenVDB lists them
};

// Reads and validates a density lattice (the contract above). cells: every active density value
// > 0 (active tiles expanded), in the density grid's iteration order, with wood and albedo read at
// the same node. Throws Io or InvalidInput naming `path`.
DensityLattice readDensityLattice(const std::string& path);

// Where a lattice came from, from its metadata only (no voxels): the density grid's canopy_source
// and the file's canopy_mesh_index (-1: the whole mesh file; absent: not written per glTF mesh).
struct DensityLatticeOrigin {
  std::string source;
  bool hasMeshIndex = false;
  int meshIndex = -1;
};
DensityLatticeOrigin readDensityLatticeOrigin(const std::string& path);

}  // namespace canopy::vdbio
