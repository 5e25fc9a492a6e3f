// scene.cpp: the coarse scene-level lattice of §4.3 (--scene SCENE.json).
//
// A cubic-cell lattice is laid over the world-space bounding box of all instances: `resolution`
// interior cells along the longest axis (cell edge h = longest extent / resolution), the other
// axes rounded up, plus one boundary layer on every side. The density of a coarse node is the
// biomass of the instances inside it: every fine node (density rho, model-space voxel volume v)
// of every instance is mapped to world space and adds rho * v * |det M| to the coarse cell that
// contains its centre; the coarse density is that mass / h^3, clamped to 1. A coarse node is
// wood where the wood-flagged share of its mass >= wood_threshold. The same update is solved for
// luminance only (Rec. 709 weights of the parameters) for the 19 boundary conditions, and every
// base is divided by its unoccluded value (unoccludedValue: 1 for B01..B18; 18 for B00 inside, 19
// on the boundary layer), so that each FloatGrid Bjj is the factor (1 = unoccluded) that scales an
// instance's fine light at run time. The coarse lattice keeps the dissertation's linear collision
// (interaction p = rho per coarse node): its nodes are metres wide and each plant's fine solution
// already holds its self-occlusion, which a Beer-Lambert coarse node inside the crown would count
// a second time (a crown's coarse node would be nearly opaque).
#include <cmath>
#include <limits>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "canopy/errors.h"
#include "canopy/lattice_dirs.h"
#include "formats/scene_json.h"
#include "lattice_io.h"
#include "lbsolve_internal.h"

namespace canopy::lb {
namespace {

struct Instance {
  int model = 0;
  openvdb::Mat4d m;  // model -> world, acting on row vectors (OpenVDB convention): p' = p * m
};

struct Scene {
  std::vector<std::string> densityPaths;
  std::vector<Instance> instances;
};

// The scene list (formats/scene_json.h reads and checks it) with OpenVDB matrices.
Scene readScene(const std::string& path) {
  const canopy::Scene list = readSceneJson(path);
  Scene s;
  for (const SceneModel& m : list.models) s.densityPaths.push_back(m.density);
  for (const SceneInstance& in : list.instances) {
    Instance I;
    I.model = int(in.model);
    // The list is row-major for column vectors (p' = A p); OpenVDB multiplies row vectors, so
    // its matrix is the transpose.
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) I.m[c][r] = in.matrix[size_t(4 * r + c)];
    s.instances.push_back(I);
  }
  return s;
}

// What base b holds at a node that nothing occludes (the normalisation of the scene lattice): a sun
// base 1 (its one direction arrives whole); B_0 19 on the boundary layer (its fixed f_0 = 1 too) and
// 18 inside, where f_0 is zeroed at every collision and the 18 moving populations arrive whole.
float unoccludedValue(int b, bool interior) { return b != 0 ? 1.f : interior ? float(kQ - 1) : float(kQ); }

// The coarse lattice over the scene: its dimensions, cell edge h and the world corner of node (0,0,0).
struct CoarseBox {
  Dims d;
  double h;
  openvdb::Vec3d origin;
};

// The coarse lattice's densities: coded per node (wood negative) for the solver, plain for the output.
struct CoarseDensity {
  DenseLattice coarse;
  std::vector<float> density;
};

// Lays the coarse lattice over the world bounding box of every instance's lattice box.
CoarseBox coarseBox(const LbsolveOptions& o, const Scene& scene, const std::vector<LoadedLattice>& models) {
  openvdb::Vec3d lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
  for (const auto& inst : scene.instances) {
    const auto& L = models[size_t(inst.model)];
    for (int c = 0; c < 8; ++c) {
      const openvdb::Vec3d idx((c & 1) ? L.meta.max.x() + 0.5 : L.meta.min.x() - 0.5,
                               (c & 2) ? L.meta.max.y() + 0.5 : L.meta.min.y() - 0.5,
                               (c & 4) ? L.meta.max.z() + 0.5 : L.meta.min.z() - 0.5);
      const openvdb::Vec3d w = inst.m.transform(L.transform->indexToWorld(idx));
      lo = openvdb::math::minComponent(lo, w);
      hi = openvdb::math::maxComponent(hi, w);
    }
  }
  const openvdb::Vec3d extent = hi - lo;
  const double h = std::max({extent.x(), extent.y(), extent.z()}) / o.sceneResolution;
  if (!(h > 0) || !std::isfinite(h)) throw invalidInput(o.scene + ": the scene has an empty bounding box");
  Dims d;
  d.nx = int(std::ceil(extent.x() / h - 1e-9)) + 2;
  d.ny = int(std::ceil(extent.y() / h - 1e-9)) + 2;
  d.nz = int(std::ceil(extent.z() / h - 1e-9)) + 2;
  d.nx = std::max(d.nx, 3), d.ny = std::max(d.ny, 3), d.nz = std::max(d.nz, 3);
  const openvdb::Vec3d origin = lo - openvdb::Vec3d(h);  // world position of node (0,0,0)'s corner
  return CoarseBox{d, h, origin};
}

// Coarse density: biomass of the instances in each coarse cell; wood where its share of the mass is.
CoarseDensity coarseDensity(const Scene& scene, const std::vector<LoadedLattice>& models, const CoarseBox& box,
                            double woodThreshold) {
  const Dims& d = box.d;
  const double h = box.h;
  const openvdb::Vec3d& origin = box.origin;
  std::vector<double> mass(size_t(d.count()), 0.0), woodMass(size_t(d.count()), 0.0);
  for (const auto& inst : scene.instances) {
    const auto& L = models[size_t(inst.model)];
    const openvdb::Vec3d vs = L.transform->voxelSize();
    const double fineVolume = vs.x() * vs.y() * vs.z() * std::abs(inst.m.det());
    const Dims& fd = L.dense.dims;
    for (int64_t i = 0; i < fd.count(); ++i) {
      const float rho = L.density[size_t(i)];
      if (rho == 0.f) continue;
      const openvdb::Coord c = nodeCoord(fd, L.meta.min, i);
      const openvdb::Vec3d w = inst.m.transform(L.transform->indexToWorld(c));
      const openvdb::Vec3d q = (w - origin) / h;
      const int x = std::clamp(int(std::floor(q.x())), 1, d.nx - 2);
      const int y = std::clamp(int(std::floor(q.y())), 1, d.ny - 2);
      const int z = std::clamp(int(std::floor(q.z())), 1, d.nz - 2);
      mass[size_t(d.index(x, y, z))] += rho * fineVolume;
      if (L.dense.coded[size_t(i)] < 0.f) woodMass[size_t(d.index(x, y, z))] += rho * fineVolume;
    }
  }
  CoarseDensity out;
  DenseLattice& coarse = out.coarse;
  coarse.dims = d;
  coarse.coded.resize(size_t(d.count()));
  std::vector<float>& density = out.density;
  density.resize(size_t(d.count()));
  const double cellVolume = h * h * h;
  for (size_t i = 0; i < density.size(); ++i) {
    density[i] = float(std::min(1.0, mass[i] / cellVolume));
    const bool wood = mass[i] > 0 && woodMass[i] / mass[i] >= woodThreshold;
    coarse.coded[i] = wood ? -density[i] : density[i];
  }
  coarse.stored.resize(size_t(d.count()));
  for (int64_t i = 0; i < d.count(); ++i) coarse.stored[size_t(i)] = i;
  return out;
}

// The 19 base solves on the coarse lattice: luminance only, with the linear collision (above).
void sceneSolves(const LbsolveOptions& o, const LightParams& params, const std::array<double, 3>& lum, int cap,
                 std::vector<SolveSpec>& specs, std::vector<LbsolveSolve>& labels) {
  const OmegaSet omega = makeOmegaSet(lum[0], lum[1], lum[2], params.gWood, 0.0);  // linear (above)
  for (int b = 0; b < kQ; ++b) {
    SolveSpec s;
    s.omega = omega;
    for (int m = 0; m < kQ; ++m) s.boundary[m] = (b == 0 || m == b) ? 1.f : 0.f;
    s.maxIterations = cap;
    s.tolerance = o.tolerance;
    s.checkEvery = o.checkEvery;
    specs.push_back(s);
    labels.push_back({lattice::baseName(b), 3});
  }
}

// The output grids: each base divided by its unoccluded value, then the coarse density.
openvdb::GridPtrVec sceneGrids(const LbsolveOptions& o, const CoarseBox& box, const std::vector<SolveResult>& results,
                               const std::vector<float>& density) {
  const Dims& d = box.d;
  const double h = box.h;
  vdbio::LatticeMeta meta;
  meta.min = openvdb::Coord(0);
  meta.max = openvdb::Coord(d.nx - 1, d.ny - 1, d.nz - 1);
  meta.source = vdbio::describeSource(o.scene);
  auto xform = openvdb::math::Transform::createLinearTransform(h);
  xform->postTranslate(box.origin + openvdb::Vec3d(0.5 * h));  // node centres
  openvdb::GridPtrVec grids;
  for (int b = 0; b < kQ; ++b) {
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName(lattice::baseName(b));
    g->setTransform(xform->copy());
    auto acc = g->getAccessor();
    for (int64_t i = 0; i < d.count(); ++i) {
      const openvdb::Coord c = nodeCoord(d, meta.min, i);
      acc.setValue(c, results[size_t(b)].values[size_t(i)] / unoccludedValue(b, d.interior(c.x(), c.y(), c.z())));
    }
    vdbio::stampGrid(*g, meta);
    g->insertMeta("canopy_direction", openvdb::Vec3IMetadata(openvdb::Vec3i(
                                          lattice::dir(b, 0), lattice::dir(b, 1), lattice::dir(b, 2))));
    g->insertMeta("canopy_iterations", openvdb::Int32Metadata(results[size_t(b)].iterations));
    g->insertMeta("canopy_residual", openvdb::FloatMetadata(results[size_t(b)].residual));
    grids.push_back(g);
  }
  auto dg = openvdb::FloatGrid::create(0.f);
  dg->setName("density");
  dg->setTransform(xform->copy());
  auto dacc = dg->getAccessor();
  for (int64_t i = 0; i < d.count(); ++i)
    if (density[size_t(i)] > 0.f) dacc.setValue(nodeCoord(d, meta.min, i), density[size_t(i)]);
  vdbio::stampGrid(*dg, meta);
  grids.push_back(dg);
  return grids;
}

}  // namespace

LbsolveReport solveScene(const LbsolveOptions& o) {
  LbsolveReport report;
  report.mode = "scene";
  report.params = resolveParams(o);
  report.params.beerLambert = false;  // the coarse lattice keeps the dissertation's collision (docs/lbsolve.md)
  report.device = o.device.str();
  vdbio::initialize();
  { AtomicOutput probe(o.output); }
  const Scene scene = readScene(o.scene);
  std::vector<LoadedLattice> models;
  for (const auto& p : scene.densityPaths) models.push_back(loadDensityLattice(p, report.params.woodThreshold));

  const CoarseBox box = coarseBox(o, scene, models);
  const Dims& d = box.d;
  const CoarseDensity cd = coarseDensity(scene, models, box, report.params.woodThreshold);
  report.dims = {d.nx, d.ny, d.nz};
  report.storedNodes = d.count();
  const int cap = iterationCap(o, d);
  logInfo(o.scene + ": " + std::to_string(scene.instances.size()) + " instances, coarse lattice " +
          std::to_string(d.nx) + "x" + std::to_string(d.ny) + "x" + std::to_string(d.nz) + ", cell " +
          std::to_string(box.h) + " m, cap " + std::to_string(cap) + " iterations");

  const auto lum = report.params.luminance();
  std::vector<SolveSpec> specs;
  std::vector<LbsolveSolve> labels;
  sceneSolves(o, report.params, lum, cap, specs, labels);
  auto results = runWithProgress(cd.coarse, specs, labels, o.device, report, parseCudaRun(o));
  const openvdb::GridPtrVec grids = sceneGrids(o, box, results, cd.density);

  openvdb::MetaMap fileMeta;
  stampRun(fileMeta, "scene", o, cap, report.params, report.solves);
  fileMeta.insertMeta("canopy_scene_resolution", openvdb::Int32Metadata(o.sceneResolution));
  fileMeta.insertMeta("canopy_scene_cell", openvdb::DoubleMetadata(box.h));
  fileMeta.insertMeta("canopy_luminance", openvdb::Vec3SMetadata(openvdb::Vec3s(float(lum[0]), float(lum[1]), float(lum[2]))));
  fileMeta.insertMeta("canopy_normalised", openvdb::BoolMetadata(true));
  vdbio::writeVdb(o.output, grids, fileMeta);
  return report;
}

}  // namespace canopy::lb
