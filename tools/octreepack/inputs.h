// inputs.h: canopy-octreepack's inputs -> plain structures (the only OpenVDB code of the tool).
//   readDensityVdb:     a density lattice (formats/density_lattice.h reads and validates it)
//   readSceneLightVdb:  the coarse scene lighting lattice (lbsolve --scene): its 19 bases, or one grid
// Every failure is a canopy::Error naming the file.
#pragma once
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "formats/canopy_file.h"
#include "formats/canopy_write.h"
#include "tools/octreepack/octree_build.h"

namespace canopy::octreepack {

ModelSource readDensityVdb(const std::string& path, const std::string& name);

// The uncompressed lighting of canopy-lbsolve (19 Vec3 grids B00..B18, lattice index space) as a
// LightFn (the value stored at each cell; the grids' background elsewhere). Where the grids carry
// the §0 lattice metadata, it must equal `model`'s lattice.
struct LightVdb {
  LightFn fn;
  std::string sourceLabel;
  // .chaar only (withHaar): its bricks re-paged as Haar light, the finest level's exact light.
  std::shared_ptr<const CanopyHaarPages> haar;
  // The sun bases B01..B18 hold only scattered light (lbsolve's default: grid metadata
  // canopy_direct_beam = false, or the .chaar's kChaarBaseScattered); packed as
  // kCanopyModelScatteredSun. All 18 must agree (else InvalidInput).
  bool scatteredSun = false;
};
LightVdb readLightVdb(const std::string& path, const ModelSource& model);

// Compressed lighting from canopy-haar (.chaar, 19 bases): fn samples it through the chaar decoder
// at every lattice cell (0 outside the lattice; chaarLightFn) for the light items, and with
// withHaar its bricks become Haar pages. Its lattice must equal `model`'s.
LightVdb readChaarLight(const std::string& path, const ModelSource& model, bool withHaar = true);

struct SceneLightSource {
  CanopySceneLight header{};
  uint32_t bases = 1;        // 19 (B00..B18) or 1 (one named grid)
  std::vector<float> values; // bases x dim.x*dim.y*dim.z, base-major, x fastest
  std::string sourceLabel;
};
// gridName empty: the 19 FloatGrids B00..B18 of canopy-lbsolve --scene, all present and on one
// lattice (bounds and transform); else that one grid. Values finite and >= 0. InvalidInput otherwise.
SceneLightSource readSceneLightVdb(const std::string& path, const std::string& gridName);

}  // namespace canopy::octreepack
