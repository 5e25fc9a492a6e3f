// source_vdb.h: a ModelSource written as a density lattice file with the one writer
// (formats/density_lattice.h, canopy-voxelize's), for tests and benchmarks that feed
// canopy-octreepack or canopy-lbsolve.
#pragma once
#include <string>

#include <openvdb/openvdb.h>

#include "formats/density_lattice.h"
#include "tools/octreepack/octree_build.h"

namespace canopy::octreepack::testing {

// A lattice as canopy-voxelize writes it; `source` is its canopy_source ("<mesh file> xxh64:<hash>")
// and meshIndex (>= -1) its file's canopy_mesh_index (none where kNoMesh).
inline constexpr int kNoMesh = -2;
// A source with detailLevels > 0 is written as a detail lattice (canopy-voxelize --detail).
inline void writeSourceVdb(const std::string& path, const ModelSource& s, const std::string& source = "test",
                           int meshIndex = kNoMesh) {
  canopy::vdbio::DensityLatticeData data;
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) m(c, r) = s.indexToModel[size_t(r * 4 + c)];  // OpenVDB: row vectors
  data.transform = openvdb::math::Transform::createLinearTransform(m);
  for (const auto& c : s.cells)
    data.cells.push_back({{c.ijk[0], c.ijk[1], c.ijk[2]}, c.density, c.wood, {c.albedo[0], c.albedo[1], c.albedo[2]}});
  data.meta.min = openvdb::Coord(s.latticeMin[0], s.latticeMin[1], s.latticeMin[2]);
  data.meta.max = openvdb::Coord(s.latticeMax[0], s.latticeMax[1], s.latticeMax[2]);
  data.meta.source = source;
  if (s.detailLevels > 0) {
    data.detailFactor = 1 << s.detailLevels;
    data.lightMin = openvdb::Coord(s.latticeMin[0] >> s.detailLevels, s.latticeMin[1] >> s.detailLevels, s.latticeMin[2] >> s.detailLevels);
    data.lightMax = openvdb::Coord(s.latticeMax[0] >> s.detailLevels, s.latticeMax[1] >> s.detailLevels, s.latticeMax[2] >> s.detailLevels);
  }
  if (meshIndex != kNoMesh) data.fileMeta.insertMeta("canopy_mesh_index", openvdb::Int32Metadata(meshIndex));
  canopy::vdbio::writeDensityLattice(path, data);
}

}  // namespace canopy::octreepack::testing
