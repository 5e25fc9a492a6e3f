
// params.cpp: see params.h.
#include "params.h"

#include <cmath>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"
#include "canopy/json_file.h"

namespace canopy::lb {
namespace {
std::array<double, 3> readTriple(const nlohmann::json& v, const std::string& what, const std::string& key) {
  std::array<double, 3> out{};
  if (v.is_number()) {
    out.fill(v.get<double>());
  } else if (v.is_array() && v.size() == 3 && v[0].is_number() && v[1].is_number() && v[2].is_number()) {
    for (int c = 0; c < 3; ++c) out[c] = v[c].get<double>();
  } else {
    throw invalidInput(what + ": \"" + key + "\" must be a number or an array of 3 numbers (R, G, B)");
  }
  for (double x : out)
    if (!std::isfinite(x)) throw invalidInput(what + ": \"" + key + "\" is not finite");
  return out;
}
double readScalar(const nlohmann::json& v, const std::string& what, const std::string& key) {
  if (!v.is_number() || !std::isfinite(v.get<double>()))
    throw invalidInput(what + ": \"" + key + "\" must be a finite number");
  return v.get<double>();
}
}  // namespace

void applyParams(LightParams& p, const nlohmann::json& j, const std::string& what) {
  if (!j.is_object()) throw invalidInput(what + ": parameters must be a JSON object");
  if (j.contains("g") && (j.contains("fs") || j.contains("bs")))
    throw invalidInput(what + ": give either \"g\" or \"fs\"/\"bs\", not both");
  bool sigmaSGiven = false;
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::string& k = it.key();
    if (k == "sigma_a") p.sigmaA = readTriple(*it, what, k);
    else if (k == "sigma_s") {
      p.sigmaS = readTriple(*it, what, k);
      sigmaSGiven = true;
    }
    else if (k == "fs") p.fs = readTriple(*it, what, k);
    else if (k == "bs") p.bs = readTriple(*it, what, k);
    else if (k == "g") {
      p.g = readTriple(*it, what, k);
      p.gFromFsBs = false;
    }
    else if (k == "wood_g") p.gWood = readScalar(*it, what, k);
    else if (k == "wood_threshold") p.woodThreshold = readScalar(*it, what, k);
    else if (k == "sigma") p.sigma = readScalar(*it, what, k);
    else if (k == "collision") {
      if (!it->is_string() || (*it != "beer-lambert" && *it != "linear"))
        throw invalidInput(what + ": \"collision\" must be \"beer-lambert\" or \"linear\"");
      p.beerLambert = *it == "beer-lambert";
    }
    else throw invalidInput(what + ": unknown parameter \"" + k + "\"");
  }
  if (!sigmaSGiven)
    for (int c = 0; c < 3; ++c) p.sigmaS[c] = 1.0 - p.sigmaA[c];
  if (p.gFromFsBs) {
    for (int c = 0; c < 3; ++c) {
      if (p.fs[c] < 0 || p.bs[c] < 0 || p.fs[c] + p.bs[c] <= 0)
        throw invalidInput(what + ": fs and bs must be >= 0 with fs + bs > 0");
      p.g[c] = (p.fs[c] - p.bs[c]) / (p.fs[c] + p.bs[c]);
    }
  }
  p.validate(what);
}

void LightParams::validate(const std::string& what) const {
  for (int c = 0; c < 3; ++c) {
    if (!(sigmaA[c] >= 0 && sigmaA[c] <= 1)) throw invalidInput(what + ": sigma_a must lie in [0, 1]");
    if (!(sigmaS[c] >= 0)) throw invalidInput(what + ": sigma_s must be >= 0");
    if (!(sigmaA[c] + sigmaS[c] > 0)) throw invalidInput(what + ": sigma_a + sigma_s must be > 0");
    if (!(g[c] >= -1 && g[c] <= 1)) throw invalidInput(what + ": g must lie in [-1, 1]");
  }
  if (!(gWood >= -1 && gWood <= 1)) throw invalidInput(what + ": wood_g must lie in [-1, 1]");
  if (!woodThresholdInRange(woodThreshold))
    throw invalidInput(what + ": wood_threshold must lie in [0, 1]");
  if (!sigmaInRange(sigma)) throw invalidInput(what + ": sigma must lie in (0, 64]");
}

nlohmann::json LightParams::toJson() const {
  nlohmann::json j = {{"sigma_a", sigmaA}, {"sigma_s", sigmaS}, {"g", g},
                      {"wood_g", gWood}, {"wood_threshold", woodThreshold},
                      {"collision", beerLambert ? "beer-lambert" : "linear"}};
  if (beerLambert) j["sigma"] = sigma;  // the linear collision has no sigma
  if (gFromFsBs) {
    j["fs"] = fs;
    j["bs"] = bs;
  }
  return j;
}

std::array<double, 3> LightParams::luminance() const {
  const double w[3] = {0.2126, 0.7152, 0.0722};
  std::array<double, 3> l{0, 0, 0};
  for (int c = 0; c < 3; ++c) {
    l[0] += w[c] * sigmaA[c];
    l[1] += w[c] * sigmaS[c];
    l[2] += w[c] * g[c];
  }
  return l;
}

LightParams loadParams(const std::string& path) {
  const nlohmann::json j = readJsonFile(path);
  LightParams p;
  applyParams(p, j, path);
  return p;
}

}  // namespace canopy::lb
