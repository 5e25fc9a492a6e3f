// lbsolve.h: canopy::lbsolve(), the library behind the canopy-lbsolve tool.
//
// Reads a density lattice (canopy-voxelize: FloatGrids `density` and `wood` in the lattice
// contract of formats/lattice_vdb.h), solves the lattice-Boltzmann lighting model of the
// dissertation (§2.2, §4.1-4.3; collide.h holds the per-node update) and writes an OpenVDB file:
//   bases mode (default): 19 Vec3SGrids B00..B18 (R, G, B = total site density per channel) for the
//       boundary conditions f_i = delta_ij (B01..B18) and f_i = 1 (B00, ambient); the sun bases
//       B01..B18 without their direct beam (beam.h; grid metadata canopy_direct_beam = false)
//       unless scatteredSunBases is false;
//   sun mode (--sun):     one Vec3SGrid `light`, the static solution for one sun direction, its
//       boundary split over at most three directions by the 32-face lookup (sun_lookup.h), plus
//       `ambient` on every direction;
//   scene mode (--scene): the coarse scene-level lattice of §4.3 over a scene's instances,
//       luminance only: 19 FloatGrids B00..B18 (normalised so that unoccluded light = 1) and the
//       coarse `density`.
// Light is stored at nodes whose density is non-zero or one of whose 26 neighbours' is (every
// node in scene mode). See docs/lbsolve.md.
#pragma once
#include <array>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "canopy/device.h"
#include "params.h"

namespace canopy {

struct LbsolveOptions {
  std::string input;       // density lattice (.vdb); unused in scene mode
  std::string scene;       // scene instance list (docs/scene-json.md); selects scene mode
  std::string output;      // .vdb to write
  std::string paramsFile;  // optional JSON parameter file (params.h)
  std::optional<std::array<float, 3>> sun;  // light travel direction; selects sun mode
  float ambient = 0.f;     // sun mode: boundary value added on all 19 directions
  int iterations = 0;      // iteration cap; 0 = 2 x the longest lattice edge
  float tolerance = 1e-4f; // residual at which a solve stops; 0 = run exactly `iterations`
  int checkEvery = 16;     // residual check interval (iterations)
  std::optional<double> woodThreshold;  // overrides the parameter file
  std::optional<double> sigma;          // overrides the parameter file's extinction per cell (params.h)
  std::optional<bool> beerLambert;      // overrides the parameter file's collision (params.h)
  int sceneResolution = 32;  // scene mode: coarse nodes along the scene's longest axis (interior)
  Device device;           // cpu, one GPU, or all GPUs
  // CUDA scheme (solver.h, CudaScheme): "shift" (default), "shift-split", "push" or "pull"; all compute
  // the CPU reference's bits. Ignored on the CPU.
  std::string cudaScheme = "shift";
  // CUDA: solves in flight on each GPU (solver.h, CudaRun::solvesPerGpu); results do not depend on it.
  int solvesPerGpu = 1;
  // Bases mode: store the sun bases B01..B18 without their unscattered beam (beam.h), the light
  // scattered at least once, which the player adds to its own shadowed direct sun. false
  // (--sun-bases total): the total site density, beam included (the dissertation's B_j).
  bool scatteredSunBases = true;
};

struct LbsolveSolve {
  std::string grid;  // B00..B18, "light" or (scene) B00..B18
  int channel = 0;   // 0 R, 1 G, 2 B; 3 = luminance (scene)
  int iterations = 0;
  float residual = 0.f;
  double seconds = 0.0;
};

struct LbsolveReport {
  std::string mode;  // "bases", "sun" or "scene"
  std::string sunBases;  // bases mode: "scattered" (direct beam removed) or "total"; else empty
  std::array<int, 3> dims{0, 0, 0};
  int64_t storedNodes = 0;
  int64_t nodeUpdates = 0;  // sum over solves of iterations x nodes
  std::string device;
  std::vector<LbsolveSolve> solves;
  lb::LightParams params;
  double seconds = 0.0;
  nlohmann::json toJson() const;
};

// Runs the whole job and writes options.output atomically. Throws canopy::Error (Io, InvalidInput,
// Runtime, Unsupported, Usage) with a one-line message naming the file; writes nothing on error.
LbsolveReport lbsolve(const LbsolveOptions& options);

// What `canopy-lbsolve info` reports about a light file.
struct LightFileInfo {
  std::string kind;  // "bases", "sun" or "scene"
  std::array<int, 3> latticeMin{0, 0, 0}, latticeMax{0, 0, 0};
  std::vector<std::string> grids;  // light grids present
  int64_t activeVoxels = 0;        // of the first light grid
  nlohmann::json metadata;         // parameters, iterations, residuals as written
  nlohmann::json toJson() const;
};

// Reads and validates a light file written by lbsolve. Throws Io or InvalidInput (not a VDB, not a
// light file, missing or mistyped base grids, wrong canopy_direction, inconsistent lattices).
LightFileInfo inspectLightFile(const std::string& path);

}  // namespace canopy
