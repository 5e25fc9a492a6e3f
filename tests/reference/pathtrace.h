// pathtrace.h: an independent reference for canopy-play's lighting: a small CPU Monte Carlo path
// tracer of the same voxel medium (issue 27, "Lighting that adds up"; docs/validation.md).
//
// Why tests/reference (not tools/): it is a test oracle, used at small sizes only (<= 48^3
// lattices, <= 128^2 pixels), never shipped. bench/reference links the same library (declared in
// tests/reference/library.cmake, which both folders include, so the bench builds without tests).
//
// The medium (docs/validation.md has the derivation and the mapping to the player's terms):
//   - extinction sigma * rho(x) per lattice cell of length (per world metre: / cellWorld, the
//     player's length correction), rho trilinear between lattice cell centres (integer indices),
//     0 outside the lattice box; instances add their extinctions where they overlap;
//   - the scattering event seen by the camera (first vertex) has the voxel's RGB albedo (density-
//     weighted trilinear, as canopySampleBrick) and an isotropic phase function;
//   - deeper events use the LB medium (tools/lbsolve/params.h, defaults: table 6.1): at leaf cells
//     single-scattering albedo sigma_s / (sigma_a + sigma_s) and Henyey-Greenstein g, per channel;
//     at wood cells (wood >= woodThreshold) albedo 1: a fraction sigma_s / sigma_t is reflected
//     back (g = wood_g = -1) and the rest, the absorbed f_0 that the LB's Omega re-emits, leaves
//     isotropically;
//   - sun: directional, irradiance 4 pi sun (so a single isotropic scatter at albedo 1 returns
//     sun * T); sky: uniform radiance `ambient` over the whole sphere; no ground; camera rays that
//     escape contribute 0 (no background).
// Estimators: per-instance delta tracking with a majorant per 4^3-cell block (the first collision
// of the summed medium is the nearest of the instances' own first collisions), ratio tracking for
// the sun's transmittance (next-event estimation) and for alpha, Russian roulette, one-sample MIS
// over the three channels' HG lobes. Deterministic: every (pixel, sample) has its own counter-
// based random stream, so an image does not depend on the thread count.
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "runtime/cone.h"

namespace canopy::reference {

using play::V3;

// One model's lattice, dense over its box [min, min + dim).
struct Volume {
  int32_t min[3] = {0, 0, 0};
  int32_t dim[3] = {0, 0, 0};
  std::vector<float> density;  // per cell, x fastest
  std::vector<float> wood;     // wood fraction per cell
  std::vector<float> albedo;   // RGB per cell
  // majorant blocks (kBlock^3 cells; each holds the largest density a trilinear sample inside it reads)
  int32_t blocks[3] = {0, 0, 0};
  std::vector<float> blockMax;

  size_t cell(int x, int y, int z) const { return size_t(x) + size_t(dim[0]) * (size_t(y) + size_t(dim[1]) * size_t(z)); }
  // Fills blocks/blockMax from density (call after filling the cells).
  void finish();
};
constexpr int kBlock = 4;

// A volume of `dim` cells with the given per-cell function (density, wood, albedo).
struct CellValue {
  float density, wood, albedo[3];
};

struct Instance {
  uint32_t volume = 0;
  double worldToIndex[12];  // 3x4 row-major: world point -> lattice index coordinates
  float cellWorld = 1.0f;   // world length of one lattice cell (cube root of |det indexToWorld|)
};

// The LB medium's optical parameters per channel (from canopy::lb::LightParams).
struct LbMaterial {
  float sigmaA[3] = {0, 0, 0}, sigmaS[3] = {1, 1, 1}, g[3] = {0, 0, 0};
  float gWood = -1.0f;
  float woodThreshold = 0.5f;
};

struct Medium {
  std::vector<Volume> volumes;
  std::vector<Instance> instances;
  float sigma = 4.0f;  // extinction per lattice cell at density 1 (canopy-play --sigma)
  LbMaterial lb;
};

struct Lighting {
  V3 toSun{0, 1, 0};                // unit, towards the sun (world)
  float sun[3] = {1, 1, 1};         // sun radiance in the player's convention (irradiance / 4 pi)
  float ambient = 0.35f;            // sky radiance, every direction
};

constexpr int kMaxSpp = 4096;  // paths per pixel at most (the random streams are pixel * kMaxSpp + sample)

struct TraceOptions {
  int spp = 16;              // 1..kMaxSpp
  uint64_t seed = 1;
  int minBounces = 3;        // Russian roulette from this camera-path vertex on
  int maxBounces = 1000;     // hard cap (never reached in practice: roulette ends paths first)
  bool firstVertexOnly = false;  // single scattering only (camera vertex's NEE): tests
  bool noCameraSun = false;      // without the camera vertex's sun (canopy-play --no-direct-sun: the indirect light alone)
  bool unshadowedSun = false;    // the sun's transmittance taken as 1 (diagnostics: canopy-play --no-shadows)
  // > 0: the extinction scale of every path segment after the camera vertex (and of their sun
  // rays) instead of Medium::sigma; the camera ray and the camera vertex's sun keep Medium::sigma.
  // Diagnostics: the light field in a thinner medium, as lbsolve's linear collision solves it
  // (interaction rho x sigma_t = rho per cell crossed: indirectSigma = 1).
  float indirectSigma = 0.0f;
};

// Unit-square RNG (PCG32 stream per pixel and sample).
class Rng {
 public:
  Rng(uint64_t seed, uint64_t stream);
  float next();  // [0, 1)
 private:
  uint64_t state_, inc_;
};

// Transmittance along o + t d (d unit, world), t in [0, tMax), by ratio tracking (one estimate).
float ratioTrackTransmittance(const Medium& m, V3 o, V3 d, float tMax, Rng& rng);
// The same by midpoint quadrature with `stepCells` lattice-cell steps (deterministic; tests).
double quadratureTransmittance(const Medium& m, V3 o, V3 d, double tMax, double stepCells);
// The extinction per world unit at world point x (sum over instances).
float extinctionAt(const Medium& m, V3 x);

// One pixel value estimate: premultiplied RGB and alpha (1 - T), mean over opt.spp paths for the
// ray o + t d, and the estimated variance of the RGB means (sample variance / spp). `pixel`
// selects the random streams.
struct PixelEstimate {
  float rgba[4];
  float variance[3];
};
PixelEstimate tracePixel(const Medium& m, const Lighting& L, V3 o, V3 d, const TraceOptions& opt, uint64_t pixel);

// The whole frame through canopy-play's camera (cameraRay: pixel centres, row 0 at the top):
// width * height RGBA floats like play()'s image; `variance` (optional) receives width * height * 3
// variances of the pixel means. TBB over pixels.
std::vector<float> renderReference(const Medium& m, const Lighting& L, const play::CameraView& camera, const TraceOptions& opt,
                                   std::vector<float>* variance = nullptr);

}  // namespace canopy::reference
