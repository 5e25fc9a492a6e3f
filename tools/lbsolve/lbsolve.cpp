// lbsolve.cpp: canopy::lbsolve() (bases and sun modes; scene mode is in scene.cpp), the output
// file's metadata, and inspectLightFile() for `canopy-lbsolve info`.
#include "lbsolve.h"

#include <chrono>
#include <cmath>

#include <unistd.h>

#include "canopy/atomic_file.h"
#include "canopy/cli.h"
#include "canopy/errors.h"
#include "canopy/lattice_dirs.h"
#include "canopy/sun_lookup.h"
#include "beam.h"
#include "lattice_io.h"
#include "lbsolve_internal.h"

namespace canopy {
namespace lb {

int iterationCap(const LbsolveOptions& o, const Dims& d) {
  if (o.iterations > 0) return o.iterations;
  return 2 * std::max({d.nx, d.ny, d.nz});  // the dissertation's rule (§5.1, P1, P2)
}

void validateOptions(const LbsolveOptions& o) {
  if (o.output.empty()) throw usageError("no output file given (-o OUT.vdb)");
  if (o.scene.empty() && o.input.empty()) throw usageError("no input lattice given");
  if (!o.scene.empty() && o.sun) throw usageError("--scene and --sun cannot be combined");
  if (o.iterations < 0) throw usageError("--iterations must be >= 0");
  parseCudaRun(o);  // an unknown scheme fails before any work
  if (o.solvesPerGpu < 1 || o.solvesPerGpu > 64) throw usageError("--solves-per-gpu must lie in [1, 64]");
  if (!(o.tolerance >= 0.f) || !std::isfinite(o.tolerance)) throw usageError("--tolerance must be >= 0");
  if (o.tolerance == 0.f && o.iterations == 0)
    throw usageError("--tolerance 0 needs --iterations N (the number of iterations to run)");
  if (o.checkEvery < 1) throw usageError("--check-every must be >= 1");
  if (!(o.ambient >= 0.f) || !std::isfinite(o.ambient)) throw usageError("--ambient must be >= 0");
  if (o.sceneResolution < 1 || o.sceneResolution > 1024)
    throw usageError("--scene-resolution must lie in [1, 1024]");
  if (o.sun) {
    sun::Weights w;
    if (!sun::lookup((*o.sun)[0], (*o.sun)[1], (*o.sun)[2], w))
      throw usageError("--sun must be a non-zero, finite direction x,y,z");
  }
}

LightParams resolveParams(const LbsolveOptions& o) {
  LightParams p = o.paramsFile.empty() ? LightParams() : loadParams(o.paramsFile);
  if (o.woodThreshold) p.woodThreshold = *o.woodThreshold;
  if (o.sigma) p.sigma = *o.sigma;
  if (o.beerLambert) p.beerLambert = *o.beerLambert;
  p.validate(o.paramsFile.empty() ? "the options" : o.paramsFile);
  return p;
}

void stampParams(openvdb::MetaMap& m, const LightParams& p) {
  auto vec3 = [](const std::array<double, 3>& a) { return openvdb::Vec3s(float(a[0]), float(a[1]), float(a[2])); };
  m.insertMeta("canopy_sigma_a", openvdb::Vec3SMetadata(vec3(p.sigmaA)));
  m.insertMeta("canopy_sigma_s", openvdb::Vec3SMetadata(vec3(p.sigmaS)));
  m.insertMeta("canopy_g", openvdb::Vec3SMetadata(vec3(p.g)));
  m.insertMeta("canopy_wood_g", openvdb::FloatMetadata(float(p.gWood)));
  m.insertMeta("canopy_wood_threshold", openvdb::FloatMetadata(float(p.woodThreshold)));
  // sigma is a property of the Beer-Lambert collision only (the linear one, and the scene lattice,
  // never read it)
  if (p.beerLambert) m.insertMeta("canopy_sigma", openvdb::FloatMetadata(float(p.sigma)));
  m.insertMeta("canopy_collision", openvdb::StringMetadata(p.beerLambert ? "beer-lambert" : "linear"));
}

void stampRun(openvdb::MetaMap& m, const std::string& kind, const LbsolveOptions& o, int cap,
              const LightParams& p, const std::vector<LbsolveSolve>& solves) {
  m.insertMeta("canopy_kind", openvdb::StringMetadata(kind));
  stampParams(m, p);
  m.insertMeta("canopy_params", openvdb::StringMetadata(p.toJson().dump()));
  m.insertMeta("canopy_iteration_cap", openvdb::Int32Metadata(cap));
  m.insertMeta("canopy_tolerance", openvdb::FloatMetadata(o.tolerance));
  m.insertMeta("canopy_check_every", openvdb::Int32Metadata(o.checkEvery));
  // Convergence of every solve (no timings: the file's bytes must not depend on the machine).
  nlohmann::json conv = nlohmann::json::array();
  for (const auto& s : solves)
    conv.push_back({{"grid", s.grid}, {"channel", s.channel}, {"iterations", s.iterations}, {"residual", s.residual}});
  m.insertMeta("canopy_convergence", openvdb::StringMetadata(conv.dump()));
}

CudaRun parseCudaRun(const LbsolveOptions& o) {
  for (CudaScheme c : {CudaScheme::Shift, CudaScheme::ShiftSplit, CudaScheme::Push, CudaScheme::Pull})
    if (o.cudaScheme == cudaSchemeName(c)) {
      CudaRun run(c);
      run.solvesPerGpu = o.solvesPerGpu;
      return run;
    }
  throw usageError("--cuda-scheme must be shift, shift-split, push or pull, not '" + o.cudaScheme + "'");
}

OmegaSet channelOmega(const LightParams& p, int c) {
  return makeOmegaSet(p.sigmaA[c], p.sigmaS[c], p.g[c], p.gWood, p.beerLambert ? p.sigma : 0.0);
}

// Runs specs with a progress bar and a log line per solve; fills report.solves (names given).
std::vector<SolveResult> runWithProgress(const DenseLattice& lattice, const std::vector<SolveSpec>& specs,
                                         const std::vector<LbsolveSolve>& labels, const Device& device,
                                         LbsolveReport& report, const CudaRun& run) {
  static const char* kChannel[] = {"R", "G", "B", "L"};
  Progress progress("lbsolve " + std::to_string(specs.size()) + " solves", int64_t(specs.size()));
  auto results = runSolves(lattice, specs, device, [&](size_t k, const SolveResult& r) {
    progress.add();
    if (!isQuiet() && !isatty(2))
      logInfo(labels[k].grid + " " + kChannel[labels[k].channel] + ": " + std::to_string(r.iterations) +
              " iterations, residual " + std::to_string(r.residual) + ", " + std::to_string(r.seconds) + " s");
  }, run);
  progress.done();
  report.solves = labels;
  for (size_t k = 0; k < specs.size(); ++k) {
    report.solves[k].iterations = results[k].iterations;
    report.solves[k].residual = results[k].residual;
    report.solves[k].seconds = results[k].seconds;
    report.nodeUpdates += int64_t(results[k].iterations) * lattice.dims.count();
  }
  return results;
}

}  // namespace lb

namespace {
using namespace lb;

openvdb::Vec3SGrid::Ptr makeLightGrid(const std::string& name, const LoadedLattice& L,
                                      const std::vector<SolveResult>& rgb, size_t first) {
  auto grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
  grid->setName(name);
  grid->setTransform(L.transform->copy());
  auto acc = grid->getAccessor();
  const auto& stored = L.dense.stored;
  for (size_t k = 0; k < stored.size(); ++k)
    acc.setValue(nodeCoord(L.dense.dims, L.meta.min, stored[k]),
                 openvdb::Vec3s(rgb[first].values[k], rgb[first + 1].values[k], rgb[first + 2].values[k]));
  vdbio::stampGrid(*grid, L.meta);
  grid->insertMeta("canopy_iterations", openvdb::Vec3IMetadata(openvdb::Vec3i(
                                            rgb[first].iterations, rgb[first + 1].iterations, rgb[first + 2].iterations)));
  grid->insertMeta("canopy_residual", openvdb::Vec3SMetadata(openvdb::Vec3s(
                                          rgb[first].residual, rgb[first + 1].residual, rgb[first + 2].residual)));
  return grid;
}

// The solves of one plant: a spec per grid and channel, with its label.
struct PlantSolves {
  std::vector<SolveSpec> specs;
  std::vector<LbsolveSolve> labels;
  void add(const LbsolveOptions& o, const LightParams& params, int cap, const std::string& grid, int c,
           const float boundary[kQ]) {
    SolveSpec s;
    s.omega = channelOmega(params, c);
    for (int m = 0; m < kQ; ++m) s.boundary[m] = boundary[m];
    s.maxIterations = cap;
    s.tolerance = o.tolerance;
    s.checkEvery = o.checkEvery;
    specs.push_back(s);
    labels.push_back({grid, c});
  }
};

// Bases mode: the 19 bases x RGB, the sun bases less their direct beam unless --sun-bases total.
void solveBases(const LbsolveOptions& o, const LoadedLattice& L, int cap, LbsolveReport& report,
                openvdb::GridPtrVec& grids) {
  PlantSolves solves;
  report.mode = "bases";
  for (int b = 0; b < kQ; ++b) {
    float boundary[kQ];
    for (int m = 0; m < kQ; ++m) boundary[m] = (b == 0 || m == b) ? 1.f : 0.f;  // §4.2
    for (int c = 0; c < 3; ++c) solves.add(o, report.params, cap, lattice::baseName(b), c, boundary);
  }
  const std::vector<SolveSpec>& specs = solves.specs;
  auto results = runWithProgress(L.dense, specs, solves.labels, o.device, report, parseCudaRun(o));
  report.sunBases = o.scatteredSunBases ? "scattered" : "total";
  if (o.scatteredSunBases) {
    // B_j - U_j: the light of the sun bases that was scattered at least once (beam.h).
    Progress progress("lbsolve direct beams", int64_t(specs.size() - 3));
    for (size_t k = 3; k < specs.size(); ++k) {
      const std::vector<float> beam =
          directBeam(L.dense, specs[k].omega, int(k / 3), results[k].iterations, specs[k].boundary[k / 3]);
      std::vector<float>& v = results[k].values;
      for (size_t i = 0; i < v.size(); ++i) v[i] = std::max(0.0f, v[i] - beam[i]);
      progress.add();
    }
    progress.done();
  }
  for (int b = 0; b < kQ; ++b) {
    auto g = makeLightGrid(lattice::baseName(b), L, results, size_t(3 * b));
    g->insertMeta("canopy_direction", openvdb::Vec3IMetadata(openvdb::Vec3i(
                                          lattice::dir(b, 0), lattice::dir(b, 1), lattice::dir(b, 2))));
    // B00 (ambient) keeps the sky's unscattered light: the player has no other sky term.
    g->insertMeta(vdbio::kDirectBeamMeta, openvdb::BoolMetadata(b == 0 || !o.scatteredSunBases));
    stampParams(*g, report.params);
    grids.push_back(g);
  }
}

// Sun mode: one static bake of the --sun direction plus --ambient, RGB.
void solveSun(const LbsolveOptions& o, const LoadedLattice& L, int cap, LbsolveReport& report,
              openvdb::GridPtrVec& grids) {
  PlantSolves solves;
  report.mode = "sun";
  const auto& s = *o.sun;
  sun::Weights w;
  sun::lookup(s[0], s[1], s[2], w);
  float boundary[kQ];
  for (int m = 0; m < kQ; ++m) boundary[m] = o.ambient;
  for (int k = 0; k < 3; ++k) boundary[w.base[k]] += w.weight[k];
  for (int c = 0; c < 3; ++c) solves.add(o, report.params, cap, "light", c, boundary);
  auto results = runWithProgress(L.dense, solves.specs, solves.labels, o.device, report, parseCudaRun(o));
  auto g = makeLightGrid("light", L, results, 0);
  g->insertMeta("canopy_sun", openvdb::Vec3SMetadata(openvdb::Vec3s(s[0], s[1], s[2])));
  g->insertMeta("canopy_sun_bases", openvdb::Vec3IMetadata(openvdb::Vec3i(w.base[0], w.base[1], w.base[2])));
  g->insertMeta("canopy_sun_weights", openvdb::Vec3SMetadata(openvdb::Vec3s(w.weight[0], w.weight[1], w.weight[2])));
  g->insertMeta("canopy_ambient", openvdb::FloatMetadata(o.ambient));
  g->insertMeta(vdbio::kDirectBeamMeta, openvdb::BoolMetadata(true));  // a static bake: all of the light
  stampParams(*g, report.params);
  grids.push_back(g);
}

LbsolveReport solvePlant(const LbsolveOptions& o) {
  LbsolveReport report;
  report.params = resolveParams(o);
  report.device = o.device.str();
  vdbio::initialize();
  // Reserve the output first: an unwritable destination fails before any work is done.
  { AtomicOutput probe(o.output); }
  LoadedLattice L = loadDensityLattice(o.input, report.params.woodThreshold);
  const Dims d = L.dense.dims;
  report.dims = {d.nx, d.ny, d.nz};
  report.storedNodes = int64_t(L.dense.stored.size());
  const int cap = iterationCap(o, d);
  logInfo(o.input + ": lattice " + std::to_string(d.nx) + "x" + std::to_string(d.ny) + "x" + std::to_string(d.nz) +
          ", " + std::to_string(L.dense.stored.size()) + " stored nodes, cap " + std::to_string(cap) +
          " iterations, device " + o.device.str());

  openvdb::GridPtrVec grids;
  openvdb::MetaMap fileMeta;
  if (!o.sun) {
    solveBases(o, L, cap, report, grids);
  } else {
    solveSun(o, L, cap, report, grids);
  }
  stampRun(fileMeta, report.mode, o, cap, report.params, report.solves);
  if (!report.sunBases.empty()) fileMeta.insertMeta("canopy_sun_terms", openvdb::StringMetadata(report.sunBases));
  vdbio::writeVdb(o.output, grids, fileMeta);
  return report;
}
}  // namespace

LbsolveReport lbsolve(const LbsolveOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  lb::validateOptions(o);
  LbsolveReport r = o.scene.empty() ? solvePlant(o) : lb::solveScene(o);
  r.seconds = secondsSince(t0);
  return r;
}

nlohmann::json LbsolveReport::toJson() const {
  nlohmann::json s = nlohmann::json::array();
  static const char* kChannel[] = {"R", "G", "B", "L"};
  for (const auto& x : solves)
    s.push_back({{"grid", x.grid}, {"channel", kChannel[x.channel]}, {"iterations", x.iterations},
                 {"residual", x.residual}, {"seconds", x.seconds}});
  nlohmann::json j = {{"mode", mode},
          {"lattice", dims},
          {"stored_nodes", storedNodes},
          {"node_updates", nodeUpdates},
          {"node_updates_per_second", seconds > 0 ? double(nodeUpdates) / seconds : 0.0},
          {"device", device},
          {"params", params.toJson()},
          {"solves", s},
          {"seconds", seconds}};
  if (!sunBases.empty()) j["sun_bases"] = sunBases;
  return j;
}

// ---- info ------------------------------------------------------------------------------------

nlohmann::json LightFileInfo::toJson() const {
  return {{"kind", kind}, {"lattice_min", latticeMin}, {"lattice_max", latticeMax},
          {"grids", grids}, {"active_voxels", activeVoxels}, {"metadata", metadata}};
}

namespace {
nlohmann::json metaToJson(const openvdb::MetaMap& m) {
  nlohmann::json j = nlohmann::json::object();
  for (auto it = m.beginMeta(); it != m.endMeta(); ++it) {
    if (it->first.rfind("canopy_", 0) != 0) continue;
    const std::string v = it->second->str();
    if (it->first == "canopy_convergence" || it->first == "canopy_params") {
      j[it->first] = nlohmann::json::parse(v, nullptr, false);
    } else {
      j[it->first] = v;
    }
  }
  return j;
}
}  // namespace

LightFileInfo inspectLightFile(const std::string& path) {
  const vdbio::VdbFile f = vdbio::readVdb(path);
  LightFileInfo info;
  vdbio::LatticeMeta lattice;
  auto checkLattice = [&](const openvdb::GridBase& g, bool first) {
    const vdbio::LatticeMeta m = vdbio::readLatticeMeta(g, path);
    if (first) lattice = m;
    else if (m.min != lattice.min || m.max != lattice.max)
      throw invalidInput(path + ": grid '" + g.getName() + "' has other lattice bounds than '" + info.grids[0] + "'");
  };
  if (f.find("B00")) {
    const bool scalar = bool(openvdb::gridPtrCast<openvdb::FloatGrid>(f.find("B00")));
    info.kind = scalar ? "scene" : "bases";
    for (int b = 0; b < lattice::kQ; ++b) {
      const std::string name = lattice::baseName(b);
      openvdb::GridBase::Ptr g = scalar ? openvdb::GridBase::Ptr(f.require<openvdb::FloatGrid>(name))
                                        : openvdb::GridBase::Ptr(f.require<openvdb::Vec3SGrid>(name));
      checkLattice(*g, b == 0);
      auto dir = g->getMetadata<openvdb::Vec3IMetadata>("canopy_direction");
      const openvdb::Vec3i want(lattice::dir(b, 0), lattice::dir(b, 1), lattice::dir(b, 2));
      if (!dir || dir->value() != want)
        throw invalidInput(path + ": grid '" + name + "' lacks canopy_direction " + want.str());
      info.grids.push_back(name);
    }
    info.activeVoxels = int64_t(f.find("B00")->activeVoxelCount());
  } else if (f.find("light")) {
    info.kind = "sun";
    auto g = f.require<openvdb::Vec3SGrid>("light");
    checkLattice(*g, true);
    if (!g->getMetadata<openvdb::Vec3SMetadata>("canopy_sun"))
      throw invalidInput(path + ": grid 'light' lacks canopy_sun metadata");
    info.grids.push_back("light");
    info.activeVoxels = int64_t(g->activeVoxelCount());
  } else {
    throw invalidInput(path + ": not a Canopy light file (no grids B00..B18 or 'light')");
  }
  info.latticeMin = {lattice.min.x(), lattice.min.y(), lattice.min.z()};
  info.latticeMax = {lattice.max.x(), lattice.max.y(), lattice.max.z()};
  if (f.meta) info.metadata = metaToJson(*f.meta);
  if (!info.metadata.contains("canopy_convergence"))
    throw invalidInput(path + ": no canopy_convergence metadata (not written by canopy-lbsolve)");
  return info;
}

}  // namespace canopy
