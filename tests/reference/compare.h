// compare.h: canopy-play against the Monte Carlo reference (pathtrace.h) on real pipeline output,
// shared by test_reference and bench-reference.
//
// prepareScenes() runs the pipeline in-process on one plant mesh: canopy::voxelize (resolution
// <= 48), canopy::lbsolve (19 bases, CPU), and canopy::octreepack twice: the plant alone, and a
// 3-tree scene (three instances of the plant, each rotated and scaled differently, with the coarse
// scene light of lbsolve --scene). compareCase() renders one of them with canopy::play::play()
// (the CPU reference renderer, default options: shadow map, LB light) and path-traces the same
// lattices with the same camera (framePlan), sun and sky, and returns the figures.
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "runtime/player.h"
#include "tests/reference/pathtrace.h"
#include "tools/octreepack/octree_build.h"

namespace canopy::reference {

struct PreparedScene {
  std::string name;
  std::string canopyPath;
  std::string unlitCanopyPath;                  // the same packed without LB light (density only)
  std::vector<octreepack::ModelSource> models;  // in the .canopy's model order
  Medium medium;                                // the lattices, instances, sigma and LB parameters
};

struct Prepared {
  PreparedScene plant, trees;
  double seconds = 0;  // voxelize + lbsolve + octreepack
};

struct PrepareOptions {
  std::string mesh;         // plant mesh (metres)
  std::string workDir;      // created; intermediate files go here
  int resolution = 40;      // lattice cells per axis (boundary layer included)
  int sceneResolution = 24; // lbsolve --scene-resolution
  float sigma = 4.0f;       // canopy-play --sigma (the reference's extinction too)
};

// Runs the pipeline (see above). Throws canopy::Error from any stage.
Prepared prepareScenes(const PrepareOptions& options);

// The medium of a .canopy file whose models are `models` (same order and lattices; throws
// otherwise): instances' world transforms composed as the player composes them.
Medium mediumFromCanopy(const std::string& canopyPath, const std::vector<octreepack::ModelSource>& models, float sigma);

struct CaseOptions {
  int width = 96, height = 96;
  double sunElevation = 15.0, sunAzimuth = 40.0;  // canopy-play --sun orbit:azimuth=..,elevation=..
  std::string camera = "orbit";                   // canopy-play --camera
  std::string shadows = "map";                    // canopy-play --shadows (map: the default)
  float playerSunScale = 1.0f;                    // the player's --sun-intensity x this (controls: a wrong sun)
  // Direct sun only: the player renders the unlit file with --ambient 0 (its indirect term is then
  // 0: albedo x sun x Tshadow alone), the reference traces single scattering only (the camera
  // vertex's sun). Isolates the camera, transforms, extinction, albedo and shadows from the LB light.
  bool directOnly = false;
  // The indirect light only: the player with --no-direct-sun, the reference without the camera
  // vertex's sun (every other path of the sun and the sky kept).
  bool indirectOnly = false;
  std::function<void(play::PlayOptions&)> tweakPlayer;  // applied last to the player's options (experiments)
  TraceOptions trace;
  uint64_t secondSeed = 0;                        // non-zero: also trace with this seed (noiseTwoSeeds)
  std::string exrPrefix;                          // non-empty: write PREFIX.mc.exr and PREFIX.play.exr
};

// The figures. norm = the player's mean RGB over pixels whose player alpha > 0.05.
//   rms       = sqrt(mean over all pixels and channels of (play - mc)^2) / norm
//   noise     = sqrt(mean over all pixels and channels of the MC pixel's variance of the mean) / norm:
//               the part of rms that MC noise explains (rms^2 ~ bias^2 + noise^2)
//   alphaRms  = sqrt(mean over all pixels of (alpha_play - alpha_mc)^2)
//   meanRatio = sum of the player's RGB / sum of the reference's RGB (all pixels)
//   noiseTwoSeeds = RMS of (MC seed 1 - MC seed 2) / sqrt(2) / norm (secondSeed only; else -1): the
//               same noise measured another way
struct CaseResult {
  double rms = 0, noise = 0, alphaRms = 0, meanRatio = 0, noiseTwoSeeds = -1;
  double norm = 0, meanPlay = 0, meanMc = 0;
  double playSeconds = 0, mcSeconds = 0;
  int coveredPixels = 0;
  std::vector<float> play, mc;  // RGBA images
};

CaseResult compareCase(const PreparedScene& scene, const CaseOptions& options);

}  // namespace canopy::reference
