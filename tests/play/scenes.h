// scenes.h: .canopy test scenes built in-process with the octreepack builder and writer
// (canopy_octree), for the player's tests and benchmark.
#pragma once
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "canopy/lattice_dirs.h"
#include "formats/canopy_write.h"
#include "formats/chaar.h"
#include "formats/haar_encode.h"
#include "tools/octreepack/octree_build.h"

namespace canopy::play::testing {

// A ball of uniform density: every lattice cell whose centre lies within `radius` cells of the
// lattice centre, in a lattice of `edge` cells per axis with one cell = `cell` metres, centred on
// the model origin.
inline octreepack::ModelSource sphereModel(int edge, float radius, float density, float cell = 0.1f,
                                           const float albedo[3] = nullptr) {
  octreepack::ModelSource s;
  s.name = "sphere";
  s.sourceLabel = "synthetic:sphere";
  for (int a = 0; a < 3; ++a) s.latticeMin[a] = 0, s.latticeMax[a] = edge - 1;
  const double c = 0.5 * (edge - 1);
  s.indexToModel = {cell, 0, 0, -c * cell, 0, cell, 0, -c * cell, 0, 0, cell, -c * cell};
  const float alb[3] = {albedo ? albedo[0] : 0.5f, albedo ? albedo[1] : 0.5f, albedo ? albedo[2] : 0.5f};
  for (int k = 0; k < edge; ++k)
    for (int j = 0; j < edge; ++j)
      for (int i = 0; i < edge; ++i) {
        const double x = i - c, y = j - c, z = k - c;
        if (x * x + y * y + z * z >= double(radius) * radius) continue;
        s.cells.push_back({{i, j, k}, density, 0.0f, {alb[0], alb[1], alb[2]}});
      }
  return s;
}

// A translation(+ uniform scale, + rotation about y) instance.
inline CanopyInstance instanceAt(uint32_t model, float x, float y, float z, float scale = 1.0f, float yawRad = 0.0f) {
  CanopyInstance in{};
  const float c = std::cos(yawRad) * scale, s = std::sin(yawRad) * scale;
  const float m[12] = {c, 0, s, x, 0, scale, 0, y, -s, 0, c, z};
  for (int i = 0; i < 12; ++i) in.modelToWorld[i] = m[i];
  in.model = model;
  return in;
}

// RMS difference of two images (all their floats: RGBA).
inline double imageRms(const std::vector<float>& a, const std::vector<float>& b) {
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += double(a[i] - b[i]) * (a[i] - b[i]);
  return std::sqrt(s / double(a.size()));
}

// Builds every model and writes `path` (raw pages, or compressed: kCanopyPageZstd).
inline void writeScene(const std::string& path, const std::vector<octreepack::ModelSource>& sources,
                       const std::vector<CanopyInstance>& instances, uint32_t pageCoding = kCanopyPageRaw) {
  std::vector<octreepack::BuiltModel> built;
  built.reserve(sources.size());
  for (const auto& s : sources) built.push_back(octreepack::buildOctree(s, s.name));
  CanopyWriteInput w;
  for (auto& b : built) w.models.push_back({b.record, &b.tiles, &b.bricks});
  w.instances = instances;
  w.metadata = "{\"tool\":\"tests/play\"}";
  w.pageCoding = pageCoding;
  writeCanopyFile(path, std::move(w));
}

// A coarse scene light as the writer takes it (CanopyWriteInput): 1 base (B00) or 19 (B00..B18),
// base-major.
struct SceneLightData {
  CanopySceneLight header{};
  uint32_t bases = 1;
  std::vector<float> values;
};

// Builds every model with its lighting (lights[m] may be null: density only; the octreepack
// builder makes the light items, canopy_layout.h's "Light pages") and writes `path`.
// scatteredSun: the lit models are flagged kCanopyModelScatteredSun, as canopy-octreepack flags
// canopy-lbsolve's default output (sun bases without their direct beam); false: beam included.
// sceneLight: an optional coarse scene light (lbsolve --scene's bases).
inline void writeLitScene(const std::string& path, const std::vector<octreepack::ModelSource>& sources,
                          const std::vector<octreepack::LightFn>& lights, const std::vector<CanopyInstance>& instances,
                          bool scatteredSun = true, const SceneLightData* sceneLight = nullptr) {
  std::vector<octreepack::BuiltModel> built;
  built.reserve(sources.size());
  for (size_t m = 0; m < sources.size(); ++m) {
    built.push_back(octreepack::buildOctree(sources[m], sources[m].name, m < lights.size() ? lights[m] : nullptr));
    if (scatteredSun) built.back().record.flags |= kCanopyModelScatteredSun;  // the writer drops it on unlit models
  }
  CanopyWriteInput w;
  for (auto& b : built) w.models.push_back({b.record, &b.tiles, &b.bricks, &b.light});
  w.instances = instances;
  if (sceneLight) {
    w.hasSceneLight = true;
    w.sceneLight = sceneLight->header;
    w.sceneLightBases = sceneLight->bases;
    w.sceneLightValues = sceneLight->values;
  }
  w.metadata = "{\"tool\":\"tests/play\"}";
  writeCanopyFile(path, std::move(w));
}

// The lighting `light` of a model as a .chaar (every lattice cell, 19 bases, Haar threshold T,
// `precision`): what canopy-haar makes of canopy-lbsolve's output.
inline haar::ChaarData chaarOf(const octreepack::ModelSource& src, const octreepack::LightFn& light, float T, haar::Precision precision) {
  const haar::LatticeGeom g = haar::LatticeGeom::fromBounds(src.latticeMin, src.latticeMax, src.name);
  std::vector<haar::DenseLight> bases(kCanopyLightBases);
  for (auto& b : bases) b.rgb.assign(3 * g.cells, 0.0f);
  std::vector<float> v(kCanopyLightChannels);
  size_t cell = 0;
  for (int32_t k = src.latticeMin[2]; k <= src.latticeMax[2]; ++k)
    for (int32_t j = src.latticeMin[1]; j <= src.latticeMax[1]; ++j)
      for (int32_t i = src.latticeMin[0]; i <= src.latticeMax[0]; ++i, ++cell) {
        light(i, j, k, v.data());
        for (uint32_t b = 0; b < kCanopyLightBases; ++b)
          for (int ch = 0; ch < 3; ++ch) bases[b].rgb[3 * cell + size_t(ch)] = v[3 * b + size_t(ch)];
      }
  haar::ChaarAssembly a;
  a.geom = g;
  a.precision = precision;
  a.threshold = T;
  for (uint32_t b = 0; b < kCanopyLightBases; ++b) {
    bases[b].activeVoxels = g.cells;
    const haar::LiftedBase lifted(g, bases[b], precision, src.name + " B" + std::to_string(b));
    a.codes.push_back(lifted.encode(T));
    a.directions.push_back({lattice::dir(int(b), 0), lattice::dir(int(b), 1), lattice::dir(int(b), 2)});
    a.valueMax.push_back(lifted.valueMax());
  }
  return haar::assembleChaar(a);
}

// The model on a detail lattice 2^levels times finer (canopy-voxelize --detail's nesting): every
// cell becomes 2^levels per axis with the same values, the transform scaled about the box corner
// (light cell c centred at the detail index point 2^n c + (2^n - 1) / 2).
inline octreepack::ModelSource detailOf(const octreepack::ModelSource& src, uint32_t levels) {
  octreepack::ModelSource d = src;
  const int f = 1 << levels;
  d.detailLevels = levels;
  for (int a = 0; a < 3; ++a) d.latticeMin[a] = src.latticeMin[a] * f, d.latticeMax[a] = src.latticeMax[a] * f + f - 1;
  const double c0 = -0.5 * (f - 1) / f;  // D(p) = L(p / f + c0)
  for (int r = 0; r < 3; ++r) {
    const double* L = &src.indexToModel[size_t(r * 4)];
    d.indexToModel[size_t(r * 4 + 3)] = L[3] + c0 * (L[0] + L[1] + L[2]);
    for (int a = 0; a < 3; ++a) d.indexToModel[size_t(r * 4 + a)] = L[a] / f;
  }
  d.cells.clear();
  for (const auto& c : src.cells)
    for (int z = 0; z < f; ++z)
      for (int y = 0; y < f; ++y)
        for (int x = 0; x < f; ++x) d.cells.push_back({{c.ijk[0] * f + x, c.ijk[1] * f + y, c.ijk[2] * f + z}, c.density, c.wood, {c.albedo[0], c.albedo[1], c.albedo[2]}});
  return d;
}

// writeLitScene with each model's lighting Haar-compressed first (chaarOf), as canopy-octreepack
// packs PLANT.light.chaar: light items of its decoded values on every level, and its bricks
// as Haar pages (the finest level's exact light, canopy-play --light exact).
inline void writeHaarLitScene(const std::string& path, const std::vector<octreepack::ModelSource>& sources,
                              const std::vector<octreepack::LightFn>& lights, const std::vector<CanopyInstance>& instances, float T,
                              haar::Precision precision, const SceneLightData* sceneLight = nullptr, uint32_t detailLevels = 0) {
  std::vector<octreepack::BuiltModel> built;
  std::vector<CanopyHaarPages> pages(sources.size());
  built.reserve(sources.size());
  for (size_t m = 0; m < sources.size(); ++m) {
    const haar::ChaarData chaar = chaarOf(sources[m], lights[m], T, precision);
    pages[m] = canopyHaarPagesFromChaar(chaar);
    // detailLevels > 0: the geometry on a detail lattice (detailOf), lit from this light lattice
    built.push_back(octreepack::buildOctree(detailLevels ? detailOf(sources[m], detailLevels) : sources[m], sources[m].name,
                                            octreepack::chaarLightFn(chaar.view())));
    built.back().record.flags |= kCanopyModelScatteredSun;
  }
  CanopyWriteInput w;
  for (size_t m = 0; m < built.size(); ++m) w.models.push_back({built[m].record, &built[m].tiles, &built[m].bricks, &built[m].light, &pages[m]});
  w.instances = instances;
  if (sceneLight) {
    w.hasSceneLight = true;
    w.sceneLight = sceneLight->header;
    w.sceneLightBases = sceneLight->bases;
    w.sceneLightValues = sceneLight->values;
  }
  w.metadata = "{\"tool\":\"tests/play\"}";
  writeCanopyFile(path, std::move(w));
}

// Lighting whose base j is (j + 1) * rgb[c] * (1 + gradient * i / edge): constant per base when
// gradient = 0 (every light level then holds exactly these values), else varying along lattice x.
inline octreepack::LightFn rampLight(const float rgb[3], float gradient = 0.0f, int edge = 1, float scale = 1.0f) {
  const float c[3] = {rgb[0], rgb[1], rgb[2]};
  return [c, gradient, edge, scale](int32_t i, int32_t, int32_t, float* out) {
    const float g = 1.0f + gradient * float(i) / float(edge);
    for (int b = 0; b < 19; ++b)
      for (int ch = 0; ch < 3; ++ch) out[3 * b + ch] = scale * float(b + 1) * c[ch] * g;
  };
}

inline std::string tmpDir(const char* sub) {
  const std::string d = std::string(CANOPY_BINARY_DIR) + "/tests/play/tmp/" + sub;
  const std::string cmd = "mkdir -p '" + d + "'";
  if (std::system(cmd.c_str()) != 0) std::abort();
  return d;
}

}  // namespace canopy::play::testing
