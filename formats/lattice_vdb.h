// lattice_vdb.h: OpenVDB files in Canopy's lattice contract (design/PIPELINE.md §0).
//
// Every grid Canopy writes lives in lattice index space (voxel (i,j,k) = lattice node (i,j,k)), its
// transform maps index space to model space (metres, +Y up), and it carries:
//   canopy_lattice_min / canopy_lattice_max (vec3i, inclusive, boundary layer included),
//   canopy_version (string), canopy_source (string: "<file> xxh64:<hash>").
// writeVdb() writes atomically and deterministically: OpenVDB puts a random UUID into every file
// header; we replace it with one derived from the rest of the file's bytes, so the same inputs
// give the same bytes. readVdb() turns every OpenVDB/Boost failure into a one-line canopy::Error and
// refuses a file format version newer than the OpenVDB it was built with (OpenVDB would read on).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>

#include "canopy/errors.h"
#include "canopy/hash.h"

namespace canopy::vdbio {

void initialize();  // openvdb::initialize(), once, thread-safe

// The largest lattice readLatticeMeta accepts: 2^33 cells (2048^3). Writers must stay within it.
constexpr int64_t kMaxLatticeCells = int64_t(1) << 33;

struct LatticeMeta {
  openvdb::Coord min{0}, max{0};  // inclusive lattice bounds (whole lattice, boundary included)
  std::string source;             // "<path> xxh64:<hex>"
  openvdb::Coord dim() const { return max - min + openvdb::Coord(1); }
};

// Writes the §0 metadata (and canopy_version) onto a grid.
void stampGrid(openvdb::GridBase& grid, const LatticeMeta& meta);
// Reads it back; throws invalidInput naming `path` if missing or inconsistent.
LatticeMeta readLatticeMeta(const openvdb::GridBase& grid, const std::string& path);

using canopy::describeSource;  // core/include/canopy/hash.h

// Writes grids (and optional file-level metadata) atomically with a content-derived UUID.
void writeVdb(const std::string& path, const openvdb::GridPtrVec& grids,
              const openvdb::MetaMap& fileMeta = openvdb::MetaMap());

struct VdbFile {
  std::string path;
  openvdb::GridPtrVecPtr grids;
  openvdb::MetaMap::Ptr meta;
  // The named grid, or nullptr.
  openvdb::GridBase::Ptr find(const std::string& name) const;
  // The named grid of type GridT; throws invalidInput naming the file if absent or of another type.
  template <class GridT>
  typename GridT::Ptr require(const std::string& name) const {
    auto g = find(name);
    if (!g) throw invalidInput(path + ": no grid named '" + name + "'");
    auto typed = openvdb::gridPtrCast<GridT>(g);
    if (!typed)
      throw invalidInput(path + ": grid '" + name + "' has type " + g->type() + ", expected " +
                         GridT::gridType());
    return typed;
  }
};

// Reads every grid of a .vdb file. Throws Io (missing/unreadable) or InvalidInput (not a VDB,
// truncated, corrupt).
VdbFile readVdb(const std::string& path);

// canopy-lbsolve's mark on each light base grid: canopy_direct_beam = false where a sun base holds
// only scattered light (its direct beam removed, docs/lbsolve.md). Absent (light files from before
// the mark): the beam is included.
constexpr const char* kDirectBeamMeta = "canopy_direct_beam";
bool gridHasDirectBeam(const openvdb::GridBase& grid);
// Whether a light field's sun bases hold scattered light only, from each base's mark (beam[b]:
// base b includes its direct beam; b = 0 is the ambient base B00). Throws InvalidInput naming
// `path` when the ambient base is marked or the sun bases disagree.
bool sunBasesScattered(const std::string& path, const std::vector<bool>& beam);

// Deterministic-UUID helper exposed for tests: rewrites the UUID field of an OpenVDB file image in
// place from the hash of the other bytes. Returns false if the image is not a VDB header.
bool rewriteUuid(std::string& fileBytes);

}  // namespace canopy::vdbio
