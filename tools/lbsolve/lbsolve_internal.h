// lbsolve_internal.h (internal): pieces of canopy::lbsolve() shared by lbsolve.cpp (bases, sun)
// and scene.cpp (the scene-level lattice).
#pragma once
#include <string>
#include <vector>

#include <openvdb/openvdb.h>

#include "lbsolve.h"
#include "solver.h"

namespace canopy::lb {

// The iteration cap: --iterations, or 2 x the longest lattice edge.
int iterationCap(const LbsolveOptions& o, const Dims& d);
// Usage errors in the options (before any file is touched).
void validateOptions(const LbsolveOptions& o);
// Defaults, then the --params file, then --wood-threshold.
LightParams resolveParams(const LbsolveOptions& o);
// sigma_a, sigma_s, g, wood_g, wood_threshold as metadata.
void stampParams(openvdb::MetaMap& m, const LightParams& p);
// File-level metadata: kind, parameters, cap, tolerance, per-solve iterations and residuals.
void stampRun(openvdb::MetaMap& m, const std::string& kind, const LbsolveOptions& o, int cap,
              const LightParams& p, const std::vector<LbsolveSolve>& solves);
OmegaSet channelOmega(const LightParams& p, int channel);
std::vector<SolveResult> runWithProgress(const DenseLattice& lattice, const std::vector<SolveSpec>& specs,
                                         const std::vector<LbsolveSolve>& labels, const Device& device,
                                         LbsolveReport& report, const CudaRun& run = CudaRun());
// LbsolveOptions::cudaScheme and solvesPerGpu -> CudaRun; throws Usage for an unknown or
// benchmark-only scheme name.
CudaRun parseCudaRun(const LbsolveOptions& o);
// Scene mode (scene.cpp).
LbsolveReport solveScene(const LbsolveOptions& o);

}  // namespace canopy::lb
