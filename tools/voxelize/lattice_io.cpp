// lattice_io.cpp: the voxeliser's OpenVDB side (the only OpenVDB translation unit of the tool):
// writes a VoxelizeResult as density/wood/albedo grids, and checks and summarises such a file.
#include <openvdb/openvdb.h>

#include <cmath>

#include "canopy/cli.h"
#include "formats/lattice_vdb.h"
#include "voxelize.h"

namespace canopy {
static_assert(int64_t(kMaxResolution) * kMaxResolution * kMaxResolution <= vdbio::kMaxLatticeCells,
              "canopy-voxelize must not write a lattice the lattice reader refuses");
namespace {

openvdb::math::Transform::Ptr latticeTransform(const LatticeFrame& f) {
  auto xf = openvdb::math::Transform::createLinearTransform(f.voxelSize);
  xf->postTranslate(openvdb::Vec3d(f.origin[0], f.origin[1], f.origin[2]));
  return xf;
}

std::string coordStr(const openvdb::Coord& c) {
  return "(" + std::to_string(c.x()) + "," + std::to_string(c.y()) + "," + std::to_string(c.z()) + ")";
}

}  // namespace

void writeLattice(const VoxelizeResult& r, const VoxelizeOptions& o, const std::string& source) {
  vdbio::initialize();
  auto density = openvdb::FloatGrid::create(0.0f);
  auto wood = openvdb::FloatGrid::create(0.0f);
  auto albedo = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
  density->setName("density");
  wood->setName("wood");
  albedo->setName("albedo");
  density->setGridClass(openvdb::GRID_FOG_VOLUME);  // renderers treat it as a participating medium
  {
    auto da = density->getAccessor();
    auto wa = wood->getAccessor();
    auto aa = albedo->getAccessor();
    for (const LatticeCell& c : r.cells) {
      const openvdb::Coord ijk(c.i, c.j, c.k);
      da.setValue(ijk, c.density);
      wa.setValue(ijk, c.wood);
      aa.setValue(ijk, openvdb::Vec3s(c.albedo[0], c.albedo[1], c.albedo[2]));
    }
  }
  vdbio::LatticeMeta meta;
  meta.min = openvdb::Coord(0);
  meta.max = openvdb::Coord(r.frame.resolution - 1);
  meta.source = source;
  const auto xf = latticeTransform(r.frame);
  for (openvdb::GridBase::Ptr g : {openvdb::GridBase::Ptr(density), openvdb::GridBase::Ptr(wood),
                                   openvdb::GridBase::Ptr(albedo)}) {
    g->setTransform(xf->copy());
    vdbio::stampGrid(*g, meta);
  }
  albedo->insertMeta("canopy_color_space", openvdb::StringMetadata("linear sRGB"));
  wood->insertMeta("canopy_meaning", openvdb::StringMetadata("fraction of the cell's biomass that is wood"));

  openvdb::MetaMap fileMeta;
  fileMeta.insertMeta("canopy_tool", openvdb::StringMetadata("canopy-voxelize"));
  fileMeta.insertMeta("canopy_resolution", openvdb::Int32Metadata(o.resolution));
  fileMeta.insertMeta("canopy_supersample", openvdb::Int32Metadata(o.supersample));
  fileMeta.insertMeta("canopy_wood_pattern", openvdb::StringMetadata(o.woodPattern));
  fileMeta.insertMeta("canopy_mesh_index", openvdb::Int32Metadata(o.meshIndex));
  fileMeta.insertMeta("canopy_clean", openvdb::BoolMetadata(o.clean));
  fileMeta.insertMeta("canopy_voxel_size", openvdb::DoubleMetadata(r.frame.voxelSize));
  fileMeta.insertMeta("canopy_triangles", openvdb::Int64Metadata(int64_t(r.stats.triangles)));
  vdbio::writeVdb(o.output, {density, wood, albedo}, fileMeta);
}

nlohmann::json latticeInfo(const std::string& path) {
  const vdbio::VdbFile f = vdbio::readVdb(path);
  auto density = f.require<openvdb::FloatGrid>("density");
  const vdbio::LatticeMeta meta = vdbio::readLatticeMeta(*density, path);
  auto bad = [&](const std::string& why) { return invalidInput(path + ": " + why); };
  // Every grid must carry the same lattice.
  for (const auto& g : *f.grids) {
    const vdbio::LatticeMeta m = vdbio::readLatticeMeta(*g, path);
    if (m.min != meta.min || m.max != meta.max)
      throw bad("grid '" + g->getName() + "' has a different lattice than 'density'");
  }
  if (!density->transform().isLinear()) throw bad("density grid transform is not linear");
  // Values: finite, density in (0,1], inside the lattice, outer layer empty.
  const openvdb::CoordBBox inner(meta.min.offsetBy(1), meta.max.offsetBy(-1));
  uint64_t occupied = 0;
  double total = 0, woodSum = 0;
  auto woodGrid = f.find("wood") ? f.require<openvdb::FloatGrid>("wood") : openvdb::FloatGrid::Ptr();
  auto woodAcc = woodGrid ? std::make_unique<openvdb::FloatGrid::ConstAccessor>(woodGrid->getConstAccessor())
                          : nullptr;
  for (auto it = density->cbeginValueOn(); it; ++it) {
    const float v = *it;
    if (!it.isVoxelValue()) throw bad("density has an active tile (expected voxels only)");
    if (!std::isfinite(v) || v < 0.f || v > 1.f)
      throw bad("density " + std::to_string(v) + " at " + coordStr(it.getCoord()) + " is outside [0,1]");
    if (!inner.isInside(it.getCoord()))
      throw bad("occupied cell " + coordStr(it.getCoord()) + " lies on or outside the lattice boundary layer");
    ++occupied;
    total += v;
    if (woodAcc) {
      const float w = woodAcc->getValue(it.getCoord());
      if (!std::isfinite(w) || w < 0.f || w > 1.f)
        throw bad("wood " + std::to_string(w) + " at " + coordStr(it.getCoord()) + " is outside [0,1]");
      woodSum += double(v) * w;
    }
  }
  nlohmann::json j;
  j["file"] = path;
  const openvdb::Coord dim = meta.dim();
  j["lattice_min"] = {meta.min.x(), meta.min.y(), meta.min.z()};
  j["lattice_max"] = {meta.max.x(), meta.max.y(), meta.max.z()};
  j["lattice_size"] = {dim.x(), dim.y(), dim.z()};
  j["voxel_size"] = density->voxelSize()[0];
  const openvdb::Vec3d o = density->indexToWorld(openvdb::Vec3d(0, 0, 0));
  j["origin"] = {o[0], o[1], o[2]};
  j["occupied_cells"] = occupied;
  j["total_density"] = total;
  j["wood_fraction"] = total > 0 ? woodSum / total : 0.0;
  j["source"] = meta.source;
  nlohmann::json grids = nlohmann::json::array();
  for (const auto& g : *f.grids) grids.push_back({{"name", g->getName()}, {"type", g->type()},
                                                   {"active_voxels", g->activeVoxelCount()}});
  j["grids"] = grids;
  nlohmann::json m = nlohmann::json::object();
  if (f.meta)
    for (auto it = f.meta->beginMeta(); it != f.meta->endMeta(); ++it) m[it->first] = it->second->str();
  j["metadata"] = m;
  return j;
}

}  // namespace canopy
