// source_vdb.h: writes a density lattice as canopy-voxelize does (grids density, wood, albedo with
// the lattice metadata), for tests that feed canopy-octreepack or canopy-lbsolve (OpenVDB).
#pragma once
#include <string>

#include <openvdb/openvdb.h>

#include "formats/lattice_vdb.h"
#include "tools/octreepack/octree_build.h"

namespace canopy::octreepack::testing {

// A lattice as canopy-voxelize writes it; `source` is its canopy_source ("<mesh file> xxh64:<hash>")
// and meshIndex (>= -1) its file's canopy_mesh_index (none where kNoMesh).
inline constexpr int kNoMesh = -2;
inline void writeSourceVdb(const std::string& path, const ModelSource& s, const std::string& source = "test",
                           int meshIndex = kNoMesh) {
  canopy::vdbio::initialize();
  auto density = openvdb::FloatGrid::create(0.0f);
  auto wood = openvdb::FloatGrid::create(0.0f);
  auto albedo = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
  density->setName("density");
  wood->setName("wood");
  albedo->setName("albedo");
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) m(c, r) = s.indexToModel[size_t(r * 4 + c)];  // OpenVDB: row vectors
  auto xf = openvdb::math::Transform::createLinearTransform(m);
  auto da = density->getAccessor();
  auto wa = wood->getAccessor();
  auto aa = albedo->getAccessor();
  for (const auto& c : s.cells) {
    const openvdb::Coord ijk(c.ijk[0], c.ijk[1], c.ijk[2]);
    da.setValue(ijk, c.density);
    wa.setValue(ijk, c.wood);
    aa.setValue(ijk, openvdb::Vec3s(c.albedo[0], c.albedo[1], c.albedo[2]));
  }
  canopy::vdbio::LatticeMeta meta;
  meta.min = openvdb::Coord(s.latticeMin[0], s.latticeMin[1], s.latticeMin[2]);
  meta.max = openvdb::Coord(s.latticeMax[0], s.latticeMax[1], s.latticeMax[2]);
  meta.source = source;
  for (openvdb::GridBase::Ptr g : {openvdb::GridBase::Ptr(density), openvdb::GridBase::Ptr(wood), openvdb::GridBase::Ptr(albedo)}) {
    g->setTransform(xf);
    canopy::vdbio::stampGrid(*g, meta);
  }
  openvdb::MetaMap fileMeta;
  if (meshIndex != kNoMesh) fileMeta.insertMeta("canopy_mesh_index", openvdb::Int32Metadata(meshIndex));
  canopy::vdbio::writeVdb(path, {density, wood, albedo}, fileMeta);
}

}  // namespace canopy::octreepack::testing
