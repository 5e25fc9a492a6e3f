// lattice_io.cpp: the voxeliser's OpenVDB side (the only OpenVDB translation unit of the tool):
// a VoxelizeResult as a density lattice file, and `info`'s summary of one; the file's grids,
// metadata and checks are formats/density_lattice.h's.
#include <openvdb/openvdb.h>

#include "formats/density_lattice.h"
#include "voxelize.h"

namespace canopy {
static_assert(int64_t(kMaxResolution) * kMaxResolution * kMaxResolution <= vdbio::kMaxLatticeCells,
              "canopy-voxelize must not write a lattice the lattice reader refuses");
static_assert(kMaxDetailFactor == vdbio::kMaxDetailFactor, "--detail's factors are the reader's");
namespace {

openvdb::math::Transform::Ptr latticeTransform(const LatticeFrame& f) {
  auto xf = openvdb::math::Transform::createLinearTransform(f.voxelSize);
  xf->postTranslate(openvdb::Vec3d(f.origin[0], f.origin[1], f.origin[2]));
  return xf;
}

// The file of one lattice (frame and cells), with the options as file metadata.
vdbio::DensityLatticeData latticeData(const LatticeFrame& frame, const std::vector<LatticeCell>& cells,
                                      const VoxelizeOptions& o, int supersample, const VoxelizeStats& st,
                                      const std::string& source) {
  vdbio::DensityLatticeData data;
  data.meta.min = openvdb::Coord(0);
  data.meta.max = openvdb::Coord(frame.resolution - 1);
  data.meta.source = source;
  data.transform = latticeTransform(frame);
  data.cells.reserve(cells.size());
  for (const LatticeCell& c : cells)
    data.cells.push_back({{c.i, c.j, c.k}, c.density, c.wood, {c.albedo[0], c.albedo[1], c.albedo[2]}});
  openvdb::MetaMap& fileMeta = data.fileMeta;
  fileMeta.insertMeta("canopy_tool", openvdb::StringMetadata("canopy-voxelize"));
  fileMeta.insertMeta("canopy_resolution", openvdb::Int32Metadata(frame.resolution));
  fileMeta.insertMeta("canopy_supersample", openvdb::Int32Metadata(supersample));
  fileMeta.insertMeta("canopy_wood_pattern", openvdb::StringMetadata(o.woodPattern));
  fileMeta.insertMeta("canopy_mesh_index", openvdb::Int32Metadata(o.meshIndex));
  fileMeta.insertMeta("canopy_clean", openvdb::BoolMetadata(o.clean));
  fileMeta.insertMeta("canopy_voxel_size", openvdb::DoubleMetadata(frame.voxelSize));
  fileMeta.insertMeta("canopy_triangles", openvdb::Int64Metadata(int64_t(st.triangles)));
  return data;
}

// vdbio::writeDensityLattice, with the cells' copy released once the grids hold them (a detail
// lattice has millions).
void writeData(const std::string& path, vdbio::DensityLatticeData& data) {
  const openvdb::GridPtrVec grids = vdbio::densityLatticeGrids(data);
  std::vector<vdbio::DensityCell>().swap(data.cells);
  vdbio::writeVdb(path, grids, data.fileMeta);
}

}  // namespace

void writeLattice(const VoxelizeResult& r, const VoxelizeOptions& o, const std::string& source) {
  vdbio::DensityLatticeData data = latticeData(r.frame, r.cells, o, o.supersample, r.stats, source);
  writeData(o.output, data);
}

void writeDetailLattice(const VoxelizeResult& r, const VoxelizeOptions& o, const std::string& source,
                        const std::string& path) {
  const int k = r.detailFactor;
  vdbio::DensityLatticeData data = latticeData(r.detailFrame, r.detailCells, o, o.supersample / k, r.stats, source);
  data.fileMeta.insertMeta("canopy_light_resolution", openvdb::Int32Metadata(r.frame.resolution));
  data.detailFactor = k;
  data.lightMin = openvdb::Coord(0);
  data.lightMax = openvdb::Coord(r.frame.resolution - 1);
  writeData(path, data);
}

nlohmann::json latticeInfo(const std::string& path) {
  const vdbio::DensityLattice L = vdbio::readDensityLattice(path);  // the one contract (formats/density_lattice.h)
  double total = 0, woodSum = 0;
  for (const vdbio::DensityCell& c : L.cells) {
    total += c.density;
    woodSum += double(c.density) * c.wood;
  }
  nlohmann::json j;
  j["file"] = path;
  const openvdb::Coord dim = L.meta.dim();
  j["lattice_min"] = {L.meta.min.x(), L.meta.min.y(), L.meta.min.z()};
  j["lattice_max"] = {L.meta.max.x(), L.meta.max.y(), L.meta.max.z()};
  j["lattice_size"] = {dim.x(), dim.y(), dim.z()};
  j["voxel_size"] = L.transform->voxelSize()[0];
  const openvdb::Vec3d o = L.transform->indexToWorld(openvdb::Vec3d(0, 0, 0));
  j["origin"] = {o[0], o[1], o[2]};
  j["occupied_cells"] = L.cells.size();
  j["total_density"] = total;
  j["wood_fraction"] = total > 0 ? woodSum / total : 0.0;
  j["source"] = L.meta.source;
  j["detail_factor"] = L.detailFactor;
  if (L.detailFactor > 1) {
    j["light_lattice_min"] = {L.lightMin.x(), L.lightMin.y(), L.lightMin.z()};
    j["light_lattice_max"] = {L.lightMax.x(), L.lightMax.y(), L.lightMax.z()};
  }
  nlohmann::json grids = nlohmann::json::array();
  for (const auto& g : L.grids) grids.push_back({{"name", g.name}, {"type", g.type}, {"active_voxels", g.activeVoxels}});
  j["grids"] = grids;
  nlohmann::json m = nlohmann::json::object();
  for (auto it = L.fileMeta.beginMeta(); it != L.fileMeta.endMeta(); ++it) m[it->first] = it->second->str();
  j["metadata"] = m;
  return j;
}

}  // namespace canopy
