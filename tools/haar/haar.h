// haar.h: canopy-haar's callable core (the tool's main only parses options and calls these).
//
// compressLight: lbsolve output (.light.vdb, Vec3 grids B00..B18 in lattice index space) -> .chaar.
// decodeToVdb:   .chaar -> OpenVDB file with the decoded bases (same names, lattice and transform).
// chaarInfo / verifyChaar / sweepThresholds: inspection, validation and the threshold table + plot.
// Every function returns its JSON report (also what --json prints) and throws canopy::Error.
#pragma once
#include <array>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "formats/haar_encode.h"

namespace canopy::haar {

struct CompressOptions {
  std::string input, output;
  float threshold = 0.0f;  // used unless maxError >= 0
  float maxError = -1.0f;  // >= 0: per base, search a threshold with measured max error <= this
  // fp16 by default: half fp32's bytes for a measured error still within maxError (docs/haar.md,
  // "Choosing the precision"); fp32 for threshold-0 lossless files.
  Precision precision = Precision::Fp16;
};

nlohmann::json compressLight(const CompressOptions& o);
nlohmann::json decodeToVdb(const std::string& input, const std::string& output);
nlohmann::json chaarInfo(const std::string& input);
nlohmann::json verifyChaar(const std::string& input);  // throws InvalidInput on any problem
// The human-readable reports of info and verify (printed on stdout by main unless --json).
std::string formatChaarInfo(const nlohmann::json& info);
std::string formatVerify(const nlohmann::json& report);

struct SweepOptions {
  std::string input, prefix;  // writes prefix.csv, prefix.json, prefix.png
  std::vector<float> thresholds;
  Precision precision = Precision::Fp16;  // as CompressOptions
};
nlohmann::json sweepThresholds(const SweepOptions& o);

// "fp32" / "fp16" / "quant" <-> Precision (usageError otherwise).
Precision parsePrecision(const std::string& s);
const char* precisionName(Precision p);

// The light field of an lbsolve output, read into dense per-base arrays on demand.
struct LightField;
struct LightFieldDeleter {
  void operator()(LightField* p) const;
};
using LightFieldPtr = std::unique_ptr<LightField, LightFieldDeleter>;
LightFieldPtr openLightField(const std::string& path);
const LatticeGeom& lightGeom(const LightField& f);
uint32_t lightBaseCount(const LightField& f);
// Dense copy of base b (3 floats per lattice cell, x fastest) and its direction metadata.
DenseLight lightBase(const LightField& f, uint32_t b, std::array<int32_t, 3>& direction);
// Whether base b includes its direct beam: the grid's canopy_direct_beam metadata (lbsolve; false
// for scattered-only sun bases), true where it is absent (light files written before it existed).
bool lightBaseHasBeam(const LightField& f, uint32_t b);

}  // namespace canopy::haar
