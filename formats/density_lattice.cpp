// density_lattice.cpp: see density_lattice.h.
#include "formats/density_lattice.h"

#include <cmath>
#include <sstream>

#include <tbb/parallel_invoke.h>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"

namespace canopy::vdbio {
namespace {

std::string coordString(const openvdb::Coord& c) {
  std::ostringstream s;
  s << "(" << c.x() << "," << c.y() << "," << c.z() << ")";
  return s.str();
}

std::string valueString(float v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// More active density voxels than this is no plant (and more than the packer's 32-bit cell counts).
constexpr openvdb::Index64 kMaxActiveVoxels = openvdb::Index64(1) << 31;

}  // namespace

openvdb::GridPtrVec densityLatticeGrids(const DensityLatticeData& data) {
  initialize();
  auto density = openvdb::FloatGrid::create(0.0f);
  auto wood = openvdb::FloatGrid::create(0.0f);
  auto albedo = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
  density->setName("density");
  wood->setName("wood");
  albedo->setName("albedo");
  density->setGridClass(openvdb::GRID_FOG_VOLUME);  // renderers treat it as a participating medium
  // The three grids are filled side by side (a detail lattice has millions of cells); each grid's
  // tree is the same whatever the order.
  auto fill = [&](auto& grid, auto value) {
    auto a = grid->getAccessor();
    for (const DensityCell& c : data.cells) a.setValue(openvdb::Coord(c.ijk[0], c.ijk[1], c.ijk[2]), value(c));
  };
  tbb::parallel_invoke([&] { fill(density, [](const DensityCell& c) { return c.density; }); },
                       [&] { fill(wood, [](const DensityCell& c) { return c.wood; }); },
                       [&] { fill(albedo, [](const DensityCell& c) { return openvdb::Vec3s(c.albedo[0], c.albedo[1], c.albedo[2]); }); });
  for (openvdb::GridBase::Ptr g : {openvdb::GridBase::Ptr(density), openvdb::GridBase::Ptr(wood),
                                   openvdb::GridBase::Ptr(albedo)}) {
    g->setTransform(data.transform->copy());
    stampGrid(*g, data.meta);
  }
  if (data.detailFactor != 1) {
    density->insertMeta(kDetailFactorMeta, openvdb::Int32Metadata(data.detailFactor));
    density->insertMeta(kLightLatticeMinMeta, openvdb::Vec3IMetadata(data.lightMin.asVec3i()));
    density->insertMeta(kLightLatticeMaxMeta, openvdb::Vec3IMetadata(data.lightMax.asVec3i()));
  }
  albedo->insertMeta("canopy_color_space", openvdb::StringMetadata("linear sRGB"));
  wood->insertMeta("canopy_meaning", openvdb::StringMetadata("fraction of the cell's biomass that is wood"));
  return {density, wood, albedo};
}

void writeDensityLattice(const std::string& path, const DensityLatticeData& data) {
  writeVdb(path, densityLatticeGrids(data), data.fileMeta);
}

DensityLattice readDensityLattice(const std::string& path) {
  const VdbFile file = readVdb(path);
  auto bad = [&](const std::string& why) { return invalidInput(path + ": " + why); };
  DensityLattice L;
  L.path = path;
  auto density = file.require<openvdb::FloatGrid>("density");
  L.meta = readLatticeMeta(*density, path);
  auto wood = file.require<openvdb::FloatGrid>("wood");
  auto albedo = file.require<openvdb::Vec3SGrid>("albedo");
  for (const openvdb::GridBase::Ptr& g : {openvdb::GridBase::Ptr(wood), openvdb::GridBase::Ptr(albedo)}) {
    const LatticeMeta m = readLatticeMeta(*g, path);
    if (m.min != L.meta.min || m.max != L.meta.max)
      throw bad("grid '" + g->getName() + "' has a different lattice than 'density' (" + coordString(m.min) + ".." +
                coordString(m.max) + " against " + coordString(L.meta.min) + ".." + coordString(L.meta.max) + ")");
  }
  if (!density->transform().isLinear()) throw bad("grid 'density' has a transform that is not linear (frustum maps are not supported)");
  if (density->background() != 0.f)
    throw bad("grid 'density' has background " + valueString(density->background()) + ", expected 0");
  const openvdb::Index64 active = density->activeVoxelCount();
  if (active > kMaxActiveVoxels)
    throw bad("grid 'density' has " + std::to_string(active) + " active voxels, more than the 2^31 Canopy reads");
  L.transform = density->transform().copy();
  if (auto k = density->getMetadata<openvdb::Int32Metadata>(kDetailFactorMeta)) {
    const int f = k->value();
    if (f < 2 || f > kMaxDetailFactor || (f & (f - 1)) != 0)
      throw bad(std::string(kDetailFactorMeta) + " is " + std::to_string(f) + ", expected 2, 4, 8 or 16");
    auto lo = density->getMetadata<openvdb::Vec3IMetadata>(kLightLatticeMinMeta);
    auto hi = density->getMetadata<openvdb::Vec3IMetadata>(kLightLatticeMaxMeta);
    if (!lo || !hi) throw bad("a detail lattice without " + std::string(kLightLatticeMinMeta) + "/" + kLightLatticeMaxMeta);
    L.detailFactor = f;
    L.lightMin = openvdb::Coord(lo->value());
    L.lightMax = openvdb::Coord(hi->value());
    for (int a = 0; a < 3; ++a)
      if (L.lightMin[a] > L.lightMax[a] || int64_t(L.lightMin[a]) * f != L.meta.min[a] ||
          int64_t(L.lightMax[a]) * f + f - 1 != L.meta.max[a])
        throw bad("its light lattice " + coordString(L.lightMin) + ".." + coordString(L.lightMax) + " x " +
                  std::to_string(f) + " is not its lattice " + coordString(L.meta.min) + ".." + coordString(L.meta.max));
  }
  if (file.meta) L.fileMeta = *file.meta;
  for (const auto& g : *file.grids) L.grids.push_back({g->getName(), g->type(), g->activeVoxelCount()});

  const openvdb::CoordBBox lattice(L.meta.min, L.meta.max);
  auto woodAcc = wood->getConstAccessor();
  auto albAcc = albedo->getConstAccessor();
  L.cells.reserve(size_t(active));
  for (auto it = density->cbeginValueOn(); it; ++it) {
    const float v = *it;
    openvdb::CoordBBox box;
    it.getBoundingBox(box);
    if (std::isnan(v)) throw bad("density is NaN at " + coordString(box.min()));
    if (!std::isfinite(v)) throw bad("density is infinite at " + coordString(box.min()));
    if (v < 0.f) throw bad("negative density " + valueString(v) + " at " + coordString(box.min()));
    if (v > 1.f)
      throw bad("density " + valueString(v) + " at " + coordString(box.min()) +
                " exceeds 1 (densities are biomass fractions in [0, 1])");
    if (v == 0.f) continue;
    if (!lattice.isInside(box))
      throw bad("non-zero density at " + coordString(box.min()) + " outside the lattice " + coordString(L.meta.min) +
                ".." + coordString(L.meta.max));
    for (auto c = box.begin(); c; ++c) {
      DensityCell cell;
      for (int a = 0; a < 3; ++a) cell.ijk[a] = (*c)[a];
      cell.density = v;
      cell.wood = woodAcc.getValue(*c);
      if (!std::isfinite(cell.wood)) throw bad("wood fraction is not finite at " + coordString(*c));
      if (cell.wood < 0.f || cell.wood > 1.f)
        throw bad("wood fraction " + valueString(cell.wood) + " at " + coordString(*c) + " is outside [0, 1]");
      const openvdb::Vec3s al = albAcc.getValue(*c);
      for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(al[a])) throw bad("albedo is not finite at " + coordString(*c));
        cell.albedo[a] = al[a];
      }
      L.cells.push_back(cell);
    }
  }
  return L;
}

DensityLatticeOrigin readDensityLatticeOrigin(const std::string& path) {
  initialize();
  requireReadableFile(path);
  openvdb::GridBase::Ptr density;
  openvdb::MetaMap::Ptr fileMeta;
  try {
    openvdb::io::File file(path);
    file.open(false);
    if (file.hasGrid("density")) density = file.readGridMetadata("density");
    fileMeta = file.getMetadata();
    file.close();
  } catch (const std::exception& e) {
    std::string what = e.what();
    throw invalidInput(path + ": not a readable OpenVDB file (" + what.substr(0, what.find('\n')) + ")");
  }
  if (!density) throw invalidInput(path + ": no grid named 'density'");
  DensityLatticeOrigin o;
  o.source = readLatticeMeta(*density, path).source;
  if (auto mesh = fileMeta ? fileMeta->getMetadata<openvdb::Int32Metadata>("canopy_mesh_index") : nullptr) {
    o.hasMeshIndex = true;
    o.meshIndex = mesh->value();
  }
  return o;
}

}  // namespace canopy::vdbio
