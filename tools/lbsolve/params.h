// params.h: the optical parameters of the lighting model and their JSON file (--params).
//
// Defaults are the dissertation's table 6.1 (R, G, B):
//   sigma_a = (0.109, 0.091, 0.118), sigma_s = 1 - sigma_a = (0.891, 0.909, 0.882),
//   fs = (0.055, 0.150, 0.020), bs = (0.070, 0.125, 0.040), g = (fs - bs) / (fs + bs)
//      = (-0.120, 0.091, -0.333).
// Caveat (PIPELINE.md §2, digest erratum): §4.1 says fs + bs = sigma_s, but the table's fs + bs is
// 0.125, 0.275, 0.060, not sigma_s. We treat fs and bs as raw leaf transmittance and reflectance
// that only set g (a ratio, so unaffected by their scale); sigma_s stays 1 - sigma_a.
// Wood ("brown") nodes, where the wood fraction >= wood_threshold, use g = wood_g = -1.
//
// File format (every key optional; unknown keys are an error):
//   { "sigma_a": [r,g,b], "sigma_s": [r,g,b], "fs": [r,g,b], "bs": [r,g,b] | "g": [r,g,b],
//     "wood_g": -1, "wood_threshold": 0.5, "sigma": 4, "collision": "beer-lambert" | "linear" }
// A scalar may stand for all three channels. "g" and "fs"/"bs" are exclusive.
#pragma once
#include <array>
#include <string>

#include <nlohmann/json.hpp>

namespace canopy::lb {

// The range of wood_threshold (and --wood-threshold): [0, 1]; false for NaN.
inline bool woodThresholdInRange(double t) { return t >= 0 && t <= 1; }
// The range of sigma (and --sigma): (0, 64]; false for NaN. (64 per cell is opaque in 1/64 cell.)
constexpr double kMaxSigma = 64.0;
inline bool sigmaInRange(double s) { return s > 0 && s <= kMaxSigma; }

struct LightParams {
  std::array<double, 3> sigmaA{0.109, 0.091, 0.118};
  std::array<double, 3> sigmaS{0.891, 0.909, 0.882};
  std::array<double, 3> fs{0.055, 0.150, 0.020};
  std::array<double, 3> bs{0.070, 0.125, 0.040};
  std::array<double, 3> g{(0.055 - 0.070) / 0.125, (0.150 - 0.125) / 0.275, (0.020 - 0.040) / 0.060};
  bool gFromFsBs = true;  // false when g was given directly
  double gWood = -1.0;
  double woodThreshold = 0.5;
  // How a node's density rho turns into interaction (collide.h, OmegaSet): "beer-lambert" (default),
  // p = 1 - exp(-sigma rho |c|), the medium canopy-play renders (its --sigma, the same default), or
  // "linear", p = rho, the dissertation's collision. sigma: extinction per lattice cell at density 1.
  double sigma = 4.0;
  bool beerLambert = true;

  // Throws canopy::Error(InvalidInput) naming `what` if a value is out of range
  // (sigma_a in [0,1], sigma_s >= 0, sigma_a + sigma_s > 0, g in [-1,1], fs, bs >= 0, fs + bs > 0,
  // sigma in (0, kMaxSigma]).
  void validate(const std::string& what) const;
  nlohmann::json toJson() const;
  // Luminance parameters for the scene-level lattice: Rec. 709 weights (0.2126, 0.7152, 0.0722)
  // applied to sigma_a, sigma_s and g.
  std::array<double, 3> luminance() const;  // {sigma_a, sigma_s, g}
};

// Reads a parameter file over the defaults. Throws Io (unreadable) or InvalidInput (bad JSON,
// unknown key, wrong type, out of range), naming the file.
LightParams loadParams(const std::string& path);
// Applies a JSON object over p (used by loadParams and tests).
void applyParams(LightParams& p, const nlohmann::json& j, const std::string& what);

}  // namespace canopy::lb
