// lattice_io.h (internal): loading a density lattice into the solvers' dense layout, and the
// metadata/grid helpers shared by the bases, sun and scene modes (lbsolve.cpp, scene.cpp).
#pragma once
#include <string>
#include <vector>

#include <openvdb/openvdb.h>

#include "formats/lattice_vdb.h"
#include "solver.h"

namespace canopy::lb {

struct LoadedLattice {
  DenseLattice dense;              // coded density (-rho at wood nodes) and the stored node list
  std::vector<float> density;      // rho per node (dense, same indexing)
  vdbio::LatticeMeta meta;         // lattice bounds; source = the input file and its hash
  openvdb::math::Transform::Ptr transform;  // index -> model space
};

// Reads a density lattice (vdbio::readDensityLattice, formats/density_lattice.h: the file's one
// read-and-validate contract) and checks what the solve adds: at least 3 nodes per axis and the
// memory of a CPU solve. Throws Io, InvalidInput (naming the file, and the node for bad values) or
// Runtime (memory).
LoadedLattice loadDensityLattice(const std::string& path, double woodThreshold);

// Node indices whose density is non-zero or one of whose 26 neighbours' is, ascending.
std::vector<int64_t> storedNodes(const Dims& d, const std::vector<float>& density);

// Index -> lattice coordinate (lattice min + (x, y, z)).
openvdb::Coord nodeCoord(const Dims& d, const openvdb::Coord& latticeMin, int64_t idx);

// Throws Runtime if a CPU solve of this lattice would not fit in this machine's memory.
void requireHostMemory(const Dims& d, const std::string& what);

}  // namespace canopy::lb
