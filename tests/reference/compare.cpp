// compare.cpp: see compare.h.
#include "tests/reference/compare.h"

#include <chrono>
#include <filesystem>
#include <cmath>
#include <cstdlib>
#include <sys/stat.h>

#include "canopy/errors.h"
#include "formats/canopy_file.h"
#include "formats/scene_json.h"
#include "lbsolve.h"
#include "runtime/image_io.h"
#include "runtime/affine.h"
#include "runtime/player.h"
#include "runtime/scene.h"
#include "tools/octreepack/inputs.h"
#include "tools/octreepack/octreepack.h"
#include "voxelize.h"

namespace canopy::reference {
namespace {

using play::M34;
using play::compose;
using play::det3;

double seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

Volume volumeOf(const octreepack::ModelSource& s) {
  Volume v;
  for (int a = 0; a < 3; ++a) {
    v.min[a] = s.latticeMin[a];
    v.dim[a] = s.latticeMax[a] - s.latticeMin[a] + 1;
  }
  const size_t n = size_t(v.dim[0]) * v.dim[1] * v.dim[2];
  v.density.assign(n, 0.0f);
  v.wood.assign(n, 0.0f);
  v.albedo.assign(3 * n, 0.0f);
  for (const octreepack::SourceCell& c : s.cells) {
    const size_t i = v.cell(c.ijk[0] - v.min[0], c.ijk[1] - v.min[1], c.ijk[2] - v.min[2]);
    v.density[i] = c.density;
    v.wood[i] = c.wood;
    for (int ch = 0; ch < 3; ++ch) v.albedo[3 * i + size_t(ch)] = c.albedo[ch];
  }
  v.finish();
  return v;
}

LbMaterial lbMaterial(const lb::LightParams& p) {
  LbMaterial m;
  for (int c = 0; c < 3; ++c) {
    m.sigmaA[c] = float(p.sigmaA[size_t(c)]);
    m.sigmaS[c] = float(p.sigmaS[size_t(c)]);
    m.g[c] = float(p.g[size_t(c)]);
  }
  m.gWood = float(p.gWood);
  m.woodThreshold = float(p.woodThreshold);
  return m;
}

void makeDir(const std::string& d) {
  const std::string cmd = "mkdir -p '" + d + "'";
  if (std::system(cmd.c_str()) != 0) throw ioError("reference: cannot create " + d);
}

std::array<double, 16> yawScaleTranslate(double yawDeg, double scale, double x, double y, double z) {
  const double a = yawDeg * M_PI / 180.0, c = std::cos(a) * scale, s = std::sin(a) * scale;
  return {c, 0, s, x, 0, scale, 0, y, -s, 0, c, z, 0, 0, 0, 1};
}

}  // namespace

Medium mediumFromCanopy(const std::string& canopyPath, const std::vector<octreepack::ModelSource>& models, float sigma) {
  const CanopyFile f = CanopyFile::open(canopyPath);
  if (f.modelCount() != models.size()) throw invalidInput(canopyPath + ": model count differs from the reference's lattices");
  Medium m;
  m.sigma = sigma;
  m.lb = lbMaterial(lb::LightParams{});
  std::vector<M34> i2m(models.size());
  for (uint32_t k = 0; k < f.modelCount(); ++k) {
    const CanopyModel& M = f.model(k);
    for (int a = 0; a < 3; ++a)
      if (M.latticeMin[a] != models[k].latticeMin[a] || M.latticeMax[a] != models[k].latticeMax[a])
        throw invalidInput(canopyPath + ": model " + std::to_string(k) + "'s lattice differs from the reference's");
    for (int e = 0; e < 12; ++e) i2m[k][size_t(e)] = M.indexToModel[e];
    m.volumes.push_back(volumeOf(models[k]));
  }
  for (uint32_t i = 0; i < f.instanceCount(); ++i) {
    const CanopyInstance& I = f.instance(i);
    M34 m2w;
    for (int e = 0; e < 12; ++e) m2w[size_t(e)] = I.modelToWorld[e];
    const M34 l2w = compose(m2w, i2m[I.model]);  // as runtime/scene.cpp composes it
    const M34 w2l = play::invert(l2w, "reference: instance transform");
    Instance in;
    in.volume = I.model;
    for (int e = 0; e < 12; ++e) in.worldToIndex[e] = w2l[size_t(e)];
    in.cellWorld = float(std::cbrt(std::fabs(det3(l2w))));
    m.instances.push_back(in);
  }
  return m;
}

Prepared prepareScenes(const PrepareOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  makeDir(options.workDir);
  // absolute: the scene lists written below name their lattices relative to themselves
  PrepareOptions o = options;
  o.workDir = std::filesystem::absolute(o.workDir).lexically_normal().string();
  const std::string density = o.workDir + "/plant.density.vdb", light = o.workDir + "/plant.light.vdb";
  VoxelizeOptions vo;
  vo.input = o.mesh;
  vo.output = density;
  vo.resolution = o.resolution;
  const VoxelizeResult vr = voxelize(vo);
  LbsolveOptions lo;
  lo.input = density;
  lo.output = light;
  lbsolve(lo);  // 19 bases, scattered sun bases (the default), CPU
  const octreepack::ModelSource model = octreepack::readDensityVdb(density, "plant");

  Prepared p;
  p.plant.name = "plant";
  p.plant.canopyPath = o.workDir + "/plant.canopy";
  {
    octreepack::OctreepackOptions po;
    po.inputs = {density, light};
    po.output = p.plant.canopyPath;
    octreepack::octreepack(po);
  }
  p.plant.unlitCanopyPath = o.workDir + "/plant-unlit.canopy";
  {
    octreepack::OctreepackOptions po;
    po.inputs = {density};
    po.output = p.plant.unlitCanopyPath;
    octreepack::octreepack(po);
  }
  p.plant.models = {model};
  p.plant.medium = mediumFromCanopy(p.plant.canopyPath, p.plant.models, o.sigma);

  // Three trees, each rotated about +y and scaled differently, crowns close enough to shade and
  // overlap each other (extent = the lattice's edge in metres).
  const double e = vr.frame.voxelSize * vr.frame.resolution;
  Scene sc;
  sc.models.push_back({"plant", density, light, -1});
  sc.instances.push_back({0, "a", yawScaleTranslate(0.0, 1.0, -0.45 * e, 0.0, 0.0)});
  sc.instances.push_back({0, "b", yawScaleTranslate(75.0, 0.8, 0.42 * e, 0.0, 0.2 * e)});
  sc.instances.push_back({0, "c", yawScaleTranslate(200.0, 1.2, 0.05 * e, 0.0, -0.6 * e)});
  const std::string sceneJson = o.workDir + "/trees.scene.json", sceneLight = o.workDir + "/trees.scene-light.vdb";
  writeSceneJson(sceneJson, sc);
  {
    LbsolveOptions so;
    so.scene = sceneJson;
    so.output = sceneLight;
    so.sceneResolution = o.sceneResolution;
    lbsolve(so);
  }
  p.trees.name = "3 trees";
  p.trees.canopyPath = o.workDir + "/trees.canopy";
  {
    octreepack::OctreepackOptions po;
    po.scene = sceneJson;
    po.sceneLight = sceneLight;
    po.output = p.trees.canopyPath;
    octreepack::octreepack(po);
  }
  p.trees.unlitCanopyPath = o.workDir + "/trees-unlit.canopy";
  {
    Scene unlit = sc;
    unlit.models[0].light.clear();
    const std::string unlitJson = o.workDir + "/trees-unlit.scene.json";
    writeSceneJson(unlitJson, unlit);
    octreepack::OctreepackOptions po;
    po.scene = unlitJson;
    po.output = p.trees.unlitCanopyPath;
    octreepack::octreepack(po);
  }
  p.trees.models = {model};
  p.trees.medium = mediumFromCanopy(p.trees.canopyPath, p.trees.models, o.sigma);
  p.seconds = seconds(t0);
  return p;
}

CaseResult compareCase(const PreparedScene& scene, const CaseOptions& o) {
  play::PlayOptions po;
  po.input = o.directOnly ? scene.unlitCanopyPath : scene.canopyPath;
  po.width = o.width;
  po.height = o.height;
  po.camera = o.camera;
  char sun[96];
  std::snprintf(sun, sizeof sun, "orbit:azimuth=%g,elevation=%g", o.sunAzimuth, o.sunElevation);
  po.sun = sun;
  po.sigma = scene.medium.sigma;
  po.shadowMethod = o.shadows;
  po.converge = true;
  po.ground = "none";  // the path tracer's medium has no ground
  po.sunIntensity = o.playerSunScale;
  if (o.directOnly) po.ambient = 0.0f;
  if (o.indirectOnly) po.directSun = false;
  if (o.tweakPlayer) o.tweakPlayer(po);
  CaseResult r;
  auto t0 = std::chrono::steady_clock::now();
  play::play(po, Device{}, &r.play);
  r.playSeconds = seconds(t0);

  // the player's own camera and sun for this frame
  const CanopyFile file = CanopyFile::open(scene.canopyPath);
  const play::HostScene hs = play::buildScene(file);
  const play::FrameSetup fs = play::framePlan(po, hs)[0];
  Lighting L;
  L.toSun = fs.toSun;
  for (float& s : L.sun) s = 1.0f;  // canopy-play's default --sun-intensity (the player's may be scaled: controls)
  L.ambient = po.ambient;
  std::vector<float> var;
  TraceOptions trace = o.trace;
  trace.firstVertexOnly = trace.firstVertexOnly || o.directOnly;
  trace.noCameraSun = trace.noCameraSun || o.indirectOnly;
  t0 = std::chrono::steady_clock::now();
  r.mc = renderReference(scene.medium, L, fs.camera, trace, &var);
  r.mcSeconds = seconds(t0);

  const size_t px = size_t(o.width) * o.height;
  double normSum = 0, se = 0, sv = 0, sa = 0, sp = 0, sm = 0;
  for (size_t i = 0; i < px; ++i) {
    const float* a = &r.play[4 * i];
    const float* b = &r.mc[4 * i];
    if (a[3] > 0.05f) {
      normSum += (a[0] + a[1] + a[2]) / 3.0;
      ++r.coveredPixels;
    }
    for (int c = 0; c < 3; ++c) {
      se += double(a[c] - b[c]) * (a[c] - b[c]);
      sv += var[3 * i + size_t(c)];
      sp += a[c];
      sm += b[c];
    }
    sa += double(a[3] - b[3]) * (a[3] - b[3]);
  }
  r.norm = r.coveredPixels > 0 ? normSum / r.coveredPixels : 0.0;
  r.rms = r.norm > 0 ? std::sqrt(se / double(3 * px)) / r.norm : 0.0;
  r.noise = r.norm > 0 ? std::sqrt(sv / double(3 * px)) / r.norm : 0.0;
  r.alphaRms = std::sqrt(sa / double(px));
  r.meanPlay = sp / double(3 * px);
  r.meanMc = sm / double(3 * px);
  r.meanRatio = sm > 0 ? sp / sm : 0.0;
  if (o.secondSeed != 0) {
    TraceOptions t2 = trace;
    t2.seed = o.secondSeed;
    const std::vector<float> mc2 = renderReference(scene.medium, L, fs.camera, t2);
    double s2 = 0;
    for (size_t i = 0; i < px; ++i)
      for (int c = 0; c < 3; ++c) s2 += double(r.mc[4 * i + size_t(c)] - mc2[4 * i + size_t(c)]) * (r.mc[4 * i + size_t(c)] - mc2[4 * i + size_t(c)]);
    r.noiseTwoSeeds = r.norm > 0 ? std::sqrt(s2 / double(3 * px) / 2.0) / r.norm : 0.0;
  }
  if (!o.exrPrefix.empty()) {
    play::writeExr(o.exrPrefix + ".mc.exr", r.mc, o.width, o.height);
    play::writeExr(o.exrPrefix + ".play.exr", r.play, o.width, o.height);
    const float bg[3] = {0.60f, 0.72f, 0.85f};
    play::writePng(o.exrPrefix + ".mc.png", r.mc, o.width, o.height, bg);
    play::writePng(o.exrPrefix + ".play.png", r.play, o.width, o.height, bg);
  }
  return r;
}

}  // namespace canopy::reference
