// inputs.cpp: see inputs.h.
#include "tools/octreepack/inputs.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <openvdb/openvdb.h>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "formats/density_lattice.h"
#include "formats/lattice_vdb.h"

#include <memory>

#include "formats/chaar.h"

namespace canopy::octreepack {
namespace {

// index -> world of a linear OpenVDB transform as a 3x4 row-major matrix.
std::array<double, 12> affineOf(const openvdb::math::Transform& xf, const std::string& path) {
  if (!xf.isLinear()) throw invalidInput(path + ": grid transform is not linear (frustum maps are not supported)");
  const openvdb::Vec3d o = xf.indexToWorld(openvdb::Vec3d(0, 0, 0));
  std::array<double, 12> m{};
  for (int a = 0; a < 3; ++a) {
    openvdb::Vec3d e(0, 0, 0);
    e[a] = 1;
    const openvdb::Vec3d c = xf.indexToWorld(e) - o;
    for (int r = 0; r < 3; ++r) m[size_t(r * 4 + a)] = c[r];
  }
  for (int r = 0; r < 3; ++r) m[size_t(r * 4 + 3)] = o[r];
  return m;
}

// The lighting's lattice (bounds, index -> model transform) must be `model`'s light lattice: its
// density lattice, or, for a detail lattice (2^n finer), the lattice it nests in: light cell c
// covers cells [2^n c, 2^n c + 2^n), so its centre is the density lattice's index point
// 2^n c + (2^n - 1) / 2. The transform is compared for detail lattices (the bounds alone for
// ordinary ones, as before): relative to the light voxel, within 1e-6.
void checkLightLattice(const std::string& path, const ModelSource& model, const int32_t lo[3], const int32_t hi[3],
                       const std::array<double, 12>* lightToModel) {
  const uint32_t n = model.detailLevels;
  const std::string which = n == 0 ? "the density lattice" : "the light lattice (the density lattice is a detail lattice, " +
                                                                 std::to_string(1 << n) + "x finer)";
  for (int a = 0; a < 3; ++a)
    if (lo[a] != (model.latticeMin[a] >> n) || hi[a] != (model.latticeMax[a] >> n))
      throw invalidInput(path + ": its lattice differs from " + which + " of model '" + model.name + "'");
  if (n == 0 || !lightToModel) return;
  const double k = double(1 << n), c0 = 0.5 * (k - 1);
  const std::array<double, 12>& L = *lightToModel;
  const std::array<double, 12>& D = model.indexToModel;
  double voxel = 0, err = 0;
  for (int r = 0; r < 3; ++r) {
    for (int a = 0; a < 3; ++a) {
      voxel = std::max(voxel, std::fabs(L[size_t(r * 4 + a)]));
      err = std::max(err, std::fabs(L[size_t(r * 4 + a)] - k * D[size_t(r * 4 + a)]));
    }
    const double d0 = D[size_t(r * 4)] * c0 + D[size_t(r * 4 + 1)] * c0 + D[size_t(r * 4 + 2)] * c0 + D[size_t(r * 4 + 3)];
    err = std::max(err, std::fabs(L[size_t(r * 4 + 3)] - d0));
  }
  if (!(err <= 1e-6 * voxel))
    throw invalidInput(path + ": its lattice's box differs from the density box of model '" + model.name + "' (" + which +
                       " must cover the same box)");
}

}  // namespace

ModelSource readDensityVdb(const std::string& path, const std::string& name) {
  const vdbio::DensityLattice lattice = vdbio::readDensityLattice(path);  // the contract: formats/density_lattice.h
  ModelSource src;
  src.name = name;
  src.sourceLabel = vdbio::describeSource(path);
  for (int a = 0; a < 3; ++a) {
    src.latticeMin[a] = lattice.meta.min[a];
    src.latticeMax[a] = lattice.meta.max[a];
  }
  src.indexToModel = affineOf(*lattice.transform, path);
  while ((1 << src.detailLevels) < lattice.detailFactor) ++src.detailLevels;  // a power of two (the reader checks)
  src.cells.reserve(lattice.cells.size());
  for (const vdbio::DensityCell& c : lattice.cells) {
    SourceCell s;
    for (int a = 0; a < 3; ++a) s.ijk[a] = c.ijk[a];
    s.density = c.density;
    s.wood = c.wood;
    for (int a = 0; a < 3; ++a) s.albedo[a] = c.albedo[a];
    src.cells.push_back(s);
  }
  return src;
}

LightVdb readLightVdb(const std::string& path, const ModelSource& model) {
  vdbio::VdbFile file = vdbio::readVdb(path);
  std::vector<openvdb::Vec3SGrid::ConstPtr> grids;
  for (uint32_t b = 0; b < kCanopyLightBases; ++b) {
    char name[8];
    std::snprintf(name, sizeof name, "B%02u", b);
    grids.push_back(file.require<openvdb::Vec3SGrid>(name));
  }
  if (grids[0]->getMetadata<openvdb::Vec3IMetadata>("canopy_lattice_min")) {
    const vdbio::LatticeMeta meta = vdbio::readLatticeMeta(*grids[0], path);
    const int32_t lo[3] = {meta.min[0], meta.min[1], meta.min[2]}, hi[3] = {meta.max[0], meta.max[1], meta.max[2]};
    const std::array<double, 12> xf = affineOf(grids[0]->transform(), path);
    checkLightLattice(path, model, lo, hi, &xf);
  } else if (model.detailLevels != 0) {
    throw invalidInput(path + ": lighting without lattice metadata cannot be matched to a detail lattice");
  }
  LightVdb out;
  out.sourceLabel = vdbio::describeSource(path);
  std::vector<bool> beam;
  for (const auto& g : grids) beam.push_back(vdbio::gridHasDirectBeam(*g));
  out.scatteredSun = vdbio::sunBasesScattered(path, beam);
  // Tree::getValue on a const tree is thread-safe (no accessor cache): the builder calls this from
  // several threads.
  out.fn = [grids](int32_t i, int32_t j, int32_t k, float* o) {
    const openvdb::Coord ijk(i, j, k);
    for (size_t b = 0; b < grids.size(); ++b) {
      const openvdb::Vec3s v = grids[b]->tree().getValue(ijk);
      o[3 * b] = v[0], o[3 * b + 1] = v[1], o[3 * b + 2] = v[2];
    }
  };
  return out;
}

LightVdb readChaarLight(const std::string& path, const ModelSource& model, bool withHaar) {
  auto data = std::make_shared<haar::ChaarData>(haar::readChaar(path));
  const haar::ChaarHeader& h = data->header;
  if (h.baseCount != kCanopyLightBases)
    throw invalidInput(path + ": has " + std::to_string(h.baseCount) + " bases, a plant's lighting has " +
                       std::to_string(kCanopyLightBases));
  std::array<double, 12> xf{};  // the chaar's row-vector Mat4d as a 3x4 row-major matrix
  for (int r = 0; r < 3; ++r) {
    for (int a = 0; a < 3; ++a) xf[size_t(r * 4 + a)] = h.indexToModel[a * 4 + r];
    xf[size_t(r * 4 + 3)] = h.indexToModel[12 + r];
  }
  checkLightLattice(path, model, h.latticeMin, h.latticeMax, &xf);
  LightVdb out;
  out.sourceLabel = vdbio::describeSource(path);
  std::vector<bool> beam;
  for (const haar::ChaarBaseEntry& e : data->bases) beam.push_back((e.flags & haar::kChaarBaseScattered) == 0);
  out.scatteredSun = vdbio::sunBasesScattered(path, beam);
  if (withHaar && data->precision() == haar::Precision::Quant)
    throw unsupported(path + ": quantised Haar light (.chaar 2.x, canopy-haar --precision quant) cannot be packed as "
                      "exact Haar pages yet; pass --no-haar-light (light items only) or encode it with --precision fp16");
  if (withHaar) out.haar = std::make_shared<const CanopyHaarPages>(canopyHaarPagesFromChaar(*data));
  out.fn = [data, fn = chaarLightFn(data->view())](int32_t i, int32_t j, int32_t k, float* o) { fn(i, j, k, o); };  // keeps data alive
  return out;
}

SceneLightSource readSceneLightVdb(const std::string& path, const std::string& gridName) {
  vdbio::VdbFile file = vdbio::readVdb(path);
  // The grids packed: the one named, or canopy-lbsolve --scene's 19 bases B00..B18 (B00 first).
  std::vector<std::string> names;
  if (!gridName.empty()) {
    names.push_back(gridName);
  } else {
    std::string missing;
    for (uint32_t b = 0; b <= kCanopySceneSunBases; ++b) {
      char name[8];
      std::snprintf(name, sizeof name, "B%02u", b);
      names.push_back(name);
      if (!file.find(name)) missing += std::string(missing.empty() ? "" : ", ") + name;
    }
    if (!missing.empty())
      throw invalidInput(path + ": the scene lighting needs the 19 float grids B00..B18 of canopy-lbsolve --scene; " + missing +
                         " missing (--scene-light-grid NAME packs one grid as the only factor)");
  }
  std::vector<openvdb::FloatGrid::Ptr> grids;
  for (const std::string& name : names) grids.push_back(file.require<openvdb::FloatGrid>(name));
  auto boxOf = [&](const openvdb::FloatGrid& g) {
    if (g.getMetadata<openvdb::Vec3IMetadata>("canopy_lattice_min")) {
      const vdbio::LatticeMeta meta = vdbio::readLatticeMeta(g, path);
      return openvdb::CoordBBox(meta.min, meta.max);
    }
    return g.evalActiveVoxelBoundingBox();
  };
  const openvdb::CoordBBox box = boxOf(*grids[0]);
  if (box.empty()) throw invalidInput(path + ": scene lighting grid '" + names[0] + "' is empty");
  const auto m = affineOf(grids[0]->transform(), path);
  for (size_t g = 1; g < grids.size(); ++g)
    if (boxOf(*grids[g]) != box || affineOf(grids[g]->transform(), path) != m)
      throw invalidInput(path + ": scene lighting grid '" + names[g] + "' is not on " + names[0] + "'s lattice (bounds or transform differ)");
  const openvdb::Coord dim = box.dim();
  const int64_t n = int64_t(dim.x()) * dim.y() * dim.z();
  if (n > (int64_t(1) << 26) / int64_t(grids.size()))
    throw invalidInput(path + ": scene lighting lattice of " + std::to_string(n) + " nodes x " + std::to_string(grids.size()) +
                       " grids is too large for the resident part");
  SceneLightSource s;
  s.sourceLabel = vdbio::describeSource(path);
  for (int i = 0; i < 12; ++i) s.header.indexToWorld[i] = m[size_t(i)];
  for (int a = 0; a < 3; ++a) {
    s.header.min[a] = box.min()[a];
    s.header.dim[a] = dim[a];
  }
  s.bases = uint32_t(grids.size());
  s.values.resize(size_t(n) * grids.size());
  size_t i = 0;
  for (size_t g = 0; g < grids.size(); ++g) {
    auto acc = grids[g]->getConstAccessor();
    for (int z = box.min().z(); z <= box.max().z(); ++z)
      for (int y = box.min().y(); y <= box.max().y(); ++y)
        for (int x = box.min().x(); x <= box.max().x(); ++x) {
          const float v = acc.getValue(openvdb::Coord(x, y, z));
          if (!std::isfinite(v) || v < 0.0f)
            throw invalidInput(path + ": scene lighting value of '" + names[g] + "' at (" + std::to_string(x) + "," + std::to_string(y) + "," +
                               std::to_string(z) + ") is " + (std::isfinite(v) ? "negative" : "not finite"));
          s.values[i++] = v;
        }
  }
  return s;
}

}  // namespace canopy::octreepack
